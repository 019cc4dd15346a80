"""Regressors of the thrust and drag models (thesis eqs. 5, 18, 19).

Frames: body z along the thrust, so the accelerometer's f_z is thrust / mass; V = (u, v, w) is
the body velocity; omega_i the rotor speeds (rad/s), omega_s their mean.

- standard thrust (eq. 5):  m f_z = k_t sum(w_i^2)
- refined thrust (eq. 19):  m f_z = k_t sum(w_i^2) - k_z w sum(w_i) + k_h (u^2 + v^2)
- drag (eq. 18):            f_x = k_dx u w_s,  f_y = k_dy v w_s
  optionally with a parasitic term c |V| u (rotorpy's frame drag, the thesis neglects it).
"""

from __future__ import annotations

import numpy as np

THRUST_MODELS = {"standard": ["k_t"], "refined": ["k_t", "k_z", "k_h"]}


def thrust_regressors(model: str, rotor: np.ndarray, vel_body: np.ndarray) -> np.ndarray:
    """Columns of X for m f_z = X theta, theta named by THRUST_MODELS[model]."""
    sq = np.sum(rotor**2, axis=1)
    if model == "standard":
        return sq[:, None]
    if model == "refined":
        return np.column_stack(
            [sq, -vel_body[:, 2] * np.sum(rotor, axis=1), vel_body[:, 0] ** 2 + vel_body[:, 1] ** 2]
        )
    raise ValueError(f"unknown thrust model {model!r}")


def drag_regressors(
    axis: int, rotor: np.ndarray, vel_body: np.ndarray, parasitic: bool
) -> tuple[np.ndarray, list[str]]:
    """Columns of X for f_axis = X theta (axis 0: x, 1: y) and the coefficient names."""
    name = "xy"[axis]
    cols = [vel_body[:, axis] * np.mean(rotor, axis=1)]
    names = [f"k_d{name}"]
    if parasitic:
        cols.append(np.linalg.norm(vel_body, axis=1) * vel_body[:, axis])
        names.append(f"c_d{name}")
    return np.column_stack(cols), names


def thrust_specific_force(
    coef: dict, model: str, rotor: np.ndarray, vel_body: np.ndarray, mass: float
) -> np.ndarray:
    """f_z predicted by a thrust model with named coefficients."""
    X = thrust_regressors(model, rotor, vel_body)
    theta = np.array([coef[n] for n in THRUST_MODELS[model]])
    return X @ theta / mass


def drag_specific_force(coef: dict, rotor: np.ndarray, vel_body: np.ndarray) -> np.ndarray:
    """(f_x, f_y) predicted by the drag model; a missing parasitic coefficient is zero."""
    w_s = np.mean(rotor, axis=-1)
    speed = np.linalg.norm(vel_body, axis=-1)
    fx = coef["k_dx"] * vel_body[..., 0] * w_s + coef.get("c_dx", 0.0) * speed * vel_body[..., 0]
    fy = coef["k_dy"] * vel_body[..., 1] * w_s + coef.get("c_dy", 0.0) * speed * vel_body[..., 1]
    return np.stack([fx, fy], axis=-1)
