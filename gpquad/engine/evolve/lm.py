"""Least-squares fits whose result is a function of their inputs: MINPACK mode 2 LM for the
search's short constant fits, scipy's trust-region reflective solver for long fits.

scipy 1.17.1's `least_squares(method="lm")` and `leastsq` without `diag` (MINPACK mode 1,
scaling from the Jacobian's column norms, updated as it goes) take other trial points for
bit-identical inputs depending on which least-squares fits ran before in the process
(`benchmarks/lm_state.py` reproduces it on one of the engine's problems); the search
amplifies that into other equations for the same seed in another process. With `diag`
given (mode 2: fixed scaling) the same replay is usually stable, not always (it stepped
elsewhere in one of about twenty runs, once in CI); the search's short fits use it (p_dot
of rotorpy-angle crazyflie seed 1 came out bit-identical after three process histories),
and moving them to `trust_region` is the next step (it changes the search's trajectories,
so it needs the benchmark re-measured). The scaling here is the column
norms of the first Jacobian, what mode 1 starts from. Without an analytic Jacobian,
`forward_difference` gives one (scipy's '2-point' step) whose result is also a function of
the inputs alone.

Mode 2 is not enough for long fits: the joint refit's LM (80 constants, about 50 MINPACK
evaluations) took another trial point at its 19th evaluation, after bit-identical
residuals and Jacobians, when the process had run other fits before, or when the Jacobian
callable was wrapped (rotorpy-angle, crazyflie, seed 2: p_dot's -23.0351 p against -23.1587
p). `trust_region` therefore uses scipy's trust-region reflective solver, which is numpy
code (an SVD per step) with no state outside the call, for such fits.
"""

from __future__ import annotations

import warnings

import numpy as np
from scipy.optimize import least_squares, leastsq

#: Relative step of the forward differences: sqrt(machine epsilon), scipy's '2-point' step.
FD_STEP = float(np.sqrt(np.finfo(float).eps))


def column_norms(jac, x0: np.ndarray) -> np.ndarray:
    """The fixed variable scaling of both fits: the column norms of jac(x0), 1 where a column
    is zero or not finite."""
    norms = np.linalg.norm(np.asarray(jac(x0), dtype=float), axis=0)
    return np.where(np.isfinite(norms) & (norms > 0.0), norms, 1.0)


def levenberg_marquardt(fun, x0: np.ndarray, jac, max_nfev: int) -> np.ndarray:
    """Minimise sum(fun(x)^2) from x0 with the analytic Jacobian jac(x) (rows = residuals);
    returns x (x0 when MINPACK stops at once). MINPACK gets max_nfev + 1 evaluations, one
    more than the `least_squares` call this replaced gave it (the measured setting). jac(x0)
    is called once more than MINPACK calls it: a caller that caches it pays nothing."""
    x0 = np.asarray(x0, dtype=float)
    diag = column_norms(jac, x0)
    # full_output=False: no covariance (it overflows on the stiff fits and is not used); the
    # budget is meant to run out, so leastsq's "reached maxfev" warning is not shown
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="Number of calls to function has reached",
                                category=RuntimeWarning)
        x, _ = leastsq(fun, x0, Dfun=jac, full_output=False, maxfev=int(max_nfev) + 1,
                       diag=diag)
    return np.atleast_1d(np.asarray(x, dtype=float))


def trust_region(fun, x0: np.ndarray, jac, max_nfev: int, ftol: float) -> np.ndarray:
    """Minimise sum(fun(x)^2) from x0 with scipy's trust-region reflective method (no
    bounds, exact SVD steps) and the variables scaled, fixed, by the first Jacobian's column
    norms; at most max_nfev residual evaluations (jac's are not counted); stops when a step
    lowers the sum by less than the fraction ftol. Returns x, whose sum is never above
    x0's (a step is taken only when it lowers the sum)."""
    x0 = np.asarray(x0, dtype=float)
    fit = least_squares(fun, x0, jac=jac, method="trf", tr_solver="exact",
                        x_scale=1.0 / column_norms(jac, x0), ftol=ftol, max_nfev=int(max_nfev))
    return np.asarray(fit.x, dtype=float)


def forward_difference(fun):
    """(value, jac) for a residual function without an analytic Jacobian: value(x) is fun(x)
    remembered at the last point asked, jac(x) the forward-difference Jacobian there with
    step FD_STEP * max(1, |x_j|) (signed like x_j, as scipy's '2-point'), also remembered,
    so that LM's repeated requests at one point cost one evaluation each."""
    memo: dict[str, tuple[bytes, np.ndarray]] = {}

    def remembered(name, x, compute):
        key = np.asarray(x, dtype=float).tobytes()
        if name not in memo or memo[name][0] != key:
            memo[name] = (key, compute(np.array(x, dtype=float)))
        return memo[name][1]

    def value(x):
        return remembered("f", x, lambda v: np.asarray(fun(v), dtype=float))

    def jacobian(x):
        f0 = value(x)
        h = FD_STEP * np.where(x >= 0.0, 1.0, -1.0) * np.maximum(1.0, np.abs(x))
        columns = []
        for j in range(x.size):
            shifted = x.copy()
            shifted[j] += h[j]
            columns.append((np.asarray(fun(shifted), dtype=float) - f0) / (shifted[j] - x[j]))
        return np.column_stack(columns)

    return value, (lambda x: remembered("jac", x, jacobian))
