"""The 12-state quadrotor model of the ga-gradient paper: symbolic form, loops, simulator.

    x_ddot = a1 x_dot + a2 u2 + b1 u1      phi_ddot   = a6 phi_dot theta_dot + a7 u2
    y_ddot = a3 y_dot + a4 u3 + b2 u1      theta_ddot = a8 phi_dot psi_dot   + a9 u3
    z_ddot = a5 z_dot + b3 u1              psi_ddot   = a10 phi_dot theta_dot + a11 u4

with u1 = sum V_i - 4 V_hover (the model has no gravity term, so u1 is the deviation
from hover), u2 = V4 - V2, u3 = V1 - V3, u4 = V1 - V2 + V3 - V4 (motor voltages V).
Loops follow the rows: roll (a6, a7), pitch (a8, a9), yaw (a10, a11), position
(a1..a5, b1..b3). (The paper's result table groups b1..b3 with the attitude loops,
which its own model contradicts; we follow the model.)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import sympy as sp

from gpquad.baselines.quad12_kernels import replay, simulate_closed_loop
from gpquad.baselines.symbolic import ParametricModel
from gpquad.data.flight import Flight
from gpquad.engine.kernels.quaternion import quat_from_euler

STATES = (
    "x",
    "x_dot",
    "y",
    "y_dot",
    "z",
    "z_dot",
    "phi",
    "phi_dot",
    "theta",
    "theta_dot",
    "psi",
    "psi_dot",
)
INPUTS = ("u_1", "u_2", "u_3", "u_4")
VOLTAGES = ("V_1", "V_2", "V_3", "V_4")
PARAMS = tuple(f"a_{i}" for i in range(1, 12)) + ("b_1", "b_2", "b_3")
LOOPS: dict[str, tuple[str, ...]] = {
    "roll": ("phi_dot",),
    "pitch": ("theta_dot",),
    "yaw": ("psi_dot",),
    "position": ("x_dot", "y_dot", "z_dot"),
}
#: Default truth: the paper's identified attitude values (a6..a11), plausible drag and
#: control effectiveness for the position rows (its table gives b1, b2 and k/m = 0.45).
TRUE_PARAMS = {
    "a_1": -0.25,
    "a_2": 0.35,
    "a_3": -0.25,
    "a_4": 0.35,
    "a_5": -0.4,
    "a_6": 0.012,
    "a_7": 2.34,
    "a_8": 0.011,
    "a_9": 2.31,
    "a_10": 0.005,
    "a_11": 1.89,
    "b_1": 0.56,
    "b_2": 0.55,
    "b_3": -0.45,
}


def f_quad12(X, U, th):
    """The paper's f(X, U; theta) as a function of sequences (works on sympy symbols)."""
    a = {i: th[i - 1] for i in range(1, 12)}
    b1, b2, b3 = th[11], th[12], th[13]
    return [
        X[1],
        a[1] * X[1] + a[2] * U[1] + b1 * U[0],
        X[3],
        a[3] * X[3] + a[4] * U[2] + b2 * U[0],
        X[5],
        a[5] * X[5] + b3 * U[0],
        X[7],
        a[6] * X[7] * X[9] + a[7] * U[1],
        X[9],
        a[8] * X[7] * X[11] + a[9] * U[2],
        X[11],
        a[10] * X[7] * X[9] + a[11] * U[3],
    ]


def loop_model(loop: str) -> tuple[ParametricModel, tuple[str, ...]]:
    """The model restricted to one loop's rows, and that loop's parameter names."""
    full = ParametricModel.from_function(f_quad12, STATES, INPUTS, PARAMS, rows=list(LOOPS[loop]))
    names = tuple(p for p in PARAMS if any(full.jacobian[(r, p)] != 0 for r in full.rows))
    syms = {p: sp.Symbol(p, real=True) for p in PARAMS}
    # the parameters outside the loop do not appear in its rows; keep only the loop's own
    rhs = {r: e for r, e in full.rhs.items()}
    assert all(
        not (e.free_symbols & {syms[p] for p in PARAMS if p not in names}) for e in rhs.values()
    )
    return ParametricModel(STATES, INPUTS, names, rhs), names


