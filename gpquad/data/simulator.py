"""Reference simulator: fly a model with known equations, by RK4 in continuous time.

The pilot is a smooth random stick signal (an Ornstein-Uhlenbeck process per
input) around trim, plus a weak proportional feedback that keeps attitude and
speed bounded, as a human pilot would. Its output is a Flight, the same record
the file readers produce, so the engine cannot tell it from a log.
"""

from __future__ import annotations

import numpy as np
import sympy as sp

from gpquad.data.flight import Flight
from gpquad.engine.kernels.quaternion import quat_mul
from gpquad.engine.kernels.step import SCHEMES
from gpquad.engine.kernels.truth_flight import fly_truth
from gpquad.engine.taps import tap_index, tap_names
from gpquad.engine.tree.encoding import stack_rows
from gpquad.engine.tree.export import from_sympy, parse_equation, symbols_for
from gpquad.engine.variables import STATE_NAMES, TARGET_NAMES, target_index, terminal_names
from gpquad.errors import GpquadError
from gpquad.study.config import SimulatorConfig

#: Longest input delay (samples) of a truth equation.
MAX_TRUTH_DELAY = 10_000


class TruthModel:
    """Known accelerations as sympy equations with per-input delays (samples)."""

    def __init__(self, equations: dict[str, str], input_names):
        self.input_names = tuple(input_names)
        self.exprs: dict[str, sp.Expr] = {}
        self.delays: dict[str, dict[str, int]] = {}
        for target, text in equations.items():
            if target not in TARGET_NAMES:
                raise GpquadError(f"unknown target '{target}'", field="simulator.equations")
            expr, delays = parse_equation(
                text, self.input_names, source=f"simulator.equations.{target}"
            )
            if max(delays.values(), default=0) > MAX_TRUTH_DELAY:
                raise GpquadError(
                    f"a delay of {max(delays.values())} samples; the simulator's "
                    f"delays are at most {MAX_TRUTH_DELAY}",
                    field=f"simulator.equations.{target}",
                )
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
            delayed = [
                inputs[max(t - self.delays[target].get(n, 0), 0), j % n_in]
                for j, n in enumerate(self._leaves)
            ]
            acc[k] = func(*state, *delayed)
        return acc


def pilot_sticks(
    cfg: SimulatorConfig, input_names, n: int, dt: float, rng: np.random.Generator
) -> np.ndarray:
    """Smooth random sticks (n, n_inputs): OU processes with the configured SD and time constant."""
    decay = np.exp(-dt / cfg.stick_time_constant_s)
    scale = np.sqrt(1.0 - decay**2)
    shocks = rng.standard_normal((n, len(input_names)))
    sd = np.array([cfg.stick_sd.get(name, 0.0) for name in input_names])
    sticks = np.zeros((n, len(input_names)))
    sticks[0] = sd * shocks[0]
    for t in range(1, n):
        sticks[t] = decay * sticks[t - 1] + scale * sd * shocks[t]
    return sticks


#: Most samples the simulator flies (its loop is plain Python: about a minute per 10^6).
MAX_SAMPLES = 2_000_000
#: Largest measurement noise SD per signal (rad, m/s, rad/s): above it the "measurement"
#: is not of the flight.
#: Most RK4 steps per sample the simulator takes.
MAX_SUBSTEPS = 64

MAX_NOISE = {"attitude": 0.5, "velocity": 10.0, "rates": 10.0}


def completed(cfg: SimulatorConfig) -> SimulatorConfig:
    """The config with its `equations`, `stick_sd` and `trim` tables merged over the
    defaults (a table that names one target or input changes that one, the others keep
    the reference model's), every number checked (GpquadError naming the field)."""
    import dataclasses
    import math

    base = SimulatorConfig()
    cfg = dataclasses.replace(
        cfg,
        equations={**base.equations, **cfg.equations},
        stick_sd={**base.stick_sd, **cfg.stick_sd},
        trim={**base.trim, **cfg.trim},
    )

    def finite(
        value,
        field: str,
        low: float | None = None,
        high: float | None = None,
        low_open: bool = False,
    ):
        ok = (
            isinstance(value, (int, float))
            and math.isfinite(value)
            and (low is None or (value > low if low_open else value >= low))
            and (high is None or value <= high)
        )
        if not ok:
            bounds = (f" {'>' if low_open else '>='} {low:g}" if low is not None else "") + (
                f" and <= {high:g}" if high is not None else ""
            )
            raise GpquadError(
                f"{value!r} is not a finite number{bounds}", field=f"simulator.{field}"
            )

    finite(cfg.rate_hz, "rate_hz", 0.0, 10_000.0, low_open=True)
    finite(cfg.duration_s, "duration_s", 0.0, None, low_open=True)
    if cfg.duration_s * cfg.rate_hz > MAX_SAMPLES:
        raise GpquadError(
            f"{cfg.duration_s:g} s at {cfg.rate_hz:g} Hz is "
            f"{cfg.duration_s * cfg.rate_hz:.3g} samples, more than the "
            f"{MAX_SAMPLES:,} the simulator flies; shorten duration_s",
            field="simulator.duration_s",
        )
    if cfg.integrator not in SCHEMES:
        raise GpquadError(
            f"{cfg.integrator!r} is not a scheme; use one of {sorted(SCHEMES)}",
            field="simulator.integrator",
        )
    if not isinstance(cfg.substeps, int) or not 1 <= cfg.substeps <= MAX_SUBSTEPS:
        raise GpquadError(
            f"{cfg.substeps!r} substeps: use a whole number from 1 to {MAX_SUBSTEPS}",
            field="simulator.substeps",
        )
    finite(cfg.stick_time_constant_s, "stick_time_constant_s", 0.0, low_open=True)
    finite(cfg.input_limit, "input_limit", 0.0, low_open=True)
    for name, sd in cfg.stick_sd.items():
        finite(sd, f"stick_sd.{name}", 0.0)
    for name, value in cfg.trim.items():
        finite(value, f"trim.{name}")
    for name, sd in cfg.measurement_noise.items():
        if name not in MAX_NOISE:
            raise GpquadError(
                f"unknown signal {name!r}; measurement noise is given for {list(MAX_NOISE)}",
                field=f"simulator.measurement_noise.{name}",
            )
        finite(sd, f"measurement_noise.{name}", 0.0, MAX_NOISE[name])
    return cfg


