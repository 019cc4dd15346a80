"""The term search's screen: one Gauss-Newton step through the integrator per candidate,
checked against numpy's least squares, and shown to be what finds a missing term."""

import numpy as np
import pytest
from test_engine_gradient import STARTS, _fit, _sym, _tree, rigid_dataset  # noqa: F401

import gpquad.engine.evolve.term_search as term_search
from gpquad.engine.evolve.evaluator import Evaluator
from gpquad.engine.evolve.gradient_fit import gauss_newton_step, residuals_and_jacobian
from gpquad.engine.evolve.term_search import improve_terms, term_candidates
from gpquad.engine.tree.operators import CONST


@pytest.mark.parametrize("target", ["p_dot", "a_x"])
def test_the_step_is_numpys_least_squares_step(rigid_dataset, target):  # noqa: F811
    ds = rigid_dataset
    ev = Evaluator(ds, target, 100, "mse")
    text = "8.0*u_R(t-2) - 3.0*p" if target == "p_dot" else "-0.5*u + 2.0*theta"
    model = _tree(text, ds)
    for candidate in term_candidates(model, 13, 5)[:40]:
        res, jac, _ = residuals_and_jacobian(ev, candidate, STARTS[:3], 100)
        h = np.linalg.lstsq(jac, -res, rcond=None)[0]
        slots = candidate.codes == CONST
        stepped = gauss_newton_step(ev, candidate, STARTS[:3], 100)
        assert stepped is not None
        step = stepped.values[slots] - candidate.values[slots]
        # a least-squares step (where columns repeat, another one than numpy's minimum-norm)
        best = np.sum((res + jac @ h) ** 2)
        assert np.sum((res + jac @ step) ** 2) == pytest.approx(best, rel=1e-7, abs=1e-12)
        if np.linalg.matrix_rank(jac) == jac.shape[1]:
            np.testing.assert_allclose(step, h, rtol=1e-6, atol=1e-9)
        np.testing.assert_array_equal(stepped.values[~slots], candidate.values[~slots])


def test_no_step_from_a_diverged_flight(rigid_dataset):  # noqa: F811
    ev = Evaluator(rigid_dataset, "p_dot", 250, "mse")
    runaway = _tree("40.0*p + 8.0*u_R(t-2)", rigid_dataset)  # unstable: p grows as e^(40 t)
    assert gauss_newton_step(ev, runaway, STARTS, 250) is None


def test_the_screen_keeps_the_missing_term(rigid_dataset, monkeypatch):  # noqa: F811
    """The gyroscopic q r of the rigid body's p_dot is found among 182 candidates with
    SCREEN_KEEP fitted; ranked without the step (by the error at c = 0, the bad case), the
    screen keeps the first candidates and misses it."""
    ds = rigid_dataset
    ev = Evaluator(ds, "p_dot", 250, "mse")
    model = _tree("8.0*u_R(t-2) - 3.0*p", ds)
    err = ev.mean_errors([model], STARTS)[0]
    fitted = []

    def counting(tree, error, starts, n_steps):
        fitted.append(tree)
        return _fit(ev)(tree, error, starts, n_steps)

    found, found_err = improve_terms(ev, model, err, STARTS, counting, 13, 5, 0.01)
    assert found_err < 1e-8 * err
    assert {"q", "r"} <= {str(s) for s in _sym(found, ds).free_symbols}
    assert len(fitted) == 1 + term_search.SCREEN_KEEP  # c * model, then the kept insertions

    def unstepped(ev, model, terms, offered, starts):
        return [tree for tree, _ in offered]

    monkeypatch.setattr(term_search, "screen_steps", unstepped)
    worst, worst_err = improve_terms(ev, model, err, STARTS, _fit(ev), 13, 5, 0.01)
    assert worst_err > 1e-3 * err


def test_rivals_that_cannot_beat_the_chosen_equation_are_not_fitted(rigid_dataset):  # noqa: F811
    """Beside an exact equation (at the MSE floor) a larger rival cannot win on BIC and is
    not fitted, a smaller one could and is; beside an equation far from the floor (the bad
    case for the rule) every rival is fitted."""
    from gpquad.engine.evolve.selection import fitted_rivals, select_by_bic

    ds = rigid_dataset
    ev = Evaluator(ds, "p_dot", 250, "mse")
    exact = _tree("9.0*u_R(t-2) - 4.0*p - 0.9*q*r", ds)
    larger = _tree("9.0*u_R(t-2) - 4.0*p - 0.9*q*r + 0.01*w", ds)
    smaller = _tree("8.0*u_R(t-2) - 3.0*p", ds)
    assert larger.size > exact.size > smaller.size
    fitted = []

    def counting(tree, error, starts, n_steps):
        fitted.append(tree.size)
        return _fit(ev)(tree, error, starts, n_steps)

    kept = fitted_rivals(ev, counting, exact, [larger, smaller], STARTS[:4], STARTS, 250)
    assert fitted == [smaller.size] and [t.size for t in kept] == [smaller.size]
    # the choice is the one fitting every rival would make
    everyone = [_fit(ev)(t, np.inf, STARTS[:4], 250)[0] for t in (larger, smaller)]
    assert select_by_bic(ev, [exact] + kept, STARTS, 250)[0] is exact
    assert select_by_bic(ev, [exact] + everyone, STARTS, 250)[0] is exact

    fitted.clear()
    fitted_rivals(ev, counting, smaller, [larger, exact], STARTS[:4], STARTS, 250)
    assert fitted == [larger.size, exact.size]


