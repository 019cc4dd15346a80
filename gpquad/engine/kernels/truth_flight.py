"""The reference simulator's flight: a known model flown in closed loop with a pilot.

Each sample the pilot sets the inputs from the state (trim + stick + gain @ state, clipped);
the inputs, and each equation's delayed inputs (whole samples), are held over the sample, as
a vehicle's controller holds its outputs. The state is advanced by the scheme of
gpquad.engine.kernels.step: eq. 2 (one explicit step per sample, the paper's discrete model)
or classical RK4 on the continuous-time rigid body with `substeps` steps per sample (the
printed equations as the ODEs they are). Each scheme is a kernel of its own, so that a
process compiles only the scheme it flies.
"""

import numpy as np

from gpquad.engine.kernels.fitness_rk4 import stage_features
from gpquad.engine.kernels.integrator import integrate_step
from gpquad.engine.kernels.quaternion import euler_from_quat
from gpquad.engine.kernels.step import (
    N_STAGES,
    NODES,
    PLANT_ROWS,
    RK4,
    WEIGHTS,
    Q,
    V,
    W,
    X,
    accumulate,
    body_derivative,
    body_stage_state,
    finish_step,
)
from gpquad.engine.kernels.tree_eval import STACK_ROWS, eval_lanes
from gpquad.engine.numba_config import njit

#: A state component beyond this magnitude is a diverged flight.
STATE_LIMIT = 1e4


@njit(inner=True)
def _accelerations(codes, values, sizes, modelled, work):
    """work's a (6,) = each modelled equation at work's features (states filled) with its
    held inputs."""
    held, features, stack, pred, a, _ = work
    n_slots = held.shape[1]
    for t in range(6):
        a[t] = 0.0
        if modelled[t]:
            for j in range(n_slots):
                features[9 + j, 0] = held[t, j]
            eval_lanes(codes[t], values[t], sizes[t], features, stack, pred, 1)
            a[t] = pred[0]


def fly_truth(
    codes, values, sizes, delays, modelled, sticks, gain, trim, limit, dt, scheme, substeps
):
    """Fly the truth trees (one row per target, gpquad.engine.tree.encoding.stack_rows; a
    row with modelled False gives zero) from rest with the pilot's inputs, by `scheme`
    (gpquad.engine.kernels.step: RK4 with `substeps` steps per sample, or eq. 2).

    sticks (n, n_in), gain (n_in, 9) on [phi, theta, psi, u, v, w, p, q, r], trim (n_in,):
    inputs = clip(trim + sticks + gain @ state, -limit, limit) at each sample.
    Returns (quat (n, 4), vel (n, 3), rates (n, 3), pos (n, 3), inputs (n, n_in),
    acc (n, 6) the accelerations at each sample's state, diverged): diverged is the first
    sample whose state or accelerations left the finite range, or -1.
    """
    pilot = (sticks, gain, trim, float(limit))
    if scheme == RK4:
        return _fly_rk4(codes, values, sizes, delays, modelled, pilot, dt, substeps)
    return _fly_euler(codes, values, sizes, delays, modelled, pilot, dt)


@njit(inner=True)
def _flight_buffers(n, n_in, n_slots):
    """The recorded flight (quat, vel, rates, pos, inputs, acc), the state y (at rest) and
    a sample's work arrays (held, features, stack, pred, a, state)."""
    y = np.zeros((PLANT_ROWS, 1))
    y[Q, 0] = 1.0
    work = (
        np.zeros((6, n_slots)),
        np.empty((9 + n_slots, 1)),
        np.empty((STACK_ROWS, 1)),
        np.empty(1),
        np.empty(6),
        np.empty(9),
    )
    record = (
        np.empty((n, 4)),
        np.empty((n, 3)),
        np.empty((n, 3)),
        np.empty((n, 3)),
        np.zeros((n, n_in)),
        np.zeros((n, 6)),
    )
    return record, y, work