def check_motion(inputs: np.ndarray, rates: np.ndarray, vel: np.ndarray, input_names) -> None:
    """A simulated flight that does not move, or an input that never changes, is a config
    that identifies nothing: one line naming the settings to change."""
    from gpquad.data.plausibility import MIN_MOTION_SD

    if (
        max(float(np.max(np.std(rates, axis=0))), float(np.max(np.std(vel, axis=0))))
        < MIN_MOTION_SD
    ):
        raise GpquadError(
            "the simulated flight does not move (rates and velocities constant): "
            "raise stick_sd or input_limit",
            field="simulator.stick_sd",
        )
    for j, name in enumerate(input_names):
        if float(np.ptp(inputs[:, j])) == 0.0:
            raise GpquadError(
                f"input {name} never changes in the simulated flight; give it a "
                "stick_sd > 0 (or a pilot gain) and an input_limit above its trim",
                field=f"simulator.stick_sd.{name}",
            )


def simulate(cfg: SimulatorConfig, input_names) -> Flight:
    """Fly the configured truth model; the true accelerations are kept in meta["true_acc"].
    The config's tables are merged over the defaults first (`completed`)."""
    cfg = completed(cfg)
    model = TruthModel(cfg.equations, input_names)
    dt = 1.0 / cfg.rate_hz
    n = int(round(cfg.duration_s * cfg.rate_hz))
    rng = np.random.default_rng(cfg.seed)
    sticks = pilot_sticks(cfg, input_names, n, dt, rng)
    names = terminal_names(input_names)
    for inp, gains in cfg.pilot_gains.items():
        for state in gains:
            if inp not in input_names or state not in STATE_NAMES:
                raise GpquadError(
                    f"pilot gain {inp}.{state}: unknown input or state "
                    f"(inputs {list(input_names)}, states {list(STATE_NAMES)})",
                    field="simulator.pilot_gains",
                )
    gain = np.zeros((len(input_names), len(STATE_NAMES)))
    for j, inp in enumerate(input_names):
        for state, g in cfg.pilot_gains.get(inp, {}).items():
            gain[j, names.index(state)] = g
    trim = np.array([cfg.trim.get(name, 0.0) for name in input_names])

    codes, values, sizes, delays = stack_rows(
        {
            target_index(t): from_sympy(e, model.delays[t], model.input_names)
            for t, e in model.exprs.items()
        },
        6,
    )
    modelled = np.zeros(6, dtype=np.bool_)
    modelled[[target_index(t) for t in model.exprs]] = True
    out_q, out_v, out_w, out_x, inputs, true_acc, diverged = fly_truth(
        codes,
        values,
        sizes,
        delays,
        modelled,
        np.ascontiguousarray(sticks, dtype=float),
        gain,
        trim,
        float(cfg.input_limit),
        dt,
        SCHEMES[cfg.integrator],
        int(cfg.substeps),
    )
    if diverged >= 0:
        raise GpquadError(
            f"the truth model diverged at t = {diverged * dt:.2f} s; lower the stick "
            "SD or change the pilot gains",
            field="simulator.equations",
        )
    check_motion(inputs, out_w, out_v, input_names)
    if any(cfg.measurement_noise.values()):
        out_q, out_v, out_w = add_measurement_noise(
            out_q, out_v, out_w, cfg.measurement_noise, np.random.default_rng([cfg.seed, 1])
        )
    return Flight(
        name=f"simulated_seed{cfg.seed}",
        t=np.arange(n) * dt,
        quat=out_q,
        vel=out_v,
        rates=out_w,
        inputs=inputs,
        input_names=tuple(input_names),
        pos=out_x,
        meta={
            "source": "simulator",
            "true_acc": true_acc,
            "equations": dict(cfg.equations),
            "measurement_noise": dict(cfg.measurement_noise),
        },
    )


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
