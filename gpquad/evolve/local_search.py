"""Deterministic local search on one model (an optional memetic step, not in the paper).

The paper's hill climbers change structure, constants and delays only together,
so a right delay or a far-off constant (28.2 from U(-5, 5)) is found slowly.
These two searches polish a model in place and keep the result only if it is
strictly better on the current suite.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import minimize

from gpquad.evolve.evaluator import Evaluator
from gpquad.tree.encoding import Tree
from gpquad.tree.operators import CONST


def improve_delays(ev: Evaluator, model: Tree, error: float, suite, max_delay: int,
                   refit_evals: int = 0) -> tuple[Tree, float]:
    """Try every other delay of every used input, one at a time; keep the best if better.

    A wrong delay is usually compensated by wrong constants, so with refit_evals > 0
    each candidate's constants are re-fitted (Nelder-Mead) before it is compared.
    """
    candidates = []
    for j in sorted(model.used_inputs()):
        for d in range(max_delay + 1):
            if d != model.delays[j]:
                delays = model.delays.copy()
                delays[j] = d
                candidates.append(Tree(model.codes, model.values, delays))
    if not candidates:
        return model, error
    errors = ev.mean_errors(candidates, suite)
    if refit_evals > 0:
        for k, candidate in enumerate(candidates):
            candidates[k], errors[k] = improve_constants(ev, candidate, errors[k], suite,
                                                         refit_evals)
    best = int(np.argmin(errors))
    if errors[best] < error:
        return candidates[best], float(errors[best])
    return model, error


def improve_constants(ev: Evaluator, model: Tree, error: float, suite, max_evals: int
                      ) -> tuple[Tree, float]:
    """Nelder-Mead on all constants of the tree, at most max_evals evaluations."""
    slots = np.flatnonzero(model.codes == CONST)
    if slots.size == 0 or max_evals == 0:
        return model, error

    def with_values(x) -> Tree:
        values = model.values.copy()
        values[slots] = x
        return Tree(model.codes, values, model.delays)

    def objective(x) -> float:
        err = ev.mean_errors([with_values(x)], suite)[0]
        return float(err) if np.isfinite(err) else 1e300

    res = minimize(objective, model.values[slots], method="Nelder-Mead",
                   options={"maxfev": max_evals, "xatol": 1e-10, "fatol": 1e-14})
    if res.fun < error:
        return with_values(res.x), float(res.fun)
    return model, error
