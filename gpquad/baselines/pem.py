"""Prediction-error method on the body-centric model (paper section 4).

E(Theta) = 1/N sum_t eps(t)^T Lambda eps(t), eps = y - y_hat (eq. 17), with
Lambda = diag(1 / mean|y_i|^2) (eq. 18) from the measured outputs. y_hat comes from the
closed-loop predictor: model (10) with the known controller driven by the references, so
the predictor stays stable. The search runs in x = Theta / Theta_0 with bounds
[1/f, f] (f = 10: one order of magnitude) and the perpendicular-axis inequalities (20).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from scipy.optimize import Bounds, LinearConstraint, minimize

from gpquad.baselines.pem_config import PemConfig
from gpquad.baselines.pem_sim import PemRecord, predict

#: E of a predictor that left the finite range (scipy needs a number).
DIVERGED = 1e6


def weights(y: np.ndarray) -> np.ndarray:
    """Lambda diagonal (9,) of eq. (18): 1 / mean(|y_i|)^2."""
    return 1.0 / np.maximum(np.mean(np.abs(y), axis=0), 1e-12) ** 2


def residuals(y: np.ndarray, y_hat: np.ndarray) -> np.ndarray:
    """y - y_hat (N, 9) with the angle columns wrapped to (-pi, pi]."""
    eps = y - y_hat
    eps[:, :3] = np.angle(np.exp(1j * eps[:, :3]))
    return eps


def error(
    theta, cfg: PemConfig, rec: PemRecord, y: np.ndarray, lam: np.ndarray, closed: bool = True
) -> float:
    """E(Theta) of eq. (17) on a record; y (N, 9) measured outputs (noisy or not)."""
    drive = rec.refs if closed else rec.speeds
    states, acc, _ = predict(theta, cfg, drive, closed, y[0, :3], y[0, 3:6], rec.dt)
    y_hat = np.hstack([states[:, :3], states[:, 6:9], acc])
    if not np.all(np.isfinite(y_hat)):
        return DIVERGED
    eps = residuals(y, y_hat)
    return float(min(np.mean(np.einsum("ni,i,ni->n", eps, lam, eps)), DIVERGED))


def perpendicular_axis_matrix(theta0: np.ndarray) -> np.ndarray:
    """A with A x >= 0 for eq. (20) in scaled variables x = Theta / Theta_0."""
    i = theta0[:3]
    A = np.zeros((3, 6))
    for row, (a, b, c) in enumerate(((0, 1, 2), (1, 0, 2), (2, 0, 1))):
        A[row, a], A[row, b], A[row, c] = -i[a], i[b], i[c]
    return A


@dataclass
class PemFit:
    theta: np.ndarray
    theta0: np.ndarray
    e_initial: float
    e_refined: float
    iterations: int
    evaluations: int
    fit_time_s: float
    message: str


def fit(
    cfg: PemConfig, rec: PemRecord, y: np.ndarray, theta0: np.ndarray, closed: bool = True
) -> PemFit:
    """Minimise E from theta0 with scipy (SLSQP or trust-constr), bounds and eq. (20)."""
    p = cfg.pem
    lam = weights(y)
    count = [0]

    def objective(x):
        count[0] += 1
        return error(x * theta0, cfg, rec, y, lam, closed)

    e0 = objective(np.ones(6))
    bounds = Bounds(np.full(6, 1.0 / p.bound_factor), np.full(6, p.bound_factor))
    cons = []
    if p.constraints:
        cons = [LinearConstraint(perpendicular_axis_matrix(theta0), 0.0, np.inf)]
    t0 = time.perf_counter()
    if p.method == "SLSQP":
        res = minimize(
            objective,
            np.ones(6),
            method="SLSQP",
            bounds=bounds,
            constraints=cons,
            options={"maxiter": p.max_iter, "ftol": p.tolerance},
        )
    else:
        res = minimize(
            objective,
            np.ones(6),
            method="trust-constr",
            bounds=bounds,
            constraints=cons,
            options={"maxiter": p.max_iter, "gtol": p.tolerance, "xtol": p.tolerance},
        )
    x = np.clip(res.x, bounds.lb, bounds.ub)
    theta = x * theta0
    return PemFit(
        theta,
        theta0,
        e0,
        error(theta, cfg, rec, y, lam, closed),
        int(getattr(res, "nit", 0)),
        count[0],
        time.perf_counter() - t0,
        str(res.message),
    )


def divergence_times(
    theta, cfg: PemConfig, rec: PemRecord, window_s: float, limit_rad: float
) -> dict[str, np.ndarray]:
    """Seconds until the predicted attitude is off by more than limit_rad, per window.

    Windows of window_s tile the record; each starts from the recorded state and flies
    in open loop (recorded motor speeds, held over each sample) and in closed loop
    (references through the controller). A window that never diverges reports window_s.
    """
    n = int(round(window_s / rec.dt))
    out = {"open": [], "closed": []}
    for start in range(0, len(rec.t) - n, n):
        part = rec.head(start + n)
        y = part.outputs()[start:]
        for mode, closed in (("open", False), ("closed", True)):
            drive = (part.refs if closed else part.speeds)[start:]
            states, _, _ = predict(theta, cfg, drive, closed, y[0, :3], y[0, 3:6], rec.dt)
            err = np.abs(np.angle(np.exp(1j * (states[:, :3] - y[:, :3])))).max(axis=1)
            bad = np.flatnonzero(~(err <= limit_rad))
            out[mode].append(bad[0] * rec.dt if bad.size else window_s)
    return {k: np.array(v) for k, v in out.items()}
