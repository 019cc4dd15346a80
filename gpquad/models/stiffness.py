"""How many RK4 steps per sample an equation needs to be fitted as the ODE it prints.

The search flies RK4 with one step per sample. For a stiff closed loop that step is no
longer the ODE: over one sample a pole at lambda dt = -1.6 keeps 0.27 of the state in one
RK4 step where the ODE keeps 0.20, at -2 0.33 against 0.14, and beyond -2.8 RK4 grows.
Fitted through it, a loop's constants are those that make the discrete map fly
(betaflight-gecko's p_dot: -40 p, |lambda| dt = 1.6), and a reader who flies the printed
ODE finely gets another vehicle. The finishing fits (gpquad.models.refine,
gpquad.models.joint_fit) therefore fly each equation with enough steps per sample that
|lambda| h <= STIFF_LIMIT, h = dt / substeps, where lambda are the
poles of the equation's loop linearised at the data:

- a rate target x (p for p_dot) with its angle a (phi): x' = c x + k a, a' = x, with
  c = df/dx and k = df/da (medians over the samples);
- a velocity target: x' = c x;
- a lag tau (tau y' + y = f): one more state, x' = y.
"""

from __future__ import annotations

import numpy as np
import sympy as sp

from gpquad.data.score import FIDELITY_SUBSTEPS
from gpquad.engine.variables import TARGET_STATE
from gpquad.models.precision import expression_values, model_rows, sample_columns

#: Largest |lambda| h of a fitted loop (at lambda h = -1 one RK4 step keeps 0.375 of the
#: state, the ODE 0.368).
STIFF_LIMIT = 1.0
#: The angle each rate integrates into (the loop an attitude controller closes).
ANGLE_OF = {"p_dot": "phi", "q_dot": "theta", "r_dot": "psi"}


def loop_speed(c: float, k: float = 0.0, tau: float = 0.0) -> float:
    """Largest |lambda| of x' = c x + k a, a' = x (k = 0: the rate alone), behind a lag
    tau (s) when tau > 0; 0 for a loop with no finite gain."""
    if not (np.isfinite(c) and np.isfinite(k) and np.isfinite(tau)):
        return 0.0
    if tau > 0:
        matrix = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [c / tau, k / tau, -1.0 / tau]])
    else:
        matrix = np.array([[c, k], [1.0, 0.0]])
    return float(np.max(np.abs(np.linalg.eigvals(matrix))))


def substeps_for(speed: float, dt: float, least: int = 1, cap: int = FIDELITY_SUBSTEPS) -> int:
    """The least power of two (from `least`, at most `cap`) of RK4 steps per sample with
    speed x dt / substeps <= STIFF_LIMIT."""
    substeps = max(1, int(least))
    while substeps < cap and speed * dt / substeps > STIFF_LIMIT:
        substeps *= 2
    return min(substeps, max(cap, int(least)))


def gains(target: str, expr: sp.Expr, values) -> tuple[float, float]:
    """(c, k): the medians over the samples of d expr / d rate and d expr / d angle (0 where
    the expression does not read it); values(expr) gives an expression's values there."""

    def median_of(symbol_name: str) -> float:
        symbol = sp.Symbol(symbol_name, real=True)
        if symbol not in expr.free_symbols:
            return 0.0
        derivative = sp.diff(expr, symbol)
        v = np.asarray(values(derivative), dtype=float)
        v = v[np.isfinite(v)]
        return float(np.median(v)) if v.size else 0.0

    c = median_of(TARGET_STATE[target])
    k = median_of(ANGLE_OF[target]) if target in ANGLE_OF else 0.0
    return c, k


def equation_substeps(target: str, expr: sp.Expr, lag: float, values, dt: float, least: int):
    """RK4 steps per sample (at least `least`) that fly the equation's loop within
    STIFF_LIMIT."""
    c, k = gains(target, expr, values)
    return substeps_for(loop_speed(c, k, lag), dt, least)


def model_substeps(model, dataset) -> int:
    """RK4 steps per sample (at least the model's own) that fly every equation of an RK4
    model within STIFF_LIMIT, its loops linearised on training samples of `dataset`; the
    model's own for a model of another scheme."""
    if model.integrator != "rk4":
        return model.substeps
    rows = model_rows(model, dataset)
    substeps = model.substeps
    if len(rows) == 0:
        return substeps
    for target, equation in model.equations.items():
        columns = sample_columns(equation, dataset.arrays, rows, raw=False)

        def values(expr, columns=columns):
            return expression_values(expr, columns, len(rows))

        substeps = max(
            substeps,
            equation_substeps(
                target, equation.sympy(), equation.lag, values, dataset.dt, model.substeps
            ),
        )
    return substeps
