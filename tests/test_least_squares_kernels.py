"""The LM's linear algebra kernels (gpquad.engine.kernels.least_squares) against numpy."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gpquad.engine.kernels import least_squares as kernels


def problem(seed: int, m: int, n: int, spread: float):
    rng = np.random.default_rng(seed)
    jac = rng.standard_normal((m, n)) * np.logspace(0.0, spread, n)
    return jac, rng.standard_normal(m)


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    m=st.integers(1, 60),
    n=st.integers(1, 8),
    spread=st.floats(0.0, 4.0),
)
def test_triangularize_is_a_qr_of_the_jacobian(seed, m, n, spread):
    """For J = jac / scale, both factorisations: R^T R = J^T J and R^T qtr = J^T res, R
    upper triangular (signs may differ from numpy's QR, products do not)."""
    m = max(m, n)
    jac, res = problem(seed, m, n, spread)
    columns = np.random.default_rng(seed).uniform(0.5, 20.0, n)  # the caller's scaling
    kept = jac.copy()
    scaled = jac / columns
    size = np.abs(scaled).max() ** 2
    for triangularize in (kernels.triangularize, kernels.householder_triangularize):
        r, qtr = np.zeros((n, n)), np.zeros(n)
        triangularize(jac, columns, res, r, qtr)
        assert np.array_equal(jac, kept)  # the input is not touched
        assert np.all(np.tril(r, -1) == 0.0)
        np.testing.assert_allclose(r.T @ r, scaled.T @ scaled, atol=1e-10 * size * m)
        np.testing.assert_allclose(r.T @ qtr, scaled.T @ res, atol=1e-10 * size * m)


def factors(triangularize, jac, res, scale=None):
    n = jac.shape[1]
    r, qtr = np.zeros((n, n)), np.zeros(n)
    triangularize(jac, np.ones(n) if scale is None else scale, res, r, qtr)
    return r, qtr


@pytest.mark.parametrize("m", [4, 7, 401, 2003])
def test_triangularize_takes_the_normal_equations_and_gives_the_qr_steps(m):
    """On a well-conditioned Jacobian (rows in blocks of four and a remainder) the factor
    is the normal equations' Cholesky factor (positive diagonal, not the QR's bits), and
    its damped steps are the QR's."""
    jac, res = problem(m, m, 4, 1.0)
    scale = np.linalg.norm(jac, axis=0)
    r, qtr = factors(kernels.triangularize, jac, res, scale)
    r_qr, qtr_qr = factors(kernels.householder_triangularize, jac, res, scale)
    assert np.all(np.diag(r) > 0.0)
    assert not np.array_equal(np.abs(r), np.abs(r_qr))
    np.testing.assert_allclose(r, np.linalg.cholesky((jac / scale).T @ (jac / scale)).T)
    for mu in (0.0, 1e-3, 1.0):
        h, h_qr = np.zeros(4), np.zeros(4)
        kernels.damped_step(r, qtr, mu, h)
        kernels.damped_step(r_qr, qtr_qr, mu, h_qr)
        np.testing.assert_allclose(h, h_qr, rtol=1e-9, atol=1e-12 * np.abs(h_qr).max())


@pytest.mark.parametrize("case", ["singular", "ill-conditioned", "zero column", "not finite"])
def test_triangularize_falls_back_to_the_qr(case):
    """Where the normal equations lose the step (two equal columns, a condition of 1e7, a
    column of zeros, a NaN) the factor is the Householder QR's, bit for bit."""
    jac, res = problem(3, 60, 4, 0.0)
    if case == "singular":
        jac[:, 3] = jac[:, 1]
    elif case == "ill-conditioned":
        jac[:, 3] = jac[:, 1] + 1e-7 * jac[:, 2]
    elif case == "zero column":
        jac[:, 2] = 0.0
    else:
        jac[5, 2] = np.nan
    r, qtr = factors(kernels.triangularize, jac, res)
    r_qr, qtr_qr = factors(kernels.householder_triangularize, jac, res)
    assert np.array_equal(r, r_qr, equal_nan=True)
    assert np.array_equal(qtr, qtr_qr, equal_nan=True)


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    n=st.integers(1, 8),
    mu=st.floats(1e-6, 1e3),
    spread=st.floats(0.0, 2.0),
)
def test_damped_step_solves_the_damped_normal_equations(seed, n, mu, spread):
    """h solves (J^T J + mu I) h = -J^T res; the returned value is h^T (J^T J + mu I)^-1 h;
    predicted_drop and gradient_norm are |res|^2 - |res + J h|^2, |J h|^2 and |J^T res|."""
    jac, res = problem(seed, 3 * n + 2, n, spread)
    r, qtr, h = np.zeros((n, n)), np.zeros(n), np.zeros(n)
    kernels.triangularize(jac, np.ones(jac.shape[1]), res, r, qtr)
    z2 = kernels.damped_step(r, qtr, mu, h)
    a = jac.T @ jac + mu * np.eye(n)
    expected = np.linalg.solve(a, -jac.T @ res)
    np.testing.assert_allclose(h, expected, rtol=1e-7, atol=1e-9 * np.abs(expected).max())
    np.testing.assert_allclose(z2, h @ np.linalg.solve(a, h), rtol=1e-7)
    drop, jh2 = kernels.predicted_drop(r, qtr, h)
    np.testing.assert_allclose(
        drop, res @ res - np.sum((res + jac @ h) ** 2), rtol=1e-7, atol=1e-9 * (res @ res)
    )
    np.testing.assert_allclose(jh2, np.sum((jac @ h) ** 2), rtol=1e-7)
    np.testing.assert_allclose(
        kernels.gradient_norm(r, qtr), np.linalg.norm(jac.T @ res), rtol=1e-9
    )


