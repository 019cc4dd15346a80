"""The reference simulator's eq. 2 flight as its plain Python loop flew it before the truth
moved into a kernel (gpquad.engine.kernels.truth_flight): TruthModel's sympy functions and
integrate_step, one step per sample. The bit-identity fixtures were recorded on this flight."""

import numpy as np

from gpquad.data.flight import Flight
from gpquad.data.simulator import TruthModel, completed, pilot_sticks
from gpquad.engine.kernels.integrator import integrate_step
from gpquad.engine.kernels.quaternion import euler_from_quat
from gpquad.engine.numba_config import python_callable
from gpquad.engine.variables import terminal_names

integrate_step = python_callable(integrate_step)
euler_from_quat = python_callable(euler_from_quat)


def eq2_flight(cfg, input_names) -> Flight:
    """The noise-free eq. 2 flight of simulator config `cfg`."""
    cfg = completed(cfg)
    model = TruthModel(cfg.equations, input_names)
    dt = 1.0 / cfg.rate_hz
    n = int(round(cfg.duration_s * cfg.rate_hz))
    sticks = pilot_sticks(cfg, input_names, n, dt, np.random.default_rng(cfg.seed))
    names = terminal_names(input_names)
    gain = np.zeros((len(input_names), 9))
    for j, inp in enumerate(input_names):
        for state, g in cfg.pilot_gains.get(inp, {}).items():
            gain[j, names.index(state)] = g
    trim = np.array([cfg.trim.get(name, 0.0) for name in input_names])
    quat, vel, rates, pos = np.array([1.0, 0.0, 0.0, 0.0]), np.zeros(3), np.zeros(3), np.zeros(3)
    mat = np.empty((3, 3))
    out = {k: np.empty((n, 4 if k == "quat" else 3)) for k in ("quat", "vel", "rates", "pos")}
    inputs = np.zeros((n, len(input_names)))
    for t in range(n):
        out["quat"][t], out["vel"][t], out["rates"][t], out["pos"][t] = quat, vel, rates, pos
        state = np.concatenate([euler_from_quat(*quat), vel, rates])
        inputs[t] = np.clip(trim + sticks[t] + gain @ state, -cfg.input_limit, cfg.input_limit)
        if t < n - 1:
            integrate_step(quat, vel, rates, pos, model.accelerations(state, inputs, t), dt, mat)
    return Flight(
        name=f"eq2_seed{cfg.seed}",
        t=np.arange(n) * dt,
        inputs=inputs,
        input_names=tuple(input_names),
        meta={"source": "tests/eq2_flight.py"},
        **out,
    )