@pytest.mark.parametrize(
    ("target", "text", "angle_tangents", "att_weight"),
    [
        ("p_dot", "8.0*u_R(t-2) - 3.0*p + 0.5*q*r", False, 0.0),
        ("p_dot", "8.0*u_R(t-2) - 3.0*p - 2.0*phi", True, 0.5),
        ("a_x", "-0.5*u + 2.0*theta*theta", False, 0.0),
    ],
)
def test_the_shared_flight_steps_every_candidate_as_its_own_flight(
    rigid_dataset,  # noqa: F811
    target,
    text,
    angle_tangents,
    att_weight,
):
    """Every candidate's step from the one shared flight is the step of the candidate flown
    alone (up to round-off), for each candidate that keeps the model's terms."""
    from gpquad.engine.evolve.term_screen import screen_steps

    ds = rigid_dataset
    ev = Evaluator(ds, target, 100, "mse")
    ev.angle_tangents, ev.att_weight = angle_tangents, att_weight
    model = _tree(text, ds)
    offered = term_search.insertion_candidates(model, 13, 5)
    assert sum(new is not None for _, new in offered) > 100
    shared = screen_steps(ev, model, term_search.model_terms(model), offered, STARTS[:3])
    compared = 0
    for (tree, _), step in zip(offered, shared, strict=True):
        alone = gauss_newton_step(ev, tree, STARTS[:3], 100)
        assert (alone is None) == (step is None)
        if alone is None:
            continue
        errors = ev.mean_errors([step, alone], STARTS[:3])
        assert errors[0] == pytest.approx(errors[1], rel=1e-6, abs=1e-12)
        _, jac, _ = residuals_and_jacobian(ev, tree, STARTS[:3], 100)
        if np.linalg.matrix_rank(jac) == jac.shape[1]:  # else another step as good
            np.testing.assert_allclose(step.values, alone.values, rtol=1e-6, atol=1e-8)
            compared += 1
    assert compared > 100


def test_a_shared_flight_with_the_wrong_columns_is_caught(rigid_dataset, monkeypatch):  # noqa: F811
    """The bad case for the test above: columns read back in the wrong order give other
    steps."""
    import gpquad.engine.evolve.term_screen as term_screen

    ds = rigid_dataset
    ev = Evaluator(ds, "p_dot", 100, "mse")
    model = _tree("8.0*u_R(t-2) - 3.0*p + 0.5*q*r", ds)
    offered = term_search.insertion_candidates(model, 13, 5)
    right = term_screen.screen_steps(ev, model, term_search.model_terms(model), offered, STARTS[:3])
    constant_tags = term_screen._constant_tags
    calls = []

    def reversed_once(prefix):  # the shared flight's columns (the first call) misread
        calls.append(1)
        tags = constant_tags(prefix)
        return tags[::-1] if len(calls) == 1 else tags

    monkeypatch.setattr(term_screen, "_constant_tags", reversed_once)
    wrong = term_screen.screen_steps(ev, model, term_search.model_terms(model), offered, STARTS[:3])
    differ = sum(
        a is not None and b is not None and not np.allclose(a.values, b.values, rtol=1e-6)
        for a, b in zip(right, wrong, strict=True)
    )
    assert differ > 100


def test_a_term_the_model_has_is_stepped_from_the_shared_flight(rigid_dataset, monkeypatch):  # noqa: F811
    """A candidate that adds a term the model already has (c p beside -3 p) has two equal
    Jacobian columns; the screen merges them and solves its normal equations instead of
    taking the pivoted QR of its columns. Without the merge (the bad case) those
    candidates fall back to it."""
    import gpquad.engine.evolve.term_screen as term_screen

    ds = rigid_dataset
    ev = Evaluator(ds, "p_dot", 100, "mse")
    model = _tree("8.0*u_R(t-2) - 3.0*p", ds)
    offered = term_search.insertion_candidates(model, 13, 5)
    fallbacks = []
    real = term_screen.step_from

    def counted(tree, res, jac):
        fallbacks.append(tree)
        return real(tree, res, jac)

    monkeypatch.setattr(term_screen, "step_from", counted)
    terms = term_search.model_terms(model)
    merged = term_screen.screen_steps(ev, model, terms, offered, STARTS[:3])
    assert fallbacks == [] and all(step is not None for step in merged)
    monkeypatch.setattr(term_screen, "SAME_COLUMN", 2.0)
    term_screen.screen_steps(ev, model, terms, offered, STARTS[:3])
    assert len(fallbacks) >= 12  # every candidate that repeats p or u_R(t-2)
