"""Fly "acceleration = f(state, lagged inputs)" models through gpquad's integrator.

gpquad's own trees fly through `gpquad.engine.kernels.rollout.rollout`; peer models (linear,
polynomial, operon expressions) read several lags of one input, which a gpquad tree
cannot express, so they fly here. Every window is advanced one step at a time, all
windows at once: at step k the model sees the integrated state x_k = [phi, theta, psi,
u, v, w, p, q, r] of each window and the recorded inputs at k - 0 .. k - max_lag, returns
the six accelerations, and `gpquad.engine.kernels.integrator.integrate_step` (the same step as
`rollout`) advances every window. A window whose state leaves [-STATE_LIMIT, STATE_LIMIT]
or turns NaN is frozen at NaN (diverged, scored as such), never an error.

With integrator "rk4" the windows are flown by RK4 with `substeps` steps per sample
(gpquad.engine.kernels.step): the model is asked at every stage's state, the lagged inputs
held over the sample.
"""

from __future__ import annotations

import numpy as np

from gpquad.engine.kernels.fitness import STATE_LIMIT
from gpquad.engine.kernels.integrator import integrate_step
from gpquad.engine.kernels.quaternion import euler_from_quat
from gpquad.engine.kernels.step import (
    BODY_ROWS,
    N_STAGES,
    NODES,
    RK4,
    WEIGHTS,
    Q,
    V,
    W,
    accumulate,
    body_derivative,
    body_stage_state,
    finish_step,
    scheme_code,
)
from gpquad.engine.numba_config import njit

#: Input lags every peer sees (samples): 0 .. MAX_LAG.
MAX_LAG = 5


@njit
def lanes_state(quat, vel, rates, out):
    """States (W, 9) of every lane: Euler angles of quat (W, 4), vel and rates (W, 3)."""
    for w in range(quat.shape[0]):
        out[w, 0], out[w, 1], out[w, 2] = euler_from_quat(
            quat[w, 0], quat[w, 1], quat[w, 2], quat[w, 3]
        )
        for i in range(3):
            out[w, 3 + i] = vel[w, i]
            out[w, 6 + i] = rates[w, i]


@njit
def lanes_step(quat, vel, rates, acc, dt, alive):
    """Advance every live lane one step with its accelerations acc (W, 6), in place.

    A lane whose acceleration or new state is non-finite or beyond STATE_LIMIT dies:
    its state becomes NaN and alive[w] False.
    """
    mat = np.empty((3, 3))
    pos = np.zeros(3)
    for w in range(quat.shape[0]):
        if not alive[w]:
            continue
        integrate_step(quat[w], vel[w], rates[w], pos, acc[w], dt, mat)
        ok = True
        for i in range(3):
            if not (abs(vel[w, i]) < STATE_LIMIT and abs(rates[w, i]) < STATE_LIMIT):
                ok = False
        for i in range(4):
            if not abs(quat[w, i]) <= 1.0 + 1e-9:
                ok = False
        if not ok:
            alive[w] = False
            quat[w, :] = np.nan
            vel[w, :] = np.nan
            rates[w, :] = np.nan


@njit
def lanes_stage(y, slope, node, h, ys, alive, out):
    """Stage states ys (BODY_ROWS, W) of the live lanes and their states out (W, 9)."""
    for w in range(y.shape[1]):
        if alive[w]:
            body_stage_state(y, slope, node, h, ys, w, BODY_ROWS)
            out[w, 0], out[w, 1], out[w, 2] = euler_from_quat(
                ys[Q, w], ys[Q + 1, w], ys[Q + 2, w], ys[Q + 3, w]
            )
            for i in range(3):
                out[w, 3 + i] = ys[V + i, w]
                out[w, 6 + i] = ys[W + i, w]


@njit
def lanes_slope(ys, acc, stage, slope, total, alive):
    """The live lanes' stage slopes under accelerations acc (W, 6), accumulated in total."""
    for w in range(ys.shape[1]):
        if alive[w]:
            body_derivative(
                ys,
                w,
                acc[w, 0],
                acc[w, 1],
                acc[w, 2],
                acc[w, 3],
                acc[w, 4],
                acc[w, 5],
                False,
                slope,
            )
            accumulate(total, slope, WEIGHTS[stage], stage, w, BODY_ROWS)


