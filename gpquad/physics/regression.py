"""Least-squares fits with R^2, standard errors and a validation-set fit (thesis IV.B-C).

Methods: "ols" (statsmodels OLS), "wls" (statsmodels WLS, feasible: weights are the inverse
of the local variance of the OLS residuals, a centred moving average of their squares over
`window` samples, for noise that grows with motor speed), "gls" (statsmodels GLSAR, AR(1)
errors estimated iteratively: successive samples of a flight are correlated), and "nls"
(scipy.optimize.least_squares with a soft-L1 robust loss; standard errors from the Jacobian).
All models here are without intercept, as the thesis's. R^2 is the centred one,
1 - SSE / sum((y - mean y)^2), on the training and on the validation set.
"""

from __future__ import annotations

import numpy as np

from gpquad.errors import GpquadError

METHODS = ("ols", "wls", "gls", "nls")


def r_squared(y: np.ndarray, fitted: np.ndarray) -> float:
    sst = float(np.sum((y - np.mean(y)) ** 2))
    return float(1.0 - np.sum((y - fitted) ** 2) / sst) if sst > 0 else float("nan")


def _local_variance(resid: np.ndarray, window: int) -> np.ndarray:
    kernel = np.ones(window) / window
    var = np.convolve(resid**2, kernel, mode="same")
    return np.maximum(var, 1e-6 * max(float(np.mean(resid**2)), 1e-300))


def fit(
    X: np.ndarray,
    y: np.ndarray,
    names: list[str],
    method: str = "ols",
    *,
    X_val: np.ndarray | None = None,
    y_val: np.ndarray | None = None,
    window: int = 25,
) -> dict:
    """Fit y = X theta; coefficients, standard errors, R^2 and RMSE (training, validation)."""
    from gpquad.extras import require

    sm = require("statsmodels.api", "the physics regressions")

    if method not in METHODS:
        raise GpquadError(
            f"unknown regression method '{method}'; use one of {METHODS}", field="regression.method"
        )
    X = np.asarray(X, dtype=float).reshape(len(y), -1)
    y = np.asarray(y, dtype=float)
    ok = np.all(np.isfinite(X), axis=1) & np.isfinite(y)
    X, y = X[ok], y[ok]
    if len(y) <= X.shape[1]:
        raise GpquadError(f"{len(y)} samples for {X.shape[1]} coefficients", field="regression")
    extra = {}
    if method == "ols":
        res = sm.OLS(y, X).fit()
        coef, se = res.params, res.bse
    elif method == "wls":
        resid = y - X @ sm.OLS(y, X).fit().params
        res = sm.WLS(y, X, weights=1.0 / _local_variance(resid, window)).fit()
        coef, se = res.params, res.bse
    elif method == "gls":
        res = sm.GLSAR(y, X, rho=1).iterative_fit(maxiter=10)
        coef, se = res.params, res.bse
        extra["rho"] = float(np.atleast_1d(res.model.rho)[0])
    else:
        from scipy.optimize import least_squares

        theta0 = np.linalg.lstsq(X, y, rcond=None)[0]
        scale = np.where(theta0 != 0, np.abs(theta0), 1.0)
        f_scale = float(np.std(y - X @ theta0)) or 1.0
        sol = least_squares(
            lambda th: X @ (th * scale) - y, theta0 / scale, loss="soft_l1", f_scale=f_scale
        )
        coef = sol.x * scale
        resid = y - X @ coef
        dof = max(len(y) - X.shape[1], 1)
        cov = np.linalg.pinv(X.T @ X) * float(resid @ resid) / dof
        se = np.sqrt(np.diag(cov))
    fitted = X @ coef
    out = {
        "method": method,
        "names": list(names),
        "coef": [float(c) for c in coef],
        "se": [float(s) for s in se],
        "r2": r_squared(y, fitted),
        "rmse": float(np.sqrt(np.mean((y - fitted) ** 2))),
        "n": int(len(y)),
        **extra,
    }
    if X_val is not None and y_val is not None:
        Xv = np.asarray(X_val, dtype=float).reshape(len(y_val), -1)
        pv = Xv @ coef
        out["r2_val"] = r_squared(np.asarray(y_val, float), pv)
        out["rmse_val"] = float(np.sqrt(np.mean((np.asarray(y_val, float) - pv) ** 2)))
        out["n_val"] = int(len(y_val))
    return out


def predict(result: dict, X: np.ndarray) -> np.ndarray:
    return np.asarray(X, dtype=float).reshape(len(X), -1) @ np.asarray(result["coef"])
