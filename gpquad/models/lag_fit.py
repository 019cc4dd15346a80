"""An equation's first-order lag, fitted (gpquad.engine.lag; steps of gpquad.models.refine).

`choose_lag` tries the time constants of LAG_GRID on the found equation's own terms, from
the smallest up, until RISES of them in a row fly no better than the lowest error before
them. The grid is coarse (a factor of about 1.4 between neighbours) and it is searched
before the refinement adds its terms, which then make up for a lag off the vehicle's.
`polish_lag` fits the chosen equation's time constant as one more constant: every constant
refitted through the integrator at each trial lag, the trials placed by parabolas in log
tau from the grid's neighbours (docs/decisions/2026-11-26-lag-fit.md).
"""

from __future__ import annotations

import math

import numpy as np
import sympy as sp

from gpquad.engine.lag import LAG_GRID
from gpquad.engine.threads import thread_map, thread_map_until
from gpquad.models.refine_problem import monomials

#: The lag grid's fits stop once this many time constants in a row (from the smallest up)
#: fly no better than the lowest error before them, the found equation's included: the
#: rest of the grid then changed neither the lag chosen nor the polish's start in any of
#: the grids measured (docs/decisions/2026-12-07-lag-grid-stop.md).
RISES = 2
#: Fits of the polish after its two bracketing neighbours (each one LM fit of every
#: constant through the integrator).
POLISH_FITS = 3
#: Significant digits of a fitted lag: the equations print it so
#: (gpquad.models.equation.Equation.text), and the fit is made at the printed value.
LAG_DIGITS = 3


def printed_lag(tau: float) -> float:
    """tau at the digits the equations print it with."""
    return float(f"{tau:.{LAG_DIGITS}g}")


def choose_lag(problem, expr: sp.Expr, error: float, gain: float, workers: int = 1):
    """(tau, refitted expr, its training error, every lag's fit): the LAG_GRID time
    constant whose refit of the equation's own terms flies best, if it beats the found
    equation by `gain`. The time constants are fitted from the smallest up, in up to
    `workers` threads (each on a problem of its own), until RISES in a row fly no better
    than the lowest error before them (`error` included); fits past that point are
    cancelled or dropped, so the result is the same for any number of workers.
    `problem` is a gpquad.models.refine_problem.RefineProblem; its lag is set to the one
    chosen. The fits, {tau: (expr, training error, problem at tau)}, are polish_lag's
    `known` when the chosen equation is the one returned here."""
    best = (0.0, expr, error)
    terms = monomials(expr)
    columns = np.column_stack([problem.values(m) for m in terms])  # the same for every lag

    def fitted(tau: float):
        lagged = problem.with_lag(tau)  # the one-step target is the data inverse-filtered by it
        coef, *_ = np.linalg.lstsq(columns, lagged.commanded(), rcond=None)
        start = sp.Add(*[sp.Float(float(c)) * m for c, m in zip(coef, terms, strict=True)])
        fit, fit_error = lagged.fit(start)
        return fit, fit_error if np.isfinite(fit_error) else np.inf, lagged

    def risen(results) -> bool:  # RISES in a row no lower than the lowest before them
        errors = [error] + [r[1] for r in results]
        return len(errors) > RISES and min(errors[-RISES:]) >= min(errors[:-RISES])

    taus = list(LAG_GRID[1:])
    fits = dict(zip(taus, thread_map_until(fitted, taus, workers, risen), strict=False))
    for tau, (fit, fit_error, _) in fits.items():
        if fit_error < best[2] - gain:
            best = (tau, fit, fit_error)
    problem.ev.set_lag(best[0])
    return (*best, fits)


def grid_neighbours(tau: float) -> tuple[float, float]:
    """The lags either side of tau on LAG_GRID (beyond its ends: a grid step further)."""
    grid = [t for t in LAG_GRID if t > 0]
    ratio = grid[-1] / grid[-2]
    below = [t for t in grid if t < tau]
    above = [t for t in grid if t > tau]
    return (
        below[-1] if below else printed_lag(tau / ratio),
        above[0] if above else printed_lag(tau * ratio),
    )


def parabola_vertex(points: list[tuple[float, float]]) -> float | None:
    """The abscissa of the minimum of the parabola through three (x, y) points, or None
    when it opens downwards or the points are collinear."""
    (x0, y0), (x1, y1), (x2, y2) = points
    d01, d12 = (y1 - y0) / (x1 - x0), (y2 - y1) / (x2 - x1)
    curvature = (d12 - d01) / (x2 - x0)
    if not curvature > 0:
        return None
    return 0.5 * (x0 + x1) - d01 / (2.0 * curvature)


def polish_lag(problem, expr: sp.Expr, tau: float, error: float, workers: int = 1, known=None):
    """(tau, expr, training error, the problem at that lag): `expr`, fitted at lag tau > 0
    with training error `error`, with its time constant fitted too (module notes). `known`:
    fits of the same terms at other lags already made ({tau: (expr, error, problem)},
    choose_lag's), not made again. The two grid neighbours are fitted side by side in up to
    `workers` threads, then up to
    POLISH_FITS trials at the vertex of the parabola in log tau through the best trial and
    the nearest tried either side of it (a step of the grid beyond the best when it is at
    an end of the tried). Each trial refits every constant from `expr`'s; the lags are
    printed_lag values, so the equation prints the lag it was fitted with."""
    tried = {**(known or {}), tau: (expr, error, problem)}

    def trial(t: float):
        lagged = problem.with_lag(t)
        fit, fit_error = lagged.fit(expr)
        return fit, fit_error if np.isfinite(fit_error) else np.inf, lagged

    neighbours = [t for t in grid_neighbours(tau) if t not in tried]
    tried.update(zip(neighbours, thread_map(trial, neighbours, workers), strict=True))
    for _ in range(POLISH_FITS):
        best = min(tried, key=lambda t: (tried[t][1], t))
        below = [t for t in tried if t < best]
        above = [t for t in tried if t > best]
        if below and above:
            points = [(math.log(t), tried[t][1]) for t in (max(below), best, min(above))]
            vertex = parabola_vertex(points)
            if vertex is None:
                break
            lo, hi = points[0][0], points[2][0]
            nxt = printed_lag(math.exp(min(max(vertex, lo), hi)))
        else:  # the best is the smallest or largest tried: a grid step further out
            nxt = grid_neighbours(best)[0 if not below else 1]
        if nxt in tried or not nxt > 0:
            break
        tried[nxt] = trial(nxt)
    best = min(tried, key=lambda t: (tried[t][1], t))
    fit, fit_error, lagged = tried[best]
    return best, fit, fit_error, lagged
