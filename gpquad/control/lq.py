"""LQ acceleration tracker of the body-centric paper (section 6), with python-control.

State x = [phi, theta, psi, p, q, r] (eq. 25), input u = motor speeds [Omega_1..4] as
deviations from hover Omega_h (eqs. 26, 28), output y = [psi, a_x, a_y, a_z] (eq. 27).
Continuous linearisation of eq. (10)/(24) about hover -> zero-order-hold discretisation
(Phi, Gamma, C, D of eq. 29) -> control law u(n) = -K x(n) + F y_r(n+1) (eq. 30) for the
index J = 1/2 sum (y - y_r)' Q_y (y - y_r) + u' R u (eq. 32):
- with y = C x + D u, J is the LQR index with Q = C' Q_y C, cross term N = C' Q_y D and
  R_bar = R + D' Q_y D, so K = (R_bar + Gamma' P Gamma)^-1 (Gamma' P Phi + N') with P the
  discrete Riccati solution (python-control `dlqr`);
- F makes the steady-state output equal a constant reference (x_ss = Pi y_r, eq. 34, and
  y_ss = (C - D K) x_ss + D F y_r = y_r):  F = [(C - D K)(I - Phi + Gamma K)^-1 Gamma + D]^-1.
  The paper cites [32] for F without the formula; this one reproduces Table A1's F from its K
  (tests/test_control_lq.py);
- Pi = (I - Phi + Gamma K)^-1 Gamma F (eq. 35).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gpquad.baselines.body_kernels import model_accelerations
from gpquad.errors import GpquadError

#: Paper Table A1 (Pelican, 1 kHz), as printed (rounded). Gamma's first row prints as
#: "1 -0.0002 0 0.0002" in our copy; its first entry is read as 0 (phi does not respond to
#: Omega_1: motor 1 sits on the pitch axis, as in rows 4 and 5). C prints 5 columns; the
#: sixth (r) is zero in every row.
TABLE_A1 = {
    "Phi": np.block([[np.eye(3), 1e-3 * np.eye(3)], [np.zeros((3, 3)), np.eye(3)]]),
    "Gamma": 1e-3
    * np.array(
        [
            [0.0, -0.0002, 0.0, 0.0002],
            [0.0001, 0.0, -0.0001, 0.0],
            [0.0, 0.0, 0.0, 0.0],
            [0.0, -0.3305, 0.0, 0.3305],
            [0.295, 0.0, -0.295, 0.0],
            [-0.0143, 0.0143, -0.0143, 0.0143],
        ]
    ),
    "C": np.array(
        [
            [0.0, 0.0, 1.0, 0.0, 0.0, 0.0],
            [0.0, -9.805, 0.0, 0.0, 0.0, 0.0],
            [9.805, 0.0, 0.0, 0.0, 0.0, 0.0],
            [0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        ]
    ),
    "D": np.vstack([np.zeros((3, 4)), np.full((1, 4), -0.0116)]),
    "K": np.array(
        [
            [0.0, 530.32, -211.61, 0.0, 42.4, -86.12],
            [-529.93, 0.0, 211.61, -40.04, 0.0, 86.12],
            [0.0, -530.32, -211.61, 0.0, -42.4, -86.12],
            [529.93, 0.0, 211.61, 40.04, 0.0, 86.12],
        ]
    ),
    "F": np.array(
        [
            [-211.61, -54.09, 0.0, -21.52],
            [211.61, 0.0, -54.05, -21.52],
            [-211.61, 54.09, 0.0, -21.52],
            [211.61, 0.0, 54.05, -21.52],
        ]
    ),
    "Q_y": np.diag([180e3, 5e3, 5e3, 5e3]),
    "R": np.eye(4),
}


@dataclass
class Tracker:
    K: np.ndarray  # (4, 6)
    F: np.ndarray  # (4, 4)
    Pi: np.ndarray  # (6, 4)
    P: np.ndarray  # (6, 6) Riccati solution
    closed_loop_poles: np.ndarray

    def to_dict(self) -> dict:
        return {
            "K": self.K.tolist(),
            "F": self.F.tolist(),
            "Pi": self.Pi.tolist(),
            "closed_loop_pole_radius_max": float(np.abs(self.closed_loop_poles).max()),
        }


def lq_tracker(Phi, Gamma, C, D, Q_y, R) -> Tracker:
    """K, F and Pi of the tracker (see the module docstring)."""
    from gpquad.extras import require

    control = require("control", "the LQ controller design")

    Phi, Gamma, C, D = (np.asarray(m, float) for m in (Phi, Gamma, C, D))
    Q_y, R = np.asarray(Q_y, float), np.asarray(R, float)
    Q = C.T @ Q_y @ C
    N = C.T @ Q_y @ D
    R_bar = R + D.T @ Q_y @ D
    try:
        K, P, poles = control.dlqr(Phi, Gamma, Q, R_bar, N)
    except (ValueError, np.linalg.LinAlgError, control.ControlArgument) as exc:
        raise GpquadError(
            f"no stabilising LQ solution ({exc}); check Q_y and R", field="lq.q_y"
        ) from None
    K = np.asarray(K)
    n = Phi.shape[0]
    closed = np.eye(n) - Phi + Gamma @ K
    F = np.linalg.inv((C - D @ K) @ np.linalg.solve(closed, Gamma) + D)
    Pi = np.linalg.solve(closed, Gamma @ F)
    return Tracker(K, F, Pi, np.asarray(P), np.asarray(poles))


def hover_speed(theta, vehicle) -> float:
    """Omega_h with 4 b Omega_h^2 = m g."""
    return float(np.sqrt(vehicle[1] * vehicle[2] / (4.0 * theta[4])))


def _f(theta, vehicle, x, u):
    """(x_dot (6,), y (4,)) of eq. (10)/(24) with Euler kinematics eq. (1)."""
    phi, th, psi, p, q, r = x
    acc = np.empty(6)
    model_accelerations(
        np.asarray(theta, float),
        np.asarray(vehicle, float),
        phi,
        th,
        np.array([p, q, r]),
        np.asarray(u, float),
        acc,
    )
    t, s, c = np.tan(th), np.sin(phi), np.cos(phi)
    xdot = np.array(
        [
            p + q * t * s + r * t * c,
            q * c - r * s,
            (q * s + r * c) / np.cos(th),
            acc[3],
            acc[4],
            acc[5],
        ]
    )
    return xdot, np.array([psi, acc[0], acc[1], acc[2]])


def linearise(theta, vehicle, omega_h: float | None = None, h: float = 1e-6):
    """Continuous (A, B, C, D) about x = 0, u = Omega_h (default: the equilibrium hover
    speed; the paper uses its measured 407 rad/s) by central differences."""
    om = hover_speed(theta, vehicle) if omega_h is None else float(omega_h)
    x0, u0 = np.zeros(6), np.full(4, om)
    A, C = np.empty((6, 6)), np.empty((4, 6))
    B, D = np.empty((6, 4)), np.empty((4, 4))
    for j in range(6):
        dx = np.zeros(6)
        dx[j] = h
        (fa, ya), (fb, yb) = _f(theta, vehicle, x0 + dx, u0), _f(theta, vehicle, x0 - dx, u0)
        A[:, j], C[:, j] = (fa - fb) / (2 * h), (ya - yb) / (2 * h)
    hu = h * om
    for j in range(4):
        du = np.zeros(4)
        du[j] = hu
        (fa, ya), (fb, yb) = _f(theta, vehicle, x0, u0 + du), _f(theta, vehicle, x0, u0 - du)
        B[:, j], D[:, j] = (fa - fb) / (2 * hu), (ya - yb) / (2 * hu)
    return A, B, C, D


def discretise(A, B, C, D, dt: float):
    """Zero-order-hold (Phi, Gamma, C, D) with python-control."""
    from gpquad.extras import require

    control = require("control", "the LQ controller design")

    sysd = control.c2d(control.ss(A, B, C, D), dt, method="zoh")
    return (np.asarray(sysd.A), np.asarray(sysd.B), np.asarray(sysd.C), np.asarray(sysd.D))
