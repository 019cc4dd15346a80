"""Deterministic local search on one model (an optional memetic step, not in the paper).

The paper's hill climbers change structure, constants and delays only together,
so a right delay or a far-off constant (28.2 from U(-5, 5)) is found slowly.
These two searches polish a model in place and keep the result only if it is
strictly better on the current suite.
"""

from __future__ import annotations

import numpy as np

from gpquad.engine.evolve.evaluator import Evaluator
from gpquad.engine.tree.encoding import Tree
from gpquad.engine.tree.operators import CONST


def improve_delays(
    ev: Evaluator, model: Tree, error: float, suite, max_delay: int, refit_evals: int = 0, fit=None
) -> tuple[Tree, float]:
    """Try every other delay of every used input, one at a time; keep the best if better.

    A wrong delay is usually compensated by wrong constants, so with refit_evals > 0
    (or a `fit`) each candidate's constants are re-fitted before it is compared.
    fit(tree, error, starts, n_steps) -> (tree, error) replaces Nelder-Mead when given.
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
    if refit_evals > 0 or fit is not None:
        for k, candidate in enumerate(candidates):
            candidates[k], errors[k] = improve_constants(
                ev, candidate, errors[k], suite, refit_evals, fit
            )
    best = int(np.argmin(errors))
    if errors[best] < error:
        return candidates[best], float(errors[best])
    return model, error


def fit_constants(model: Tree, error: float, error_of, max_evals: int) -> tuple[Tree, float]:
    """Nelder-Mead on all constants of the tree against error_of(tree); keeps improvements."""
    from scipy.optimize import minimize  # the LM engine (the default) loads no scipy.optimize

    slots = np.flatnonzero(model.codes == CONST)
    if slots.size == 0 or max_evals == 0:
        return model, error

    def with_values(x) -> Tree:
        values = model.values.copy()
        values[slots] = x
        return Tree(model.codes, values, model.delays)

    def objective(x) -> float:
        err = error_of(with_values(x))
        return float(err) if np.isfinite(err) else 1e300

    res = minimize(
        objective,
        model.values[slots],
        method="Nelder-Mead",
        options={"maxfev": max_evals, "xatol": 1e-10, "fatol": 1e-14},
    )
    if res.fun < error:
        return with_values(res.x), float(res.fun)
    return model, error


def improve_constants(
    ev: Evaluator, model: Tree, error: float, suite, max_evals: int, fit=None
) -> tuple[Tree, float]:
    """Nelder-Mead (or `fit`, see improve_delays) on the constants against the mean error
    on the suite windows."""
    if fit is not None:
        return fit(model, error, suite, ev.n_steps)
    return fit_constants(model, error, lambda t: ev.mean_errors([t], suite)[0], max_evals)


def prune(
    ev: Evaluator,
    model: Tree,
    starts,
    n_steps: int,
    allowance: float,
    evals: int,
    constant_of,
    fit=None,
) -> tuple[Tree, float]:
    """Remove bloat from a final model: replace subtrees by constants while the error stays
    below the starting error plus `allowance` (same units as the error).

    Subtrees are tried largest first; each candidate's constants are re-fitted by
    Nelder-Mead (`evals` evaluations) or by `fit` (see improve_delays).
    constant_of(tree, start, end) gives the constant that replaces tree.codes[start:end].
    Errors are measured on `starts` windows.
    """
    from gpquad.engine.tree.variation import fold_constants, subtrees_as_constants

    def error_of(tree: Tree) -> float:
        return float(ev.window_errors([tree], starts, n_steps=n_steps).mean())

    def refit(tree: Tree, err: float) -> tuple[Tree, float]:
        if fit is not None:
            return fit(tree, err, starts, n_steps)
        return fit_constants(tree, err, error_of, evals)

    model = fold_constants(model)
    base = error_of(model)
    limit = base + allowance
    model, err = refit(model, base)
    changed = True
    while changed and model.size > 1:
        changed = False
        for candidate in subtrees_as_constants(model, constant_of):
            candidate, cand_err = refit(candidate, error_of(candidate))
            if cand_err <= limit:
                model, err, changed = candidate, cand_err, True
                break
    return model, err