@njit(inner=True)
def _sample(k, y, record, codes, values, sizes, delays, modelled, pilot, work):
    """Record sample k's state, set its inputs and held inputs, and its accelerations in
    work's a; returns True where the state or the accelerations left the finite range."""
    quat, vel, rates, pos, inputs, acc = record
    sticks, gain, trim, limit = pilot
    held, features, _, _, a, state = work
    n_in = sticks.shape[1]
    n_slots = delays.shape[1]
    for i in range(4):
        quat[k, i] = y[Q + i, 0]
    for i in range(3):
        vel[k, i] = y[V + i, 0]
        rates[k, i] = y[W + i, 0]
        pos[k, i] = y[X + i, 0]
    state[0], state[1], state[2] = euler_from_quat(y[Q, 0], y[Q + 1, 0], y[Q + 2, 0], y[Q + 3, 0])
    for i in range(3):
        state[3 + i] = y[V + i, 0]
        state[6 + i] = y[W + i, 0]
    for j in range(n_in):
        feedback = 0.0
        for i in range(9):
            feedback += gain[j, i] * state[i]
        u = trim[j] + sticks[k, j] + feedback
        inputs[k, j] = min(max(u, -limit), limit)
    for t in range(6):
        for j in range(n_slots):
            held[t, j] = inputs[max(k - delays[t, j], 0), j % n_in]
    for i in range(9):
        features[i, 0] = state[i]
    _accelerations(codes, values, sizes, modelled, work)
    for t in range(6):
        acc[k, t] = a[t]
    for i in range(9):
        if not (abs(state[i]) <= STATE_LIMIT):
            return True
    for t in range(6):
        if not np.isfinite(a[t]):
            return True
    return False


@njit
def _fly_euler(codes, values, sizes, delays, modelled, pilot, dt):
    """fly_truth by eq. 2: the engine's own step, one per sample."""
    n, n_in = pilot[0].shape
    n_slots = delays.shape[1]
    record, y, work = _flight_buffers(n, n_in, n_slots)
    a = work[4]
    mat = np.empty((3, 3))
    q4, v3, w3, x3 = np.empty(4), np.empty(3), np.empty(3), np.empty(3)
    for k in range(n):
        if _sample(k, y, record, codes, values, sizes, delays, modelled, pilot, work):
            return (*record, k)
        if k == n - 1:
            break
        for i in range(4):
            q4[i] = y[Q + i, 0]
        for i in range(3):
            v3[i], w3[i], x3[i] = y[V + i, 0], y[W + i, 0], y[X + i, 0]
        integrate_step(q4, v3, w3, x3, a, dt, mat)
        for i in range(4):
            y[Q + i, 0] = q4[i]
        for i in range(3):
            y[V + i, 0], y[W + i, 0], y[X + i, 0] = v3[i], w3[i], x3[i]
    return (*record, -1)


@njit
def _fly_rk4(codes, values, sizes, delays, modelled, pilot, dt, substeps):
    """fly_truth by classical RK4, `substeps` steps per sample."""
    n, n_in = pilot[0].shape
    n_slots = delays.shape[1]
    record, y, work = _flight_buffers(n, n_in, n_slots)
    features, a = work[1], work[4]
    ys = np.empty((PLANT_ROWS, 1))
    slope = np.zeros((PLANT_ROWS, 1))
    total = np.empty((PLANT_ROWS, 1))
    every_state = np.ones(9, dtype=np.bool_)
    h = dt / substeps
    for k in range(n):
        if _sample(k, y, record, codes, values, sizes, delays, modelled, pilot, work):
            return (*record, k)
        if k == n - 1:
            break
        for _ in range(substeps):
            for stage in range(N_STAGES):
                body_stage_state(y, slope, NODES[stage], h, ys, 0, PLANT_ROWS)
                stage_features(ys, 0, every_state, features)
                _accelerations(codes, values, sizes, modelled, work)
                body_derivative(ys, 0, a[0], a[1], a[2], a[3], a[4], a[5], True, slope)
                accumulate(total, slope, WEIGHTS[stage], stage, 0, PLANT_ROWS)
            finish_step(y, total, h, 0, PLANT_ROWS)
    return (*record, -1)