def decoupled_inputs(V: np.ndarray, v_hover: float) -> np.ndarray:
    """u (N, 4) from motor voltages V (N, 4)."""
    u = np.empty_like(V)
    u[:, 0] = V.sum(axis=1) - 4.0 * v_hover
    u[:, 1] = V[:, 3] - V[:, 1]
    u[:, 2] = V[:, 0] - V[:, 2]
    u[:, 3] = V[:, 0] - V[:, 1] + V[:, 2] - V[:, 3]
    return u


def motor_voltages(u: np.ndarray, v_hover: float) -> np.ndarray:
    """Inverse of decoupled_inputs: V (N, 4)."""
    s = 0.5 * (u[:, 0] + 4.0 * v_hover + u[:, 3])  # V1 + V3
    t = 0.5 * (u[:, 0] + 4.0 * v_hover - u[:, 3])  # V2 + V4
    return np.column_stack(
        [0.5 * (s + u[:, 2]), 0.5 * (t - u[:, 1]), 0.5 * (s - u[:, 2]), 0.5 * (t + u[:, 1])]
    )


@dataclass
class Quad12Record:
    """A simulated flight of the 12-state model: t (N,) s, X (N, 12), V (N, 4) volts."""

    t: np.ndarray
    X: np.ndarray
    V: np.ndarray
    v_hover: float

    @property
    def dt(self) -> float:
        return float(self.t[1] - self.t[0])

    @property
    def u(self) -> np.ndarray:
        return decoupled_inputs(self.V, self.v_hover)


def ou_signal(
    rng: np.random.Generator, n: int, sd: np.ndarray, dt: float, tau: float
) -> np.ndarray:
    """Ornstein-Uhlenbeck excitation (n, len(sd)) with stationary SD sd and time constant tau s."""
    decay = np.exp(-dt / tau)
    shocks = rng.standard_normal((n, len(sd))) * sd * np.sqrt(1.0 - decay**2)
    out = np.empty((n, len(sd)))
    out[0] = sd * rng.standard_normal(len(sd))
    for k in range(1, n):
        out[k] = decay * out[k - 1] + shocks[k]
    return out


def simulate_quad12(
    theta: np.ndarray,
    *,
    duration_s: float,
    rate_hz: float,
    substeps: int,
    excitation_sd: np.ndarray,
    tau_s: float,
    gains: np.ndarray,
    v_hover: float,
    rng: np.random.Generator,
) -> Quad12Record:
    """Fly the 12-state model (RK4, `substeps` per sample) with a PD pilot plus OU excitation."""
    n = int(round(duration_s * rate_hz))
    dt = 1.0 / rate_hz
    exc = ou_signal(rng, n, np.asarray(excitation_sd, float), dt, tau_s)
    X, u = simulate_closed_loop(
        np.asarray(theta, float), np.zeros(12), exc, np.asarray(gains, float), dt, int(substeps)
    )
    return Quad12Record(np.arange(n) * dt, X, motor_voltages(u, v_hover), v_hover)


def euler_rate_matrix(phi, theta):
    """W (..., 3, 3) with body rates omega = W eta_dot (paper's kinematics)."""
    z, o = np.zeros_like(phi), np.ones_like(phi)
    return np.stack(
        [
            np.stack([o, z, -np.sin(theta)], -1),
            np.stack([z, np.cos(phi), np.sin(phi) * np.cos(theta)], -1),
            np.stack([z, -np.sin(phi), np.cos(phi) * np.cos(theta)], -1),
        ],
        -2,
    )


