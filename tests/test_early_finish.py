"""Per-equation finishing work begun during the searches (gpquad.models.early_finish): the
finish takes a result begun early only for an input equal to its own, so the model is the
one the finish makes alone."""

import dataclasses
import threading
import time

import numpy as np
import pytest
from test_refine import FLIP, R_DOT, TRUTH, dataset, evolution  # noqa: F401
from test_stability import model_of

from gpquad.models.early_finish import EarlyFinish, content_key
from gpquad.models.finish import finish_model
from gpquad.study.config import VehicleConfig

VEHICLE = VehicleConfig(mirror_inputs=FLIP)


def _other_constant(equation):
    """The equation with one constant changed in its last bit."""
    values = equation.tree.values.copy()
    i = int(np.flatnonzero(values)[0])
    values[i] = np.nextafter(values[i], np.inf)
    tree = dataclasses.replace(equation.tree, values=values)
    return dataclasses.replace(equation, tree=tree)


def test_the_key_tells_equations_apart_by_every_bit(dataset):  # noqa: F811
    found = model_of({"r_dot": TRUTH["r_dot"]}, dataset).equations["r_dot"]
    assert content_key(dataclasses.replace(found)) == content_key(found)
    assert content_key(_other_constant(found)) != content_key(found)
    assert content_key(dataclasses.replace(found, lag=0.02)) != content_key(found)


def test_a_result_is_taken_only_for_an_equal_input(dataset):  # noqa: F811
    early = EarlyFinish(dataset, evolution(), FLIP)
    found = model_of({"r_dot": TRUTH["r_dot"]}, dataset).equations["r_dot"]
    calls = []

    def compute(equation):
        calls.append(equation)
        return object()

    first = early("refine", found, compute)
    assert early("refine", dataclasses.replace(found), compute) is first  # equal: taken
    assert len(calls) == 1 and early.used == 1
    other = early("refine", _other_constant(found), compute)  # bad case: another input
    assert other is not first and len(calls) == 2
    assert early("symmetrize", found, compute) is not first  # another step, another key


def _finished(model, dataset, each=None):  # noqa: F811
    evo = dataclasses.replace(evolution(2), finish=("symmetrize", "refine"))
    return finish_model(model, dataset, evo, VEHICLE, each=each)


def _begun(dataset, equations):  # noqa: F811
    """An EarlyFinish that has done its work on `equations` (found one by one)."""
    evo = dataclasses.replace(evolution(2), finish=("symmetrize", "refine"))
    early = EarlyFinish(dataset, evo, FLIP)
    early.start()
    for equation in equations:
        early.found(equation)
    early._pool.shutdown(wait=True)  # every piece of work queued is done
    return early


def test_the_finish_takes_the_work_begun_and_makes_the_same_model(dataset):  # noqa: F811
    model = model_of({"r_dot": TRUTH["r_dot"], "q_dot": TRUTH["q_dot"]}, dataset)
    alone = _finished(model, dataset)
    assert alone.refined["r_dot"]["added"]  # the refinement had work to do
    early = _begun(dataset, model.equations.values())
    assert early.busy_s > 0
    with_early = _finished(model, dataset, each=early)
    early.close()
    assert early.used >= 1  # r_dot's refinement was taken, not made again
    assert with_early.to_dict() == alone.to_dict()


def test_work_begun_on_other_equations_is_not_taken(dataset):  # noqa: F811
    """The bad case: the early work saw r_dot with another constant (as when its expected
    rows were wrong); the finish makes its own, and the model is the same."""
    model = model_of({"r_dot": TRUTH["r_dot"]}, dataset)
    alone = _finished(model, dataset)
    early = _begun(dataset, [_other_constant(model.equations["r_dot"])])
    with_early = _finished(model, dataset, each=early)
    early.close()
    assert early.used == 0
    assert with_early.to_dict() == alone.to_dict()


def test_nothing_begins_before_start_or_after_drain(dataset):  # noqa: F811
    model = model_of({"r_dot": TRUTH["r_dot"]}, dataset)
    evo = dataclasses.replace(evolution(2), finish=("refine", "repair"))
    early = EarlyFinish(dataset, evo, FLIP)
    early.found(model.equations["r_dot"])
    assert early.busy_s == 0 and early._pool is None
    early.drain()
    early.start()  # after drain: never
    assert early._pool is None
    assert early.steps == ("refine",)  # the model-level steps are the finish's own
    assert not EarlyFinish(
        dataset, dataclasses.replace(evo, finish=("repair", "refine")), ()
    ).useful


@pytest.mark.parametrize("flipped", [(), FLIP])
def test_useful_only_with_per_equation_work(dataset, flipped):  # noqa: F811
    evo = dataclasses.replace(evolution(2), finish=("symmetrize",))
    assert EarlyFinish(dataset, evo, flipped).useful == bool(flipped)


def test_an_abandoned_early_finish_does_not_wait_for_its_work(dataset):  # noqa: F811
    """On an error or Ctrl-C the fit leaves at once; close() (a finish that ended) waits.
    Bad case: abandon() waiting would take the work's 10 s."""
    gate, began = threading.Event(), threading.Event()
    early = EarlyFinish(dataset, evolution(2), FLIP)
    early._prepare = lambda equation: (began.set(), gate.wait(10))
    early.start()
    early.found(object())
    assert began.wait(10)
    t0 = time.perf_counter()
    early.abandon()
    assert time.perf_counter() - t0 < 5 and not gate.is_set()
    gate.set()
    early.close()
