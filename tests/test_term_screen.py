"""The term screen: which insertions are fitted through the integrator."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from gpquad.data.dataset import build_dataset
from gpquad.data.simulator import simulate
from gpquad.engine.evolve.evaluator import Evaluator
from gpquad.engine.evolve.gradient_fit import residuals_and_jacobian
from gpquad.engine.evolve.term_screen import SCREENED, explained, insertions, screened
from gpquad.engine.evolve.term_search import model_terms, term_candidates
from gpquad.engine.tree.export import from_sympy, parse_equation
from gpquad.engine.variables import N_STATE
from gpquad.study.config import load_config

EXPERIMENTS = Path(__file__).resolve().parents[1] / "experiments"


@pytest.fixture(scope="module")
def rigid():
    """40 s of the rigid-body truth: p_dot = 9 u_R(t-2) - 4 p - 0.9 q r."""
    sim = load_config(EXPERIMENTS / "rigid_body.toml").simulator
    sim = dataclasses.replace(sim, duration_s=40.0, seed=3)
    return build_dataset(
        [simulate(sim, ("u_P", "u_R", "u_Y", "u_T"))], validation_fraction=0.25, trim="none"
    )


def _tree(text, ds):
    expr, delays = parse_equation(text, ds.input_names)
    return from_sympy(expr, delays, ds.input_names)


def test_insertions_are_term_candidates_in_order():
    taps = {N_STATE + 4 + j: N_STATE + j for j in range(4)}
    every = insertions(list(range(17)), taps)
    assert len(every) == len(set(every))
    assert len(insertions(list(range(13)), {})) == 13 + 91 + 78
    model = _tree("2.0*p", _Names())
    trees = term_candidates(model, 13, 5, with_insertions=True)
    assert [i for i, _ in trees] == insertions(list(range(13)), {})


class _Names:
    input_names = ("u_P", "u_R", "u_Y", "u_T")


@settings(max_examples=30, deadline=None)
@given(
    arrays(np.float64, 40, elements=st.floats(-10, 10)),
    arrays(np.float64, (40, 2), elements=st.floats(-10, 10)),
)
def test_explained_is_the_drop_of_a_least_squares_fit(r, x):
    coef, *_ = np.linalg.lstsq(x, r, rcond=None)
    expected = float((r**2).sum() - ((r - x @ coef) ** 2).sum())
    got = explained(r, x)
    assert got == pytest.approx(expected, rel=1e-6, abs=1e-6 * (1 + (r**2).sum()))
    assert got >= -1e-6 * (1 + (r**2).sum())
    assert explained(r, np.full((40, 1), np.nan)) == 0.0


def _screen(ds, text, candidates, count=SCREENED):
    ev = Evaluator(ds, "p_dot", 250, "mse")
    model = _tree(text, ds)

    def flown(tree):
        return residuals_and_jacobian(ev, tree, STARTS, 250)[:2]

    return screened(model_terms(model), model.delays, candidates, flown, count)


STARTS = np.array([10, 260, 510], dtype=np.int64)


@pytest.mark.parametrize("model", ["9.0*u_R(t-2) - 4.0*p", "8.0*u_R(t-2) - 3.0*p"])
def test_the_missing_coupling_passes_the_screen(rigid, model):
    """The truth without -0.9 q r, with its gains right or wrong (the screen re-fits them)."""
    every = insertions(list(range(13)), {})
    kept = _screen(rigid, model, every)
    assert len(kept) == SCREENED and kept == [i for i in every if i in kept]
    q, r = 7, 8
    assert _screen(rigid, model, every, count=1) == [((q, r),)]


def test_few_candidates_or_a_non_finite_flight_keep_all(rigid):
    few = insertions(list(range(3)), {})
    assert _screen(rigid, "9.0*u_R(t-2) - 4.0*p", few) == few
    every = insertions(list(range(13)), {})
    model = _tree("9.0*u_R(t-2) - 4.0*p", rigid)

    def broken(tree):
        return np.full(10, np.nan), np.zeros((10, 200))

    assert screened(model_terms(model), model.delays, every, broken) == every