def rotation(phi, theta, psi):
    """Body-to-world rotation matrices (..., 3, 3), ZYX Euler angles."""
    cf, sf, ct, st, cp, sp_ = (
        np.cos(phi),
        np.sin(phi),
        np.cos(theta),
        np.sin(theta),
        np.cos(psi),
        np.sin(psi),
    )
    return np.stack(
        [
            np.stack([cp * ct, cp * st * sf - sp_ * cf, cp * st * cf + sp_ * sf], -1),
            np.stack([sp_ * ct, sp_ * st * sf + cp * cf, sp_ * st * cf - cp * sf], -1),
            np.stack([-st, ct * sf, ct * cf], -1),
        ],
        -2,
    )


def engine_states(X: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(quat (N, 4), body velocity (N, 3), body rates (N, 3)) of 12-state rows X (N, 12)."""
    phi, theta, psi = X[:, 6], X[:, 8], X[:, 10]
    R = rotation(phi, theta, psi)
    vel = np.einsum("nji,nj->ni", R, X[:, [1, 3, 5]])
    rates = np.einsum("nij,nj->ni", euler_rate_matrix(phi, theta), X[:, [7, 9, 11]])
    quat = np.array([quat_from_euler(a, b, c) for a, b, c in zip(phi, theta, psi, strict=True)])
    return quat, vel, rates


def from_engine_states(states: np.ndarray) -> np.ndarray:
    """12-state rows (N, 12) at position 0 from engine states [phi..r] (N, 9)."""
    phi, theta, psi = states[:, 0], states[:, 1], states[:, 2]
    R = rotation(phi, theta, psi)
    world = np.einsum("nij,nj->ni", R, states[:, 3:6])
    eta_dot = np.linalg.solve(euler_rate_matrix(phi, theta), states[:, 6:9][..., None])[..., 0]
    X = np.zeros((len(states), 12))
    X[:, [1, 3, 5]] = world
    X[:, [6, 8, 10]] = states[:, :3]
    X[:, [7, 9, 11]] = eta_dot
    return X


def to_engine_states(X: np.ndarray) -> np.ndarray:
    """Engine states [phi, theta, psi, u, v, w, p, q, r] (..., 9) of 12-state rows (..., 12)."""
    phi, theta, psi = X[..., 6], X[..., 8], X[..., 10]
    R = rotation(phi, theta, psi)
    vel = np.einsum("...ji,...j->...i", R, X[..., [1, 3, 5]])
    rates = np.einsum("...ij,...j->...i", euler_rate_matrix(phi, theta), X[..., [7, 9, 11]])
    ang = np.stack([phi, theta, np.angle(np.exp(1j * psi))], -1)
    return np.concatenate([ang, vel, rates], -1)


def to_flight(rec: Quad12Record, name: str) -> Flight:
    """The record as an engine Flight (NED/FRD) with the motor voltages V_1..V_4 as inputs."""
    quat, vel, rates = engine_states(rec.X)
    return Flight(
        name=name,
        t=rec.t.copy(),
        quat=quat,
        vel=vel,
        rates=rates,
        inputs=rec.V.copy(),
        input_names=VOLTAGES,
        pos=rec.X[:, [0, 2, 4]].copy(),
        meta={"source": "quad12 simulator", "v_hover": rec.v_hover},
    )


def fly_windows(
    theta: np.ndarray, states0: np.ndarray, V: np.ndarray, v_hover: float, dt: float, substeps: int
) -> np.ndarray:
    """Fly from engine states (W, 9) with voltages V (W, n, 4): engine states (W, n+1, 9)."""
    W, n = V.shape[0], V.shape[1]
    u = decoupled_inputs(V.reshape(W * n, 4), v_hover).reshape(W, n, 4)
    X = replay(
        np.asarray(theta, float),
        from_engine_states(states0),
        np.ascontiguousarray(u),
        dt,
        int(substeps),
    )
    return to_engine_states(X)
