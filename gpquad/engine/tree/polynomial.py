"""A tree as a polynomial: its expansion into monomials, and monomials back as prefix terms.

Term insertion (gpquad.engine.evolve.term_search) works on a model's additive terms. A
climber written as a product of sums, (c1 u_T + c2 w) * (1 + c3 u_R^2), is one term at
the top, so a missing phi^2 could only replace the whole model. Expanded, it is four
monomials, each with its own coefficient, of which the least useful can make room.
"""

from __future__ import annotations

from gpquad.engine.tree.encoding import shallow_sum, subtree_end
from gpquad.engine.tree.operators import ADD, CONST, DIV, DIV_EPS, MUL, SUB

#: Largest expansion used: a product of sums that multiplies out into more monomials than
#: this is kept as it is.
MAX_MONOMIALS = 32

Polynomial = dict  # {sorted tuple of variable codes (the monomial): coefficient}


class _NotPolynomial(Exception):
    pass


def _multiply(a: Polynomial, b: Polynomial) -> Polynomial:
    out: Polynomial = {}
    for ma, ca in a.items():
        for mb, cb in b.items():
            m = tuple(sorted(ma + mb))
            out[m] = out.get(m, 0.0) + ca * cb
    if len(out) > MAX_MONOMIALS:
        raise _NotPolynomial
    return out


def _combine(a: Polynomial, b: Polynomial, sign: float) -> Polynomial:
    out = dict(a)
    for m, c in b.items():
        out[m] = out.get(m, 0.0) + sign * c
    if len(out) > MAX_MONOMIALS:
        raise _NotPolynomial
    return out


def _expand(codes, values, start: int) -> Polynomial:
    code = int(codes[start])
    if code == CONST:
        return {(): float(values[start])}
    if code > CONST:
        return {(code,): 1.0}
    left_end = subtree_end(codes, start + 1)
    left = _expand(codes, values, start + 1)
    right = _expand(codes, values, left_end)
    if code == ADD:
        return _combine(left, right, 1.0)
    if code == SUB:
        return _combine(left, right, -1.0)
    if code == MUL:
        return _multiply(left, right)
    assert code == DIV
    nonzero = {m: c for m, c in right.items() if c != 0.0}
    if any(m for m in nonzero):
        raise _NotPolynomial  # a division by a variable
    denominator = nonzero.get((), 0.0)
    if abs(denominator) < DIV_EPS:  # protected division, as the kernels evaluate it
        return {(): 1.0}
    return {m: c / denominator for m, c in left.items()}


def expand(codes, values) -> Polynomial | None:
    """The prefix tree multiplied out, {monomial: coefficient} with like monomials merged
    and zero coefficients dropped, or None when it divides by a variable or has more than
    MAX_MONOMIALS monomials."""
    try:
        poly = _expand(codes, values, 0)
    except _NotPolynomial:
        return None
    return {m: c for m, c in sorted(poly.items()) if c != 0.0} or {(): 0.0}


def product(variables: tuple[int, ...]) -> list[tuple[int, float]]:
    """Prefix (code, value) list of a product of variable leaves, as a shallow tree."""
    return shallow_sum([[(v, 0.0)] for v in variables], operator=MUL)


def monomial_terms(poly: Polynomial) -> list[list[tuple[int, float]]]:
    """Each monomial as a prefix term c * x * y ... (a constant alone for the monomial ())."""
    return [[(MUL, 0.0), (CONST, c)] + product(m) if m else [(CONST, c)] for m, c in poly.items()]


def polynomial_form(codes, values) -> list[tuple[int, float]] | None:
    """The prefix (code, value) list of the tree multiplied out: the shallow sum of its
    monomials (c * x * y ..., one constant each), the same function written with as few
    nodes as its printed form; None when it does not multiply out (`expand`)."""
    poly = expand(codes, values)
    return None if poly is None else shallow_sum(monomial_terms(poly))
