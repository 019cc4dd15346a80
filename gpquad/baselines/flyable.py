"""Fitted baseline models that fly over dataset windows like DiscoveredModel.simulate.

Both read the dataset's raw (not trim-subtracted) inputs and return engine states
(n_windows, n_steps + 1, 9) = [phi, theta, psi, u, v, w, p, q, r].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import sympy as sp

from gpquad.baselines import quad12
from gpquad.baselines.body_kernels import fly
from gpquad.baselines.pem_config import PARAMS as BODY_PARAMS
from gpquad.baselines.pem_sim import REF_NAMES


@dataclass
class Quad12Model:
    """The 12-state model with fitted theta (14,), flown with the recorded voltages V_1..V_4."""

    theta: np.ndarray
    v_hover: float
    substeps: int
    input_names: tuple[str, ...] = quad12.VOLTAGES
    max_delay: int = 0

    @property
    def n_parameters(self) -> int:
        return len(self.theta)

    def simulate(self, dataset, starts, n_steps: int) -> np.ndarray:
        idx = np.asarray(starts)[:, None] + np.arange(n_steps)[None, :]
        V = dataset.arrays.inputs[idx]
        return quad12.fly_windows(
            self.theta,
            dataset.arrays.states[np.asarray(starts)],
            V,
            self.v_hover,
            dataset.dt,
            self.substeps,
        )

    def equations(self) -> dict[str, str]:
        f = quad12.f_quad12(
            [sp.Symbol(n, real=True) for n in quad12.STATES],
            [sp.Symbol(n, real=True) for n in quad12.INPUTS],
            list(self.theta),
        )
        pairs = zip(quad12.STATES, f, strict=True)
        return {f"d({n})/dt": sp.sstr(e, full_prec=True) for n, e in pairs}


@dataclass
class BodyModel:
    """Eq. (10) with fitted Theta (6,), flown in closed loop from the recorded references."""

    theta: np.ndarray
    vehicle: np.ndarray  # [l, m, g, omega_min, omega_max]
    gain: np.ndarray  # (4, 6)
    substeps: int
    input_names: tuple[str, ...] = REF_NAMES
    max_delay: int = 0

    @property
    def n_parameters(self) -> int:
        return len(self.theta)

    def simulate(self, dataset, starts, n_steps: int) -> np.ndarray:
        arr = dataset.arrays
        out = np.empty((len(starts), n_steps + 1, 9))
        for i, s in enumerate(np.asarray(starts)):
            states, _, _ = fly(
                self.theta,
                self.vehicle,
                self.gain,
                np.ascontiguousarray(arr.inputs[s : s + n_steps + 1]),
                True,
                arr.quat[s].copy(),
                arr.states[s, 3:6].copy(),
                arr.states[s, 6:9].copy(),
                dataset.dt,
                self.substeps,
            )
            out[i] = states
        return out

    def equations(self) -> dict[str, str]:
        """Eq. (10) accelerations in motor speeds Omega_1..4 (the controller is in model.json)."""
        s = {
            n: sp.Symbol(n, real=True)
            for n in ("phi", "theta", "p", "q", "r", "Omega_1", "Omega_2", "Omega_3", "Omega_4")
        }
        ixx, iyy, izz, jr, b, d = (sp.Float(float(v)) for v in self.theta)
        ell, m, g = (sp.Float(float(v)) for v in self.vehicle[:3])
        w = [s[f"Omega_{i}"] for i in range(1, 5)]
        u1 = sum(x**2 for x in w)
        u2, u3 = w[3] ** 2 - w[1] ** 2, w[0] ** 2 - w[2] ** 2
        u4 = w[1] ** 2 + w[3] ** 2 - w[0] ** 2 - w[2] ** 2
        om = w[1] + w[3] - w[0] - w[2]
        p, q, r, phi, th = s["p"], s["q"], s["r"], s["phi"], s["theta"]
        eqs = {
            "a_x": -g * sp.sin(th),
            "a_y": g * sp.cos(th) * sp.sin(phi),
            "a_z": g * sp.cos(th) * sp.cos(phi) - b * u1 / m,
            "p_dot": (q * r * (iyy - izz) + jr * q * om + ell * b * u2) / ixx,
            "q_dot": (p * r * (izz - ixx) - jr * p * om + ell * b * u3) / iyy,
            "r_dot": (p * q * (ixx - iyy) + d * u4) / izz,
        }
        return {k: sp.sstr(e, full_prec=True) for k, e in eqs.items()}


def from_model_dict(d: dict):
    """The flyable model of a baseline model.json."""
    params = d["parameters"]
    if d["model"] == "quad12":
        return Quad12Model(
            np.array([params[p] for p in quad12.PARAMS]), float(d["v_hover"]), int(d["substeps"])
        )
    return BodyModel(
        np.array([params[p] for p in BODY_PARAMS]),
        np.array(d["vehicle"], float),
        np.array(d["controller_gain"], float),
        int(d["substeps"]),
    )
