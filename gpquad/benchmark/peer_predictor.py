"""A peer's printed expressions as one predictor of the six accelerations.

A peer prints each acceleration as an expression in the integrated states and the lagged
inputs (the features of `gpquad.benchmark.rollout`). PySINDy's are polynomials of
hundreds to thousands of terms that share one library of monomials, and the fidelity
column asks them for every window at every RK4 stage: evaluated term by term on a few
dozen windows (`sympy.lambdify`), one stage costs thousands of small numpy operations.

An expression that is a polynomial in the features is therefore evaluated as one: every
monomial of any of the six expressions is computed once per call, as the product of its
factors (x**2 y is x * x * y), and the accelerations are one matrix product of those
values and the coefficients (zero where an expression lacks the monomial). An expression
that is not a polynomial (an operon model's division or exp) is evaluated by its
`sympy.lambdify` function.
"""

from __future__ import annotations

import functools

import numpy as np
import sympy as sp

from gpquad.benchmark.rollout import MAX_LAG, lagged_names
from gpquad.engine.tree.arithmetic import parse_in_symbols
from gpquad.engine.variables import STATE_NAMES, TARGET_NAMES

#: Largest total degree evaluated as a polynomial (higher: by lambdify).
MAX_DEGREE = 16


def polynomial_terms(expr: sp.Expr, symbols) -> tuple[np.ndarray, np.ndarray] | None:
    """(exponents (M, F) int, coefficients (M,) float) of expr as a polynomial in the
    symbols, or None when it is not one, a coefficient is not a real number or its
    degree exceeds MAX_DEGREE."""
    poly = sp.sympify(expr).as_poly(*symbols)
    if poly is None:
        return None
    terms = poly.terms()
    try:
        coefficients = np.array([float(c) for _, c in terms], dtype=float)
    except (TypeError, ValueError):
        return None
    exponents = np.array([m for m, _ in terms], dtype=np.int64).reshape(len(terms), len(symbols))
    if len(terms) and exponents.sum(axis=1).max() > MAX_DEGREE:
        return None
    return exponents, coefficients


class PolynomialPredictor:
    """predict(features (W, F)) -> (W, T): output t is the sum over monomials m of
    coefficients[m, t] * prod_f features[:, f] ** exponents[m, f].

    exponents (M, F) whole numbers >= 0; coefficients (M, T). Each monomial is computed once
    per call, as the product of its factors, and the outputs are one matrix product."""

    def __init__(self, exponents: np.ndarray, coefficients: np.ndarray):
        exponents = np.asarray(exponents, dtype=np.int64)
        n_features = exponents.shape[1]
        degree = int(exponents.sum(axis=1).max()) if len(exponents) else 0
        # factors[m, d]: the feature of monomial m's d-th factor; n_features is the constant 1
        self.factors = np.full((len(exponents), max(degree, 1)), n_features, dtype=np.int64)
        for m, row in enumerate(exponents):
            names = np.repeat(np.arange(n_features), row)
            self.factors[m, : len(names)] = names
        self.coefficients = np.ascontiguousarray(coefficients, dtype=float)
        self.n_features = n_features

    def __call__(self, features: np.ndarray) -> np.ndarray:
        padded = np.empty((features.shape[0], self.n_features + 1))
        padded[:, : self.n_features] = features
        padded[:, self.n_features] = 1.0
        values = padded[:, self.factors[:, 0]]
        for d in range(1, self.factors.shape[1]):
            values *= padded[:, self.factors[:, d]]
        return values @ self.coefficients


def shared_terms(polynomials, n_features: int) -> tuple[np.ndarray, np.ndarray]:
    """(exponents (M, F), coefficients (M, T)) of T polynomials, each a pair (exponents,
    coefficients) of `polynomial_terms`, over the monomials any of them has."""
    rows: dict[tuple[int, ...], int] = {}
    for exponents, _ in polynomials:
        for e in exponents:
            rows.setdefault(tuple(int(x) for x in e), len(rows))
    coefficients = np.zeros((len(rows), len(polynomials)))
    for t, (exponents, values) in enumerate(polynomials):
        for e, c in zip(exponents, values, strict=True):
            coefficients[rows[tuple(int(x) for x in e)], t] += c
    exponents = np.array(list(rows), dtype=np.int64).reshape(len(rows), n_features)
    return exponents, coefficients


def peer_predictor(equations: dict, input_names):
    """predict(features, idx) -> (W, 6) of a peer's expressions in the lagged features
    (module notes); equations: {target: expression text}. The same texts are read once
    (a cell's equations fly in two schemes)."""
    return _predictor(tuple(equations[t] for t in TARGET_NAMES), tuple(input_names))


@functools.lru_cache(maxsize=4)
def _predictor(texts: tuple[str, ...], input_names: tuple[str, ...]):
    equations = dict(zip(TARGET_NAMES, texts, strict=True))
    names = list(STATE_NAMES) + lagged_names(input_names, MAX_LAG)
    syms = [sp.Symbol(n, real=True) for n in names]
    table = dict(zip(names, syms, strict=True))
    exprs = [parse_in_symbols(equations[t], table, caret_power=True, field=t) for t in TARGET_NAMES]
    terms = [polynomial_terms(e, syms) for e in exprs]
    polynomial = [t for t, found in enumerate(terms) if found is not None]
    poly = PolynomialPredictor(*shared_terms([terms[t] for t in polynomial], len(syms)))
    others = {
        t: sp.lambdify(syms, exprs[t], "numpy") for t, found in enumerate(terms) if found is None
    }

    def predict(features, idx):
        out = np.empty((len(idx), len(TARGET_NAMES)))
        out[:, polynomial] = poly(features)
        cols = list(features.T)
        for t, func in others.items():
            out[:, t] = np.broadcast_to(np.asarray(func(*cols), dtype=float), (len(idx),))
        return out

    return predict