@njit
def lanes_finish(y, total, h, alive):
    """End an RK4 step of the live lanes; a lane beyond STATE_LIMIT or NaN dies (NaN)."""
    for w in range(y.shape[1]):
        if not alive[w]:
            continue
        finish_step(y, total, h, w, BODY_ROWS)
        ok = True
        for i in range(3):
            if not (abs(y[V + i, w]) < STATE_LIMIT and abs(y[W + i, w]) < STATE_LIMIT):
                ok = False
        for i in range(4):
            if not abs(y[Q + i, w]) <= 1.0 + 1e-9:
                ok = False
        if not ok:
            alive[w] = False
            y[:, w] = np.nan


def lagged_inputs(inputs: np.ndarray, idx: np.ndarray, max_lag: int = MAX_LAG) -> np.ndarray:
    """(len(idx), n_inputs * (max_lag + 1)): input j at lag l in column j * (max_lag + 1) + l."""
    cols = [inputs[idx - lag, j] for j in range(inputs.shape[1]) for lag in range(max_lag + 1)]
    return np.column_stack(cols) if cols else np.zeros((len(idx), 0))


def lagged_names(input_names, max_lag: int = MAX_LAG) -> list[str]:
    """Column names of `lagged_inputs`: u_R_l0 .. u_R_l5 for each input."""
    return [f"{n}_l{lag}" for n in input_names for lag in range(max_lag + 1)]


def fly(
    predict,
    arrays,
    starts,
    n_steps: int,
    max_lag: int = MAX_LAG,
    integrator: str = "euler",
    substeps: int = 1,
) -> np.ndarray:
    """Fly a model over windows of a dataset's arrays: states (W, n_steps + 1, 9).

    predict(features (W, 9 + n_inputs * (max_lag + 1)), idx (W,)) -> accelerations (W, 6);
    features are the integrated states followed by `lagged_inputs` at the data index idx.
    Each window starts from the recorded state at starts[w] (needs starts >= max_lag).
    Diverged windows are NaN from the step they diverged on. integrator, substeps: the
    scheme (module notes).
    """
    starts = np.ascontiguousarray(starts, dtype=np.int64)
    n = len(starts)
    if scheme_code(integrator) == RK4:
        return _fly_rk4(predict, arrays, starts, n_steps, max_lag, int(substeps))
    quat = np.ascontiguousarray(arrays.quat[starts], dtype=float)
    vel = np.ascontiguousarray(arrays.states[starts, 3:6], dtype=float)
    rates = np.ascontiguousarray(arrays.states[starts, 6:9], dtype=float)
    alive = np.ones(n, dtype=np.bool_)
    out = np.empty((n, n_steps + 1, 9))
    state = np.empty((n, 9))
    for k in range(n_steps + 1):
        lanes_state(quat, vel, rates, state)
        out[:, k] = state
        if k == n_steps:
            break
        idx = starts + k
        acc = np.zeros((n, 6))
        if alive.any():  # dead lanes are NaN; only live ones are asked (sklearn refuses NaN)
            live = idx[alive]
            features = np.hstack([state[alive], lagged_inputs(arrays.inputs, live, max_lag)])
            with np.errstate(all="ignore"):
                acc[alive] = predict(features, live)
        lanes_step(quat, vel, rates, acc, float(arrays.dt), alive)
    return out


def _fly_rk4(predict, arrays, starts, n_steps: int, max_lag: int, substeps: int) -> np.ndarray:
    """fly by RK4: the model asked at every stage's state, the lagged inputs held."""
    n = len(starts)
    y = np.empty((BODY_ROWS, n))
    y[Q : Q + 4] = arrays.quat[starts].T
    y[V : V + 3] = arrays.states[starts, 3:6].T
    y[W : W + 3] = arrays.states[starts, 6:9].T
    ys, slope, total = np.empty_like(y), np.zeros_like(y), np.empty_like(y)
    alive = np.ones(n, dtype=np.bool_)
    out = np.empty((n, n_steps + 1, 9))
    state = np.full((n, 9), np.nan)
    h = float(arrays.dt) / substeps
    for k in range(n_steps + 1):
        lanes_stage(y, slope, 0.0, h, ys, np.ones(n, dtype=np.bool_), state)
        out[:, k] = state
        if k == n_steps:
            break
        idx = starts + k
        for _ in range(substeps):
            for stage in range(N_STAGES):
                lanes_stage(y, slope, NODES[stage], h, ys, alive, state)
                acc = np.zeros((n, 6))
                if alive.any():
                    live = idx[alive]
                    features = np.hstack(
                        [state[alive], lagged_inputs(arrays.inputs, live, max_lag)]
                    )
                    with np.errstate(all="ignore"):
                        acc[alive] = predict(features, live)
                lanes_slope(ys, acc, stage, slope, total, alive)
            lanes_finish(y, total, h, alive)
    return out
