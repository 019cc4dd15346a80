"""Which term insertions are worth a fit through the integrator.

Term insertion (gpquad.engine.evolve.term_search) offers every variable, product and pair
of variables: 182 candidates with 13 variables, each re-fitted through the integrator.
Most of them explain nothing the model misses. The screen ranks them by how much of the
target's one-step acceleration (the data's, at the suite's samples) a least-squares fit of
the model's terms, the new ones and an intercept explains beyond the model's terms alone
(every gain re-fitted, as the integrated fit will), and only the best SCREENED are fitted.
The choice among those is still made on the integrated error: the one-step fit only orders
the candidates.
"""

from __future__ import annotations

import numpy as np

from gpquad.engine.kernels.tree_eval import eval_on_samples
from gpquad.engine.tree.encoding import Tree
from gpquad.engine.tree.operators import VAR_BASE

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


def _column(arrays, delays, samples, variable: int) -> np.ndarray:
    tree = Tree.from_lists([VAR_BASE + variable], [0.0], delays)
    return eval_on_samples(
        tree.codes, tree.values, 1, tree.delays, arrays.states, arrays.inputs, samples
    )


def explained(residual: np.ndarray, columns: list[np.ndarray]) -> float:
    """Sum of squares of `residual` that a least-squares fit on `columns` and an intercept
    removes (0 for a column that is constant or not finite)."""
    x = np.column_stack(columns)
    if not np.all(np.isfinite(x)):
        return 0.0
    x = x - x.mean(axis=0)
    r = residual - residual.mean()
    coef, *_ = np.linalg.lstsq(x, r, rcond=None)
    fitted = x @ coef
    return float(r @ r - (r - fitted) @ (r - fitted))


def _residual_maker(base: list[np.ndarray]):
    """x -> x minus its least-squares projection on the base columns and an intercept."""
    design = np.column_stack([np.ones(len(base[0]) if base else 0)] + base) if base else None
    if design is None or not np.all(np.isfinite(design)):
        return lambda x: x - x.mean()
    q, _ = np.linalg.qr(design)
    return lambda x: x - q @ (q.T @ x)


def screened(
    base: list[np.ndarray],
    acc: np.ndarray,
    arrays,
    delays,
    samples,
    candidates: list[Insertion],
    count: int = SCREENED,
) -> list[Insertion]:
    """The `count` insertions of `candidates` that explain most of the target's one-step
    acceleration `acc` at `samples` beyond what the model's terms explain, all gains
    re-fitted (base: each term's values at the samples), in their original order (ties: the
    earlier); all of them when they are not more than `count` or a value is not finite."""
    if len(candidates) <= count:
        return list(candidates)
    samples = np.ascontiguousarray(samples, dtype=np.int64)
    if not np.all(np.isfinite(acc)) or not all(np.all(np.isfinite(b)) for b in base):
        return list(candidates)
    project_out = _residual_maker(base)
    residual = project_out(acc)
    variables = sorted({v for new in candidates for term in new for v in term})
    column = {v: _column(arrays, delays, samples, v) for v in variables}
    products: dict[tuple[int, ...], np.ndarray] = {}
    for new in candidates:
        for term in new:
            if term not in products:
                values = np.prod([column[v] for v in term], axis=0)
                products[term] = project_out(values) if np.all(np.isfinite(values)) else values
    scores = [explained(residual, [products[term] for term in new]) for new in candidates]
    best = np.argsort(-np.asarray(scores), kind="stable")[:count]
    return [candidates[k] for k in sorted(best.tolist())]
