"""Levenberg-Marquardt whose result is a function of its inputs (MINPACK mode 2).

scipy 1.17.1's `least_squares(method="lm")` and `leastsq` without `diag` (MINPACK mode 1,
scaling from the Jacobian's column norms, updated as it goes) take other trial points for
bit-identical inputs depending on which least-squares fits ran before in the process
(`benchmarks/lm_state.py` reproduces it on one of the engine's problems); the search
amplifies that into other equations for the same seed in another process. With `diag`
given (mode 2: fixed scaling) the same replay is stable. The scaling here is the column
norms of the first Jacobian, what mode 1 starts from.
"""

from __future__ import annotations

import warnings

import numpy as np
from scipy.optimize import leastsq


def levenberg_marquardt(fun, x0: np.ndarray, jac, max_nfev: int) -> np.ndarray:
    """Minimise sum(fun(x)^2) from x0 with the analytic Jacobian jac(x) (rows = residuals);
    returns x (x0 when MINPACK stops at once). MINPACK gets max_nfev + 1 evaluations, one
    more than the `least_squares` call this replaced gave it (the measured setting). jac(x0)
    is called once more than MINPACK calls it: a caller that caches it pays nothing."""
    x0 = np.asarray(x0, dtype=float)
    norms = np.linalg.norm(np.asarray(jac(x0), dtype=float), axis=0)
    diag = np.where(np.isfinite(norms) & (norms > 0.0), norms, 1.0)
    # full_output=False: no covariance (it overflows on the stiff fits and is not used); the
    # budget is meant to run out, so leastsq's "reached maxfev" warning is not shown
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="Number of calls to function has reached",
                                category=RuntimeWarning)
        x, _ = leastsq(fun, x0, Dfun=jac, full_output=False, maxfev=int(max_nfev) + 1,
                       diag=diag)
    return np.atleast_1d(np.asarray(x, dtype=float))
