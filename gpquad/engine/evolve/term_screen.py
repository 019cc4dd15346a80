"""Which term insertions are worth a fit through the integrator.

Term insertion (gpquad.engine.evolve.term_search) offers every variable, product and pair
of variables: 182 candidates with 13 variables, each re-fitted through the integrator.
Most of them explain nothing the model misses. The screen predicts each insertion's drop
of the integrated error by one Gauss-Newton step from its new gains at 0: one flight of
the model with every candidate term added at gain 0 gives the residuals and their
sensitivities to every gain (gpquad.engine.kernels.sensitivity); an insertion's predicted
drop is the part of the residuals its terms' sensitivities explain beyond the model's own
gains' (every gain re-fitted, to first order). Only the SCREENED best are fitted. A
one-step regression on the data's accelerations ranked them worse on a real log
(docs/decisions/2026-11-26-search-speed.md): what one sample's noisy acceleration
correlates with is not what an integrated state needs.
"""

from __future__ import annotations

import numpy as np

from gpquad.engine.tree.encoding import Tree
from gpquad.engine.tree.operators import ADD, CONST, MUL, VAR_BASE

#: Term insertions fitted through the integrator per term search.
SCREENED = 16

#: An insertion: its new terms, each a tuple of the variables it multiplies.
Insertion = tuple[tuple[int, ...], ...]


def insertions(variables: list[int], taps: dict[int, int]) -> list[Insertion]:
    """Every term insertion of term_candidates, in its order: x_i, x_i x_j (no taps), the
    pairs x_i + x_j (no taps), and two taps of one input."""
    plain = [v for v in variables if v not in taps]
    out: list[Insertion] = [((i,),) for i in variables]
    out += [((i, j),) for k, i in enumerate(plain) for j in plain[k:]]
    out += [((i,), (j,)) for k, i in enumerate(plain) for j in plain[k + 1 :]]
    out += [
        ((i,), (j,))
        for k, i in enumerate(variables)
        for j in variables[k + 1 :]
        if j in taps and taps[j] == taps.get(i, i)
    ]
    return out


def zero_term(variables: tuple[int, ...]) -> list[tuple[int, float]]:
    """Prefix of 0 * x_i (* x_j)."""
    if len(variables) == 1:
        return [(MUL, 0.0), (CONST, 0.0), (VAR_BASE + variables[0], 0.0)]
    return [
        (MUL, 0.0),
        (CONST, 0.0),
        (MUL, 0.0),
        (VAR_BASE + variables[0], 0.0),
        (VAR_BASE + variables[1], 0.0),
    ]


def _balanced_sum(terms: list[list[tuple[int, float]]]) -> list[tuple[int, float]]:
    """Prefix of the sum of `terms` as a balanced tree, the terms in their order."""
    if len(terms) == 1:
        return terms[0]
    half = len(terms) // 2
    return [(ADD, 0.0)] + _balanced_sum(terms[:half]) + _balanced_sum(terms[half:])


def explained(residual: np.ndarray, columns: np.ndarray) -> float:
    """Sum of squares of `residual` that a least-squares fit on the columns (n, k) removes
    (0 when a value is not finite)."""
    if not (np.all(np.isfinite(columns)) and np.all(np.isfinite(residual))):
        return 0.0
    coef, *_ = np.linalg.lstsq(columns, residual, rcond=None)
    rest = residual - columns @ coef
    return float(residual @ residual - rest @ rest)


def screened(
    base: list[list[tuple[int, float]]],
    delays: np.ndarray,
    candidates: list[Insertion],
    residuals_and_jacobian,
    count: int = SCREENED,
) -> list[Insertion]:
    """The `count` insertions of `candidates` with the largest predicted drops (module
    notes), in their original order (ties: the earlier); all of them when they are not
    more than `count` or the flight does not give finite sensitivities.

    base: the model's terms (prefix lists, gpquad.engine.evolve.term_search.model_terms);
    residuals_and_jacobian(tree) -> (residuals, Jacobian): one flight with sensitivities."""
    if len(candidates) <= count:
        return list(candidates)
    new = sorted({term for insertion in candidates for term in insertion})
    prefix = _balanced_sum(base + [zero_term(t) for t in new])
    tree = Tree.from_lists([c for c, _ in prefix], [v for _, v in prefix], delays)
    residual, jac = residuals_and_jacobian(tree)
    n_new = len(new)
    if jac.shape[1] < n_new or not (np.all(np.isfinite(jac)) and np.all(np.isfinite(residual))):
        return list(candidates)
    own, added = jac[:, : jac.shape[1] - n_new], jac[:, jac.shape[1] - n_new :]
    if own.shape[1]:  # the model's own gains re-fitted: their span projected out
        q, _ = np.linalg.qr(own)
        residual = residual - q @ (q.T @ residual)
        added = added - q @ (q.T @ added)
    column = {term: k for k, term in enumerate(new)}
    scores = [
        explained(residual, added[:, [column[t] for t in insertion]]) for insertion in candidates
    ]
    best = np.argsort(-np.asarray(scores), kind="stable")[:count]
    return [candidates[k] for k in sorted(best.tolist())]
