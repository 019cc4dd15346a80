"""Reference simulator: fly a model with known equations through the engine's integrator.

The pilot is a smooth random stick signal (an Ornstein-Uhlenbeck process per
input) around trim, plus a weak proportional feedback that keeps attitude and
speed bounded, as a human pilot would. Its output is a Flight, the same record
the file readers produce, so the engine cannot tell it from a log.
"""

from __future__ import annotations

import numpy as np
import sympy as sp

from gpquad.data.flight import Flight
from gpquad.engine.kernels.integrator import integrate_step
from gpquad.engine.kernels.quaternion import euler_from_quat, quat_mul
from gpquad.engine.taps import tap_index, tap_names
from gpquad.engine.tree.export import parse_equation, symbols_for
from gpquad.engine.variables import STATE_NAMES, TARGET_NAMES, terminal_names
from gpquad.errors import GpquadError
from gpquad.study.config import SimulatorConfig


class TruthModel:
    """Known accelerations as sympy equations with per-input delays (samples)."""

    def __init__(self, equations: dict[str, str], input_names):
        self.input_names = tuple(input_names)
        self.exprs: dict[str, sp.Expr] = {}
        self.delays: dict[str, dict[str, int]] = {}
        for target, text in equations.items():
            if target not in TARGET_NAMES:
                raise GpquadError(f"unknown target '{target}'", field="simulator.equations")
            expr, delays = parse_equation(text, self.input_names,
                                          source=f"simulator.equations.{target}")
            self.exprs[target] = expr
            self.delays[target] = delays
        # an input written at several delays is one leaf per delay (gpquad.engine.taps)
        taps = 1 + max((tap_index(n) for d in self.delays.values() for n in d), default=0)
        self._leaves = tap_names(self.input_names, taps)
        syms = list(symbols_for(self._leaves).values())
        self._funcs = {t: sp.lambdify(syms, e, "math") for t, e in self.exprs.items()}
        self.max_delay = max([d for ds in self.delays.values() for d in ds.values()] + [0])

    def accelerations(self, state: np.ndarray, inputs: np.ndarray, t: int) -> np.ndarray:
        """The six accelerations at step t; state (9,), inputs (N, n_inputs) whole record."""
        acc = np.zeros(6)
        n_in = len(self.input_names)
        for k, target in enumerate(TARGET_NAMES):
            func = self._funcs.get(target)
            if func is None:
                continue
            delayed = [inputs[max(t - self.delays[target].get(n, 0), 0), j % n_in]
                       for j, n in enumerate(self._leaves)]
            acc[k] = func(*state, *delayed)
        return acc


def pilot_sticks(cfg: SimulatorConfig, input_names, n: int, dt: float,
                 rng: np.random.Generator) -> np.ndarray:
    """Smooth random sticks (n, n_inputs): OU processes with the configured SD and time constant."""
    decay = np.exp(-dt / cfg.stick_time_constant_s)
    scale = np.sqrt(1.0 - decay ** 2)
    shocks = rng.standard_normal((n, len(input_names)))
    sd = np.array([cfg.stick_sd.get(name, 0.0) for name in input_names])
    sticks = np.zeros((n, len(input_names)))
    sticks[0] = sd * shocks[0]
    for t in range(1, n):
        sticks[t] = decay * sticks[t - 1] + scale * sd * shocks[t]
    return sticks


def simulate(cfg: SimulatorConfig, input_names) -> Flight:
    """Fly the configured truth model; the true accelerations are kept in meta["true_acc"]."""
    model = TruthModel(cfg.equations, input_names)
    dt = 1.0 / cfg.rate_hz
    n = int(round(cfg.duration_s * cfg.rate_hz))
    rng = np.random.default_rng(cfg.seed)
    sticks = pilot_sticks(cfg, input_names, n, dt, rng)
    names = terminal_names(input_names)
    for inp, gains in cfg.pilot_gains.items():
        for state in gains:
            if inp not in input_names or state not in STATE_NAMES:
                raise GpquadError(f"pilot gain {inp}.{state}: unknown input or state "
                                  f"(inputs {list(input_names)}, states {list(STATE_NAMES)})",
                                  field="simulator.pilot_gains")
    gain = np.zeros((len(input_names), len(STATE_NAMES)))
    for j, inp in enumerate(input_names):
        for state, g in cfg.pilot_gains.get(inp, {}).items():
            gain[j, names.index(state)] = g
    trim = np.array([cfg.trim.get(name, 0.0) for name in input_names])

    quat = np.array([1.0, 0.0, 0.0, 0.0])
    vel = np.zeros(3)
    rates = np.zeros(3)
    pos = np.zeros(3)
    mat = np.empty((3, 3))
    out_q = np.empty((n, 4))
    out_v = np.empty((n, 3))
    out_w = np.empty((n, 3))
    out_x = np.empty((n, 3))
    inputs = np.zeros((n, len(input_names)))
    true_acc = np.zeros((n, 6))
    for t in range(n):
        out_q[t], out_v[t], out_w[t], out_x[t] = quat, vel, rates, pos
        state = np.concatenate([euler_from_quat(*quat), vel, rates])
        inputs[t] = np.clip(trim + sticks[t] + gain @ state, -cfg.input_limit, cfg.input_limit)
        acc = model.accelerations(state, inputs, t)
        if not np.all(np.isfinite(acc)) or np.abs(state).max() > 1e4:
            raise GpquadError(f"the truth model diverged at t = {t * dt:.2f} s; lower the stick "
                              "SD or change the pilot gains", field="simulator.equations")
        true_acc[t] = acc
        if t < n - 1:
            integrate_step(quat, vel, rates, pos, acc, dt, mat)
    if any(cfg.measurement_noise.values()):
        out_q, out_v, out_w = add_measurement_noise(out_q, out_v, out_w, cfg.measurement_noise,
                                                    np.random.default_rng([cfg.seed, 1]))
    return Flight(name=f"simulated_seed{cfg.seed}", t=np.arange(n) * dt, quat=out_q, vel=out_v,
                  rates=out_w, inputs=inputs, input_names=tuple(input_names), pos=out_x,
                  meta={"source": "simulator", "true_acc": true_acc,
                        "equations": dict(cfg.equations),
                        "measurement_noise": dict(cfg.measurement_noise)})


def add_measurement_noise(quat, vel, rates, sd: dict, rng: np.random.Generator):
    """Noisy copies of recorded attitude (N, 4), velocity and rates (N, 3).

    Attitude noise is a random rotation by N(0, sd^2) about each body axis; the noise
    generator is separate from the flight's, so adding noise leaves the flight unchanged.
    """
    n = len(quat)
    noisy_q = quat.copy()
    if sd.get("attitude", 0.0):
        half = 0.5 * rng.normal(0.0, sd["attitude"], size=(n, 3))
        for i in range(n):
            dq = np.array([1.0, *half[i]]) / np.sqrt(1.0 + half[i] @ half[i])
            noisy_q[i] = quat_mul(*quat[i], *dq)
    noisy_v = vel + rng.normal(0.0, sd.get("velocity", 0.0), size=vel.shape)
    noisy_w = rates + rng.normal(0.0, sd.get("rates", 0.0), size=rates.shape)
    return noisy_q, noisy_v, noisy_w
