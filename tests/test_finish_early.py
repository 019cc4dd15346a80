"""Each equation's own finishing steps made apart (gpquad.models.finish.finish_equation), as
a fit starts them when the equation's search ends, give the model finish_model makes."""

import dataclasses

import pytest
from test_refine import FLIP, R_DOT, TRUTH, dataset, evolution  # noqa: F401 (fixture)
from test_stability import model_of

from gpquad.models import finish
from gpquad.models.equations import DiscoveredModel
from gpquad.study.config import VehicleConfig

VEHICLE = VehicleConfig(mirror_inputs=FLIP)


def steps(*names):
    return dataclasses.replace(evolution(), finish=tuple(names))


def found(dataset, text):  # noqa: F811 (the fixture)
    return model_of({"r_dot": text}, dataset)


def as_dict(model: DiscoveredModel) -> dict:
    return model.to_dict()


def test_the_leading_steps_are_the_per_equation_ones_up_to_the_first_refine():
    full = ("symmetrize", "refine", "repair", "joint_fit")
    assert finish.leading_steps(full) == ("symmetrize", "refine")
    assert finish.leading_steps(("refine", "symmetrize", "repair")) == ("refine",)
    assert finish.leading_steps(("repair", "refine")) == ()
    assert finish.leading_steps(("symmetrize", "repair", "refine")) == ("symmetrize",)
    assert finish.leading_steps(()) == ()


def test_equations_finished_early_give_the_same_model(dataset):  # noqa: F811
    """The refinement adds the missing product and the mirror drops a wrong-parity term
    (u_P(t-1) in r_dot): made by finish_model or handed to it, the same model to the bit,
    and finish_model then makes none of them itself."""
    model = found(dataset, TRUTH["r_dot"] + " + 0.5*u_P(t-1)")
    evo = steps("symmetrize", "refine")
    late_steps, early_steps = [], []
    late = finish.finish_model(model, dataset, evo, VEHICLE, on_step=late_steps.append)
    early = {
        t: finish.finish_equation(e, dataset, evo, VEHICLE) for t, e in model.equations.items()
    }
    made = finish.finish_model(
        model, dataset, evo, VEHICLE, on_step=early_steps.append, early=early
    )
    assert late.refined["r_dot"]["added"] == ["u_P(t-2)*u_R(t-1)"]
    assert late.symmetrized["r_dot"]["dropped"] == ["0.5*u_P(t-1)"]
    assert as_dict(made) == as_dict(late)
    assert late_steps == ["equations", "symmetrize", "refine"]
    assert early_steps == ["symmetrize", "refine"]


def test_an_early_result_of_another_equation_is_not_used(dataset):  # noqa: F811
    """The bad case: a result made from another equation of the same target (an older
    search, say) would change the model; finish_model makes the equation's own instead."""
    model = found(dataset, TRUTH["r_dot"])
    other = found(dataset, R_DOT)
    evo = steps("refine")
    stale = {"r_dot": finish.finish_equation(other.equations["r_dot"], dataset, evo)}
    late = finish.finish_model(model, dataset, evo)
    assert as_dict(finish.finish_model(other, dataset, evo)) != as_dict(late)
    assert as_dict(finish.finish_model(model, dataset, evo, early=stale)) == as_dict(late)


@pytest.mark.parametrize("order", [("repair", "refine"), ("repair", "symmetrize")])
def test_a_per_equation_step_after_a_full_model_one_is_made_on_the_model(dataset, order):  # noqa: F811
    """After "repair" (a partial model: nothing to repair) the per-equation step is made on
    the whole model, with the result it has as a leading step."""
    model = found(dataset, TRUTH["r_dot"] + " + 0.5*u_P(t-1)")
    after = finish.finish_model(model, dataset, steps(*order), VEHICLE)
    leading = finish.finish_model(model, dataset, steps(order[1]), VEHICLE)
    assert as_dict(after) == as_dict(leading)
    assert after.refined is not None or after.symmetrized is not None
