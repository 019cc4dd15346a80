"""Full-model stability repair (gpquad.models.stability) on flights of the median model,
whose truth is known: an equation that makes the full model diverge is swapped for the
front alternative that flies."""

import numpy as np
import pytest

from gpquad.data.dataset import build_dataset
from gpquad.engine.tree.export import from_sympy, parse_equation
from gpquad.models import finish, stability
from gpquad.models.equations import DiscoveredModel, Equation
from gpquad.study.config import SimulatorConfig, preset_evolution

TRUTH = dict(SimulatorConfig().equations)
#: Pitch damping with the wrong sign: q grows as exp(3.3 t), the full model diverges.
UNSTABLE_Q = "-9.8*u_P + 3.3*q"


@pytest.fixture(scope="module")
def raw_dataset(short_flight):
    return build_dataset([short_flight], validation_fraction=0.25, trim="none")


def equation(target, text, dataset, front=()):
    expr, delays = parse_equation(text, dataset.input_names)
    eq = Equation(
        target,
        from_sympy(expr, delays, dataset.input_names),
        dataset.input_names,
        0.5,
        np.nan,
        dict(dataset.trim),
    )
    eq.candidates = [equation(target, t, dataset).summary() for t in front]
    return eq


def model_of(equations, dataset, fronts=None):
    eqs = {
        t: equation(t, text, dataset, (fronts or {}).get(t, ())) for t, text in equations.items()
    }
    return DiscoveredModel(eqs, dataset.input_names, dict(dataset.trim), dataset.dt, 1, {})


def test_alternatives_rebuild_the_front(raw_dataset):
    eq = equation("a_z", "1.0", raw_dataset, ["28.2*u_T(t-5) - w - 9.81", "-w"])
    alts = eq.alternatives()
    assert [a.text() for a in alts] == [
        equation("a_z", t, raw_dataset).text() for t in ("28.2*u_T(t-5) - w - 9.81", "-w")
    ]
    assert alts[0].used_delays() == {"u_T": 5}


def test_a_diverging_equation_is_swapped_for_the_front_alternative_that_flies(raw_dataset):
    fronts = {"q_dot": ["-9.8*u_P", UNSTABLE_Q, TRUTH["q_dot"]]}
    model = model_of(dict(TRUTH, q_dot=UNSTABLE_Q), raw_dataset, fronts)
    repaired, report = stability.repair_stability(model, raw_dataset)
    assert report["judged_on"] == "validation" and report["diverged_before"] > 0
    assert report["diverged_after"] == 0 and report["error_after"] < report["error_before"]
    assert [s["target"] for s in report["swaps"]] == ["q_dot"]
    assert (
        repaired.equations["q_dot"].text() == equation("q_dot", TRUTH["q_dot"], raw_dataset).text()
    )
    assert repaired.equations["q_dot"].candidates == model.equations["q_dot"].candidates
    for t in ("a_x", "a_y", "a_z", "p_dot", "r_dot"):
        assert repaired.equations[t] is model.equations[t]
    assert "q_dot" in stability.stability_summary(report)


def test_no_swap_when_no_alternative_helps(raw_dataset):
    """The check can fail: with only diverging alternatives the model stays as it was and
    the report says it still diverges."""
    model = model_of(dict(TRUTH, q_dot=UNSTABLE_Q), raw_dataset, {"q_dot": ["-9.8*u_P + 5.0*q"]})
    repaired, report = stability.repair_stability(model, raw_dataset)
    assert report["swaps"] == [] and report["diverged_after"] == report["diverged_before"] > 0
    assert repaired.equations["q_dot"].text() == model.equations["q_dot"].text()


def test_a_model_that_flies_is_left_alone(raw_dataset):
    """Never a swap for accuracy alone: the truth's front holds a better-looking nothing."""
    model = model_of(TRUTH, raw_dataset, {"a_x": ["10.0*theta"]})
    repaired, report = stability.repair_stability(model, raw_dataset)
    assert report["diverged_before"] == 0 and report["swaps"] == [] and report["flights"] == 1
    assert repaired is model
    assert "no diverged window" in stability.stability_summary(report)


def test_finish_model_repairs_only_with_the_option(raw_dataset):
    model = model_of(dict(TRUTH, q_dot=UNSTABLE_Q), raw_dataset, {"q_dot": [TRUTH["q_dot"]]})
    off = finish.finish_model(model, raw_dataset, preset_evolution())
    assert (
        off.stability is None and off.equations["q_dot"].text() == model.equations["q_dot"].text()
    )
    on = finish.finish_model(model, raw_dataset, preset_evolution(finish=["repair"]))
    assert on.stability["diverged_after"] == 0
    assert on.equations["q_dot"].text() == equation("q_dot", TRUTH["q_dot"], raw_dataset).text()
    again = DiscoveredModel.from_dict(on.to_dict())  # the report is kept in model.json
    assert again.stability == on.stability
