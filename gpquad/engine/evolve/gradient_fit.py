"""Constants by gradient through the integrator (an optional memetic step, not in the paper).

Levenberg-Marquardt (scipy.optimize.least_squares, MINPACK) on the integrated-state
residuals of a tree over data windows, with the Jacobian from the forward-mode sensitivity
kernel (gpquad.engine.kernels.sensitivity). This is the gradient operator of
../shared/seeds/ga-gradient-parameter-identification.txt carried into GP: a coefficient
such as 28.2 or 544 is reached in a few steps instead of by Gaussian steps from U(-5, 5).

LM minimises the squared residuals; the engine's fitness may be the mean absolute error,
so the fitted tree is kept only if `error_of` (the engine's own fitness) improves.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from gpquad.engine.evolve.evaluator import Evaluator
from gpquad.engine.kernels.sensitivity import window_residuals
from gpquad.engine.tree.encoding import Tree
from gpquad.engine.tree.operators import CONST


def residuals_and_jacobian(ev: Evaluator, tree: Tree, starts, n_steps: int
                           ) -> tuple[np.ndarray, np.ndarray, int]:
    """Residuals (W * n_steps,), Jacobian (W * n_steps, n_constants), diverged windows."""
    starts = np.ascontiguousarray(starts, dtype=np.int64)
    n_c = int(np.count_nonzero(tree.codes == CONST))
    res = np.empty(len(starts) * n_steps)
    jac = np.empty((len(starts) * n_steps, n_c))
    diverged = window_residuals(tree.codes, tree.values, tree.size, tree.delays, ev.target,
                                ev.arrays, starts, int(n_steps), res, jac)
    ev.evaluations += len(starts)
    return res, jac, int(diverged)


def gauss_newton_constants(ev: Evaluator, model: Tree, error: float, starts, n_steps: int,
                           error_of, max_steps: int) -> tuple[Tree, float]:
    """LM fit of all constants of `model` on the windows `starts` (n_steps each).

    Keeps the result only if error_of(fitted) < error. max_steps bounds the number of
    residual evaluations (each one flies every window once with sensitivities).
    """
    slots = np.flatnonzero(model.codes == CONST)
    if slots.size == 0 or max_steps == 0:
        return model, error
    cache: dict = {}

    def with_values(x) -> Tree:
        values = model.values.copy()
        values[slots] = x
        return Tree(model.codes, values, model.delays)

    def evaluate(x):
        key = x.tobytes()
        if key not in cache:
            cache.clear()
            cache[key] = residuals_and_jacobian(ev, with_values(x), starts, n_steps)
        return cache[key]

    x0 = model.values[slots].copy()
    res0, _, _ = evaluate(x0)
    if not np.all(np.isfinite(res0)) or res0.size < slots.size:
        return model, error
    try:
        fit = least_squares(lambda x: evaluate(x)[0], x0, jac=lambda x: evaluate(x)[1],
                            method="lm", max_nfev=max_steps, x_scale="jac")
    except (ValueError, np.linalg.LinAlgError):  # pragma: no cover - non-finite steps
        return model, error
    if not np.all(np.isfinite(fit.x)) or np.array_equal(fit.x, x0):
        return model, error
    fitted = with_values(fit.x)
    fitted_error = float(error_of(fitted))
    if fitted_error < error:
        return fitted, fitted_error
    return model, error


def continued_constants(ev: Evaluator, model: Tree, error: float, starts, n_steps: int,
                        error_of, max_steps: int, short_windows) -> tuple[Tree, float]:
    """LM fit with a growing horizon: the direct fit on (starts, n_steps), and a fit that
    starts on each (short_starts, short_steps) of `short_windows` in turn (each from the
    last result) before the full windows; the better of the two (by error_of), if better
    than `error`.

    Short windows are nearly the one-step problem, whose error has one basin for a model
    linear in its constants; the long-window error of a stiff closed loop has many, and a
    fit from small constants stops in the wrong one (tests/test_engine_gradient.py).
    """
    best, best_error = gauss_newton_constants(ev, model, error, starts, n_steps, error_of,
                                              max_steps)
    if not short_windows:
        return best, best_error
    tree = model
    for short_starts, short_steps in short_windows:
        tree, _ = gauss_newton_constants(ev, tree, np.inf, short_starts, short_steps,
                                         lambda t: 0.0, max_steps)
    if tree is model:
        return best, best_error
    tree_error = float(error_of(tree))
    if not np.isfinite(tree_error):
        return best, best_error
    tree, tree_error = gauss_newton_constants(ev, tree, tree_error, starts, n_steps, error_of,
                                              max_steps)
    if tree_error < best_error:
        return tree, tree_error
    return best, best_error
