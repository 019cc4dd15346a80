"""Constants by gradient through the integrator (an optional memetic step, not in the paper).

Levenberg-Marquardt (gpquad.engine.evolve.lm: MINPACK's algorithm in numba loops) on the
integrated-state residuals of a tree over data windows, with the Jacobian from the
forward-mode sensitivity kernel (gpquad.engine.kernels.sensitivity). This is the gradient
operator of ../shared/seeds/ga-gradient-parameter-identification.txt carried into GP: a
coefficient such as 28.2 or 544 is reached in a few steps instead of by Gaussian steps from
U(-5, 5).

LM minimises the squared residuals; the engine's fitness may be the mean absolute error,
so the fitted tree is kept only if `error_of` (the engine's own fitness) improves.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import qr

from gpquad.engine.evolve.evaluator import Evaluator
from gpquad.engine.evolve.lm import column_norms, levenberg_marquardt
from gpquad.engine.kernels import least_squares
from gpquad.engine.kernels.fitness import population_window_errors
from gpquad.engine.kernels.sensitivity import residual_rows, window_residuals
from gpquad.engine.kernels.step import RK4
from gpquad.engine.kernels.tree_eval import check_stack
from gpquad.engine.tree.encoding import Tree
from gpquad.engine.tree.operators import CONST

#: Relative drop of the squared residuals (actual and predicted) below which the search's
#: LM fits stop: a fit that gains less is as good for ranking trees, and the finishing
#: steps refit with MINPACK's FTOL (docs/decisions/2026-11-26-speed.md).
SEARCH_FTOL = 1e-4
#: A constant is held fixed when its Jacobian column is this close to a combination of the
#: others (relative pivot of the pivoted QR, unit-norm columns).
IDENTIFIABLE_RTOL = 1e-9
#: Smallest / largest eigenvalue of the unit columns' Gram matrix above which every column
#: is identifiable without the QR (condition number below 1e5, far from 1 / rtol).
GRAM_FULL_RANK = 1e-10


def _flight_rows(ev: Evaluator, tree: Tree, starts, n_steps: int) -> tuple[np.ndarray, int]:
    """(the window starts as the kernels take them, the residual rows of their flight)."""
    check_stack(tree.codes, tree.size)
    starts = np.ascontiguousarray(starts, dtype=np.int64)
    return starts, len(starts) * n_steps * residual_rows(ev.target, ev.att_weight)


def residuals_and_jacobian(
    ev: Evaluator, tree: Tree, starts, n_steps: int
) -> tuple[np.ndarray, np.ndarray, int]:
    """Residuals (W * n_steps * rows,), Jacobian (same rows, n_constants), diverged windows;
    rows = 2 when the evaluator scores the attitude too (gpquad.engine.kernels.sensitivity)."""
    starts, rows = _flight_rows(ev, tree, starts, n_steps)
    n_c = int(np.count_nonzero(tree.codes == CONST))
    res = np.empty(rows)
    jac = np.empty((rows, n_c))
    diverged = window_residuals(
        tree.codes,
        tree.values,
        tree.size,
        tree.delays,
        ev.target,
        ev.arrays,
        starts,
        int(n_steps),
        ev.att_weight,
        ev.angle_tangents,
        ev.alpha,
        res,
        jac,
        ev.scheme,
        ev.substeps,
    )
    ev.evaluations += len(starts)
    return res, jac, int(diverged)


def residuals_only(ev: Evaluator, tree: Tree, starts, n_steps: int) -> np.ndarray | None:
    """residuals_and_jacobian's residuals to the bit, without the Jacobian, from the RK4
    fitness kernel (its windows flown as lanes: a quarter to a half of the sensitivity
    flight's time). None for the eq. 2 scheme: its fits take most of their trial points
    (about 80 % in a search), where the Jacobian would be flown a second time, so LM flies
    each trial with the Jacobian there (docs/decisions/2026-11-27-lanes-and-trials.md)."""
    if ev.scheme != RK4:
        return None
    starts, rows = _flight_rows(ev, tree, starts, n_steps)
    res = np.empty(rows)
    codes, values, sizes, delays = ev.pack([tree])
    population_window_errors(
        codes,
        values,
        sizes,
        delays,
        ev.target,
        ev.arrays,
        starts,
        int(n_steps),
        False,
        ev.att_weight,
        ev.alpha,
        np.full(1, np.inf),
        np.empty((1, len(starts))),
        ev.scheme,
        ev.substeps,
        res,
    )
    ev.evaluations += len(starts)
    return res


def identifiable(jac: np.ndarray, rtol: float = IDENTIFIABLE_RTOL) -> np.ndarray:
    """Columns of a Jacobian whose constants the residuals can tell apart: a maximal set of
    linearly independent columns (pivoted QR of the unit-norm columns, pivots above rtol x
    the largest), in ascending order.

    A tree can hold constants that only act together (c1 + (c2 + x), or c1 * (c2 * x)):
    their columns are equal or proportional, the least-squares problem is singular along
    a line, and LM drifts along it by round-off. Measured before this check: the constant
    term of median-noisy's p_dot came out as two cancelling constants of size 6e9 and 4e11
    whose sum, the only thing the data fixes, then differed at 1e-5 between two runs of the
    same seed. The others are held fixed at their current values.
    """
    norms = np.sqrt((jac * jac).sum(axis=0))
    live = np.flatnonzero(norms > 0)
    if live.size == 0:
        return live
    unit = jac[:, live] / norms[live]
    # Shortcut, same answer: every pivot satisfies |r_kk| / |r_11| >= 1 / cond(unit), and
    # cond(unit) < 1e5 (eigenvalues of the Gram matrix, exact to ~1e-16 of the largest) puts
    # all columns far above rtol. The Gram matrix costs a fraction of the pivoted QR.
    gram = np.linalg.eigvalsh(unit.T @ unit)
    if np.sqrt(GRAM_FULL_RANK) > rtol and gram[0] > GRAM_FULL_RANK * gram[-1]:
        return live
    _, r, pivots = qr(unit, mode="economic", pivoting=True)
    diag = np.abs(np.diag(r))
    rank = int(np.count_nonzero(diag > rtol * diag[0]))
    return np.sort(live[pivots[:rank]])


def gauss_newton_step(ev: Evaluator, tree: Tree, starts, n_steps: int) -> Tree | None:
    """`tree` after one undamped Gauss-Newton step in all its identifiable constants, on the
    integrated-state residuals of the windows (one residual-and-Jacobian flight: the cost
    of one LM iteration); None when a window diverges, the flight is not finite or the step
    is singular."""
    res, jac, diverged = residuals_and_jacobian(ev, tree, starts, n_steps)
    if diverged:
        return None
    return step_from(tree, res, jac)


def step_from(tree: Tree, res: np.ndarray, jac: np.ndarray) -> Tree | None:
    """`tree` after one undamped Gauss-Newton step on residuals `res` with Jacobian `jac`
    (one column per constant of the tree, in prefix order; see gauss_newton_step); None
    when they are not finite or the step is singular."""
    if not np.all(np.isfinite(res)) or not np.all(np.isfinite(jac)):
        return None
    free = identifiable(jac)
    if free.size == 0:
        return None
    j = np.ascontiguousarray(jac[:, free])
    n = free.size
    scale = column_norms(j)
    r, qtr, h = np.zeros((n, n)), np.zeros(n), np.zeros(n)
    least_squares.triangularize(j, scale, res, r, qtr)
    if least_squares.damped_step(r, qtr, 0.0, h) < 0.0:
        return None
    values = tree.values.copy()
    values[np.flatnonzero(tree.codes == CONST)[free]] += h / scale
    return Tree(tree.codes, values, tree.delays)


def gauss_newton_constants(
    ev: Evaluator,
    model: Tree,
    error: float,
    starts,
    n_steps: int,
    error_of,
    max_steps: int,
    ftol: float = SEARCH_FTOL,
    stall: tuple[int, float] | None = None,
) -> tuple[Tree, float]:
    """LM fit of all constants of `model` on the windows `starts` (n_steps each).

    Keeps the result only if error_of(fitted) < error. max_steps bounds the number of
    residual evaluations (each one flies every window once with sensitivities); ftol is
    the LM's relative-drop tolerance and `stall` its stall rule (gpquad.engine.evolve.lm).
    """
    slots = np.flatnonzero(model.codes == CONST)
    if slots.size == 0 or max_steps == 0:
        return model, error
    cache: dict = {}  # the last point's (residuals, Jacobian or None)

    def with_values(x) -> Tree:
        values = model.values.copy()
        values[slots] = x
        return Tree(model.codes, values, model.delays)

    def evaluate(x, jacobian: bool = True):
        """(residuals, Jacobian) at x; with jacobian False the Jacobian may be None: LM
        asks for it at the points it takes only, a fraction of its trials, and where the
        residuals alone cost less (residuals_only) they are flown alone."""
        key = x.tobytes()
        found = cache.get(key)
        if found is None or (jacobian and found[1] is None):
            cache.clear()
            res = None if jacobian else residuals_only(ev, with_values(x), starts, n_steps)
            if res is None:
                res, jac, _ = residuals_and_jacobian(ev, with_values(x), starts, n_steps)
                found = (res, jac)
            else:
                found = (res, None)
            cache[key] = found
        return found

    x0 = model.values[slots].copy()
    res0, jac0 = evaluate(x0)
    if not np.all(np.isfinite(res0)) or res0.size < slots.size or not np.all(np.isfinite(jac0)):
        return model, error
    free = identifiable(jac0)
    if free.size == 0:
        return model, error

    # every constant fitted (the usual case): the Jacobian itself, a view, not a copy
    columns = slice(None) if free.size == slots.size else free

    def full(x_free):
        x = x0.copy()
        x[free] = x_free
        return x

    try:
        x_fit = levenberg_marquardt(
            lambda x: evaluate(full(x), jacobian=False)[0],
            x0[free],
            lambda x: evaluate(full(x))[1][:, columns],
            max_steps,
            ftol=ftol,
            stall=stall,
        )
    except (ValueError, np.linalg.LinAlgError):  # pragma: no cover - non-finite steps
        return model, error
    if not np.all(np.isfinite(x_fit)) or np.array_equal(x_fit, x0[free]):
        return model, error
    fitted = with_values(full(x_fit))
    fitted_error = float(error_of(fitted))
    if fitted_error < error:
        return fitted, fitted_error
    return model, error


def continued_constants(
    ev: Evaluator,
    model: Tree,
    error: float,
    starts,
    n_steps: int,
    error_of,
    max_steps: int,
    short_windows,
    ftol: float = SEARCH_FTOL,
    stall: tuple[int, float] | None = None,
    direct: tuple[Tree, float] | None = None,
) -> tuple[Tree, float]:
    """LM fit with a growing horizon: the direct fit on (starts, n_steps), and a fit that
    starts on each (short_starts, short_steps) of `short_windows` in turn (each from the
    last result) before the full windows; the better of the two (by error_of), if better
    than `error`. direct: the direct fit's result (tree, error), when it was made already
    (the refinement ranks its candidates by it).

    Short windows are nearly the one-step problem, whose error has one basin for a model
    linear in its constants; the long-window error of a stiff closed loop has many, and a
    fit from small constants stops in the wrong one (tests/test_engine_gradient.py).
    ftol: the LM's relative-drop tolerance (SEARCH_FTOL in the search, lm.FTOL to finish);
    stall: its stall rule (refine_problem.STALL in the refinement, lm.STALL in the BIC
    selection), both passed to every fit.
    """
    if direct is None:
        direct = gauss_newton_constants(
            ev, model, error, starts, n_steps, error_of, max_steps, ftol, stall
        )
    best, best_error = direct
    if not short_windows:
        return best, best_error
    tree = model
    for short_starts, short_steps in short_windows:
        tree, _ = gauss_newton_constants(
            ev, tree, np.inf, short_starts, short_steps, lambda t: 0.0, max_steps, ftol, stall
        )
    if tree is model:
        return best, best_error
    tree_error = float(error_of(tree))
    if not np.isfinite(tree_error):
        return best, best_error
    tree, tree_error = gauss_newton_constants(
        ev, tree, tree_error, starts, n_steps, error_of, max_steps, ftol, stall
    )
    if tree_error < best_error:
        return tree, tree_error
    return best, best_error
