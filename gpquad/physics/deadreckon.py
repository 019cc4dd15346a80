"""Dead-reckoning position with four acceleration models (thesis section V, Table III).

All four integrate the body velocity V from its true value at the window start, with the
measured attitude R_k (body to world) and rotor speeds, and the model's body specific force f:

- "accelerometer": f = (drag x, drag y, measured f_z)    (drag compensated in x, y only)
- "base":          f = (drag x, drag y, standard thrust eq. 5 / m)
- "refined":       f = (drag x, drag y, refined thrust eq. 19 / m)
- "coriolis":      the refined f, and the Coriolis term of eq. (4), -Omega x V.

Without the Coriolis term:  V_{k+1} = V_k + dt (f_k + R_k^T g)   (the body velocity is not
turned with the body). With it, the term is integrated exactly over the step as the rotation
of the velocity into the new body frame:  V_{k+1} = R_{k+1}^T R_k (V_k + dt (f_k + R_k^T g)).
Position: trapezoid on R V. The drag and refined-thrust terms read the model's own V estimate
(dead reckoning has no other velocity).
"""

from __future__ import annotations

import numpy as np

from gpquad.physics.aero import drag_specific_force, thrust_specific_force

MODELS = ("accelerometer", "base", "refined", "coriolis")
GRAVITY = np.array([0.0, 0.0, -9.81])


def _specific_force(
    model: str, V: np.ndarray, rotor: np.ndarray, f_meas_z: float, coef: dict, mass: float
) -> np.ndarray:
    fxy = drag_specific_force(coef["drag"], rotor, V)
    if model == "accelerometer":
        fz = f_meas_z
    elif model == "base":
        fz = thrust_specific_force(coef["standard"], "standard", rotor[None], V[None], mass)[0]
    else:
        fz = thrust_specific_force(coef["refined"], "refined", rotor[None], V[None], mass)[0]
    return np.array([fxy[0], fxy[1], fz])


def integrate(
    model: str, meas: dict, coef: dict, mass: float, start: int = 0, stop: int | None = None
) -> np.ndarray:
    """Positions (n, 3) from `start` to `stop` (exclusive) estimated by one model.

    meas: t, pos, vel (world), rot (N, 3, 3), rotor, force (measured specific force).
    coef: {"drag": {k_dx, k_dy[, c_dx, c_dy]}, "standard": {k_t}, "refined": {k_t, k_z, k_h}}.
    """
    if model not in MODELS:
        raise ValueError(f"unknown model {model!r}")
    stop = len(meas["t"]) if stop is None else stop
    t, rot, rotor, force = meas["t"], meas["rot"], meas["rotor"], meas["force"]
    pos = np.empty((stop - start, 3))
    pos[0] = meas["pos"][start]
    V = rot[start].T @ meas["vel"][start]
    for k in range(start, stop - 1):
        dt = t[k + 1] - t[k]
        f = _specific_force(model, V, rotor[k], force[k, 2], coef, mass)
        V_new = V + dt * (f + rot[k].T @ GRAVITY)
        if model == "coriolis":
            V_new = rot[k + 1].T @ (rot[k] @ V_new)
        pos[k - start + 1] = pos[k - start] + 0.5 * dt * (rot[k] @ V + rot[k + 1] @ V_new)
        V = V_new
    return pos


def position_rmse(estimate: np.ndarray, truth: np.ndarray) -> list[float]:
    """RMS position error per axis (x, y, z), m."""
    return [float(v) for v in np.sqrt(np.mean((estimate - truth) ** 2, axis=0))]


def compare_models(
    meas: dict, coef: dict, mass: float, start: int = 0, stop: int | None = None
) -> dict:
    """Tracks and per-axis RMSE of the four models over one window."""
    stop = len(meas["t"]) if stop is None else stop
    truth = meas["pos"][start:stop]
    out = {}
    for model in MODELS:
        est = integrate(model, meas, coef, mass, start, stop)
        out[model] = {"rmse": position_rmse(est, truth), "_track": est}
    return out
