"""The reference simulator's flight: a known model flown in closed loop with a pilot.

Each sample the pilot sets the inputs from the state (trim + stick + gain @ state, clipped);
the inputs, and each equation's delayed inputs (whole samples), are held over the sample, as
a vehicle's controller holds its outputs. The state is advanced by the scheme of
gpquad.engine.kernels.step: eq. 2 (one explicit step per sample, the paper's discrete model)
or classical RK4 on the continuous-time rigid body with `substeps` steps per sample (the
printed equations as the ODEs they are).
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


@njit
def _accelerations(codes, values, sizes, modelled, held, features, stack, pred, a):
    """a (6,) = each modelled equation at `features` (states filled) with its held inputs."""
    n_slots = held.shape[1]
    for t in range(6):
        a[t] = 0.0
        if modelled[t]:
            for j in range(n_slots):
                features[9 + j, 0] = held[t, j]
            eval_lanes(codes[t], values[t], sizes[t], features, stack, pred, 1)
            a[t] = pred[0]


@njit(cache=True)
def fly_truth(
    codes, values, sizes, delays, modelled, sticks, gain, trim, limit, dt, scheme, substeps
):
    """Fly the truth trees (one row per target, gpquad.engine.tree.encoding.stack_rows; a
    row with modelled False gives zero) from rest with the pilot's inputs.

    sticks (n, n_in), gain (n_in, 9) on [phi, theta, psi, u, v, w, p, q, r], trim (n_in,):
    inputs = clip(trim + sticks + gain @ state, -limit, limit) at each sample.
    Returns (quat (n, 4), vel (n, 3), rates (n, 3), pos (n, 3), inputs (n, n_in),
    acc (n, 6) the accelerations at each sample's state, diverged): diverged is the first
    sample whose state or accelerations left the finite range, or -1.
    """
    n, n_in = sticks.shape
    n_slots = delays.shape[1]
    quat = np.empty((n, 4))
    vel = np.empty((n, 3))
    rates = np.empty((n, 3))
    pos = np.empty((n, 3))
    inputs = np.zeros((n, n_in))
    acc = np.zeros((n, 6))
    y = np.zeros((PLANT_ROWS, 1))
    y[Q, 0] = 1.0
    ys = np.empty((PLANT_ROWS, 1))
    slope = np.zeros((PLANT_ROWS, 1))
    total = np.empty((PLANT_ROWS, 1))
    features = np.empty((9 + n_slots, 1))
    held = np.zeros((6, n_slots))
    stack = np.empty((STACK_ROWS, 1))
    pred = np.empty(1)
    a = np.empty(6)
    state = np.empty(9)
    mat = np.empty((3, 3))
    q4, v3, w3, x3 = np.empty(4), np.empty(3), np.empty(3), np.empty(3)
    every_state = np.ones(9, dtype=np.bool_)
    h = dt / substeps
    for k in range(n):
        for i in range(4):
            quat[k, i] = y[Q + i, 0]
        for i in range(3):
            vel[k, i] = y[V + i, 0]
            rates[k, i] = y[W + i, 0]
            pos[k, i] = y[X + i, 0]
        state[0], state[1], state[2] = euler_from_quat(
            y[Q, 0], y[Q + 1, 0], y[Q + 2, 0], y[Q + 3, 0]
        )
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
        _accelerations(codes, values, sizes, modelled, held, features, stack, pred, a)
        for t in range(6):
            acc[k, t] = a[t]
        for i in range(9):
            if not (abs(state[i]) <= STATE_LIMIT):
                return quat, vel, rates, pos, inputs, acc, k
        for t in range(6):
            if not np.isfinite(a[t]):
                return quat, vel, rates, pos, inputs, acc, k
        if k == n - 1:
            break
        if scheme != RK4:  # eq. 2, the engine's own step
            for i in range(4):
                q4[i] = y[Q + i, 0]
            for i in range(3):
                v3[i], w3[i], x3[i] = y[V + i, 0], y[W + i, 0], y[X + i, 0]
            integrate_step(q4, v3, w3, x3, a, dt, mat)
            for i in range(4):
                y[Q + i, 0] = q4[i]
            for i in range(3):
                y[V + i, 0], y[W + i, 0], y[X + i, 0] = v3[i], w3[i], x3[i]
            continue
        for _ in range(substeps):
            for stage in range(N_STAGES):
                body_stage_state(y, slope, NODES[stage], h, ys, 0, PLANT_ROWS)
                stage_features(ys, 0, every_state, features)
                _accelerations(codes, values, sizes, modelled, held, features, stack, pred, a)
                body_derivative(ys, 0, a[0], a[1], a[2], a[3], a[4], a[5], True, slope)
                accumulate(total, slope, WEIGHTS[stage], stage, 0, PLANT_ROWS)
            finish_step(y, total, h, 0, PLANT_ROWS)
    return quat, vel, rates, pos, inputs, acc, -1
