"""A peer's printed expressions as one predictor (gpquad.benchmark.peer_predictor): the
polynomial path against a plain-numpy sum of terms, the fallback against sympy.lambdify."""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp
from hypothesis import given, settings
from hypothesis import strategies as st

from gpquad.benchmark.peer_predictor import (
    PolynomialPredictor,
    peer_predictor,
    polynomial_terms,
    shared_terms,
)
from gpquad.benchmark.rollout import MAX_LAG, lagged_names
from gpquad.engine.variables import STATE_NAMES, TARGET_NAMES

INPUTS = ("u_R", "u_P", "u_Y", "u_T")
NAMES = list(STATE_NAMES) + lagged_names(INPUTS, MAX_LAG)


def _features(rng, n: int = 7) -> np.ndarray:
    return rng.normal(0.0, 1.0, (n, len(NAMES)))


@settings(max_examples=60)
@given(st.data())
def test_polynomials_evaluate_as_their_sum_of_terms(data):
    """Random monomials (shared between targets, up to degree 4) and coefficients: each
    output is sum_m c_m prod_f x_f ** e_mf, computed term by term."""
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    n_features = data.draw(st.integers(1, 6))
    pool = rng.integers(0, 3, (data.draw(st.integers(1, 12)), n_features))
    pool[:, rng.integers(0, n_features)] %= 2  # some low degrees
    polynomials = []
    for _ in range(data.draw(st.integers(1, 6))):
        rows = rng.choice(len(pool), rng.integers(0, len(pool) + 1), replace=False)
        polynomials.append((pool[rows], rng.normal(0.0, 3.0, len(rows))))
    x = rng.normal(0.0, 1.5, (5, n_features))
    got = PolynomialPredictor(*shared_terms(polynomials, n_features))(x)
    for t, (exponents, coefficients) in enumerate(polynomials):
        expected = np.zeros(len(x))
        for e, c in zip(exponents, coefficients, strict=True):
            expected += c * np.prod(x**e, axis=1)
        assert got[:, t] == pytest.approx(expected, rel=1e-12, abs=1e-12)


@pytest.mark.parametrize("text", ["sin(p)", "1/(1 + p**2)", "p/q", "p**(-1)"])
def test_a_non_polynomial_is_not_taken_as_one(text):
    syms = [sp.Symbol(n, real=True) for n in ("p", "q")]
    expr = sp.sympify(text, locals={s.name: s for s in syms})
    assert polynomial_terms(expr, syms) is None


def test_polynomial_terms_of_a_polynomial():
    p, q = (sp.Symbol(n, real=True) for n in ("p", "q"))
    exponents, coefficients = polynomial_terms(2.5 * p**2 * q - q + 3, [p, q])
    found = {tuple(e): c for e, c in zip(exponents, coefficients, strict=True)}
    assert found == {(2, 1): 2.5, (0, 1): -1.0, (0, 0): 3.0}


def test_a_peers_texts_predict_what_lambdify_gives():
    """Long polynomials (PySINDy's kind, sharing monomials), a constant, zero and two
    non-polynomials (operon's kind) flown by one predictor equal each text lambdified."""
    rng = np.random.default_rng(11)
    squares = " + ".join(
        f"{rng.normal():.5f}*{a}*{b}"
        for a, b in zip(rng.choice(NAMES, 400), rng.choice(NAMES, 400), strict=True)
    )
    texts = {
        "a_x": "0.25 + " + squares,
        "a_y": squares + " - 3.5*p^2*q",
        "a_z": "-9.81",
        "p_dot": "0",
        "q_dot": "(q - u_P_l2)/(1 + p^2)",
        "r_dot": "-4*r + 4*u_Y_l0*(1 + 0.5*r)/(2 + q^2)",
    }
    predict = peer_predictor(texts, INPUTS)
    x = _features(rng)
    got = predict(x, np.arange(len(x)))
    syms = [sp.Symbol(n, real=True) for n in NAMES]
    table = {s.name: s for s in syms}
    for t, target in enumerate(TARGET_NAMES):
        func = sp.lambdify(syms, sp.sympify(texts[target].replace("^", "**"), locals=table))
        expected = np.broadcast_to(np.asarray(func(*x.T), dtype=float), (len(x),))
        assert got[:, t] == pytest.approx(expected, rel=1e-11, abs=1e-11), target


def test_a_fitted_librarys_predictor_uses_its_terms_in_the_reordered_features():
    """gpquad.benchmark.peers.polynomial_predictor (PySINDy's fits): library powers in the
    reordered features, coefficients (6, T) with unused terms; a plain sum of terms."""
    from gpquad.benchmark.peers import polynomial_predictor

    rng = np.random.default_rng(5)
    n_features = 6
    powers = np.array(
        [[0] * n_features] + [list(r) for r in rng.integers(0, 2, (20, n_features))],
        dtype=np.int64,
    )
    powers[3] = 0
    powers[3, 2] = 3  # a cube
    coef = rng.normal(0.0, 1.0, (6, len(powers)))
    coef[:, 5] = 0.0  # a term no equation uses
    coef[2, 1::2] = 0.0

    def reorder(f):
        return f[:, ::-1]

    x = rng.normal(0.0, 1.0, (9, n_features))
    got = polynomial_predictor(powers, coef, reorder)(x, np.arange(len(x)))
    z = reorder(x)
    library = np.column_stack([np.prod(z**row, axis=1) for row in powers])
    assert got == pytest.approx(library @ coef.T, rel=1e-12, abs=1e-12)