def test_damped_step_reports_a_singular_system():
    """mu = 0 with a rank-deficient Jacobian (two equal columns) is singular: -1 and h
    untouched; any mu > 0 solves it."""
    jac, res = problem(1, 20, 3, 0.0)
    jac[:, 2] = jac[:, 0]
    r, qtr, h = np.zeros((3, 3)), np.zeros(3), np.full(3, 7.0)
    kernels.triangularize(jac, np.ones(jac.shape[1]), res, r, qtr)
    r[2, 2] = 0.0  # exactly singular (round-off leaves ~1e-16)
    assert kernels.damped_step(r, qtr, 0.0, h) == -1.0
    assert np.all(h == 7.0)
    assert kernels.damped_step(r, qtr, 1e-3, h) >= 0.0
    assert np.all(np.isfinite(h))


@pytest.mark.parametrize("shape", [(5, 3), (1, 1), (40, 7)])
def test_reductions(shape):
    jac, res = problem(2, *shape, 1.0)
    jac[:, 0] = 0.0
    out = np.empty(shape[1])
    kernels.column_norms(jac, out)
    expected = np.linalg.norm(jac, axis=0)
    np.testing.assert_allclose(out, np.where(expected > 0, expected, 1.0), rtol=1e-12)
    np.testing.assert_allclose(kernels.sum_squares(res), res @ res, rtol=1e-12)
    assert np.isinf(kernels.sum_squares(np.array([1.0, np.inf])))


@settings(max_examples=60, deadline=None)
@given(
    values=st.lists(
        st.one_of(
            st.floats(-1e6, 1e6),
            st.sampled_from([np.inf, -np.inf, np.nan, 1e154, -3e154, 1e200]),
        ),
        max_size=23,
    )
)
def test_squares_finite_is_the_finiteness_of_sum_squares(values):
    """The LM's check of a Jacobian: finite exactly when sum_squares is (an entry not
    finite, or squares that overflow together)."""
    v = np.array(values, dtype=float)
    assert kernels.squares_finite(v) == np.isfinite(kernels.sum_squares(v))


def test_squares_finite_sees_an_overflow_of_the_sum_alone():
    """Squares that are each finite and overflow only when summed."""
    assert kernels.squares_finite(np.full(7, 1e153))
    assert not kernels.squares_finite(np.full(7, 1e154))
