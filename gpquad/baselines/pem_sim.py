"""Closed-loop truth simulator of the body-centric model: the data for the PEM baseline."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gpquad.baselines.body_kernels import fly
from gpquad.baselines.pem_config import PARAMS, PemConfig
from gpquad.baselines.quad12 import ou_signal
from gpquad.data.flight import Flight
from gpquad.engine.kernels.quaternion import quat_from_euler

REF_NAMES = ("phi_r", "theta_r", "psi_r", "Omega_T")
OUTPUT_NAMES = ("phi", "theta", "psi", "p", "q", "r", "a_x", "a_y", "a_z")


@dataclass
class PemRecord:
    """t (N,) s; states (N, 9) engine order; acc (N, 3); speeds (N, 4) rad/s; refs (N, 4)."""

    t: np.ndarray
    states: np.ndarray
    acc: np.ndarray
    speeds: np.ndarray
    refs: np.ndarray

    @property
    def dt(self) -> float:
        return float(self.t[1] - self.t[0])

    def outputs(self) -> np.ndarray:
        """y (N, 9) = [phi, theta, psi, p, q, r, a_x, a_y, a_z], eq. (22)."""
        return np.hstack([self.states[:, :3], self.states[:, 6:9], self.acc])

    def head(self, n: int) -> PemRecord:
        return PemRecord(self.t[:n], self.states[:n], self.acc[:n], self.speeds[:n], self.refs[:n])


def vehicle_array(cfg: PemConfig) -> np.ndarray:
    v = cfg.vehicle
    return np.array([v.arm_length, v.mass, v.gravity, v.omega_min, v.omega_max])


def hover_speed(theta: np.ndarray, cfg: PemConfig) -> float:
    return float(np.sqrt(cfg.vehicle.mass * cfg.vehicle.gravity / (4.0 * theta[4])))


def theta_array(params: dict) -> np.ndarray:
    return np.array([params[p] for p in PARAMS], dtype=float)


def quat_of(angles: np.ndarray) -> np.ndarray:
    return np.array(quat_from_euler(float(angles[0]), float(angles[1]), float(angles[2])))


def predict(theta, cfg: PemConfig, drive, closed: bool, angles0, rates0, dt: float):
    """Fly the model from initial angles/rates (zero velocity): (states, acc, speeds)."""
    return fly(
        np.asarray(theta, float),
        vehicle_array(cfg),
        np.array(cfg.controller.gain),
        np.ascontiguousarray(drive, dtype=float),
        closed,
        quat_of(angles0),
        np.zeros(3),
        np.asarray(rates0, float),
        dt,
        cfg.simulator.substeps,
    )


def simulate(cfg: PemConfig, duration_s: float, flight_index: int) -> PemRecord:
    """Fly the truth in closed loop with OU references; flight_index picks the random stream."""
    s = cfg.simulator
    rng = np.random.default_rng(np.random.SeedSequence([s.seed, flight_index]))
    theta = theta_array(s.true_params)
    dt = 1.0 / s.rate_hz
    n = int(round(duration_s * s.rate_hz))
    refs = np.empty((n, 4))
    for i in range(4):
        refs[:, i] = ou_signal(rng, n, np.array([s.ref_sd[i]]), dt, s.ref_tau_s[i])[:, 0]
    refs[:, 3] += hover_speed(theta, cfg)
    states, acc, speeds = predict(theta, cfg, refs, True, np.zeros(3), np.zeros(3), dt)
    return PemRecord(np.arange(n) * dt, states, acc, speeds, refs)


def add_noise(y: np.ndarray, sd, rng: np.random.Generator) -> np.ndarray:
    if len(sd) == 0 or not np.any(sd):
        return y.copy()
    return y + rng.standard_normal(y.shape) * np.asarray(sd)


def to_flight(rec: PemRecord, name: str) -> Flight:
    """The truth record as an engine Flight with the references as inputs."""
    quat = np.array([quat_of(a) for a in rec.states[:, :3]])
    return Flight(
        name=name,
        t=rec.t.copy(),
        quat=quat,
        vel=rec.states[:, 3:6].copy(),
        rates=rec.states[:, 6:9].copy(),
        inputs=rec.refs.copy(),
        input_names=REF_NAMES,
        meta={"source": "body-centric closed-loop simulator"},
    )
