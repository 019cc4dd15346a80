"""Numba kernels: the nested PID waypoint controller flying a plant of six prefix trees.

Plant (flat arrays): codes (6, M), values (6, M), sizes (6,), delays (6, n_in) as in
gpquad.engine.kernels.rollout.rollout, plus trim (n_in,), subtracted from the raw input before the
trees read it (a discovered model's inputs are trim-subtracted; a truth model has trim 0).
A tree of size 1 holding the constant 0 gives zero acceleration.

Controller (paper section 3.3), every step, with e the distance to the current waypoint in
the heading frame (world rotated by -psi) and [u, v, w] the body velocity:
  outer PD   a_x* = kp_x e_x - kd_x u,  a_y* = kp_y e_y - kd_y v        (m/s^2)
             theta* = clip(a_x* / g_x, +-max_angle), phi* = clip(a_y* / g_y, +-max_angle)
             (g_x = d a_x / d theta, g_y = d a_y / d phi of the model at hover)
  altitude   a_z* = kp_z e_z + ki_z int(e_z) - kd_z w     (PID; e_z > 0 means go down, NED)
  inner PD   alpha_roll* = kp_roll (phi* - level * phi) - kd_roll p   (and pitch, yaw with
             psi* = 0 and a wrapped yaw error); level = 1 for rate-level inputs, 0 for
             angle-level inputs (the plant closes the angle loop itself).
  waypoints  the next waypoint is flown to once the current one is within waypoint_radius or
             has been passed (the position's projection on the leg is beyond it)
  inputs     u[chan[i]] = hover[chan[i]] + scale[i] * command_i for i = roll, pitch, yaw,
             thrust (scale = 1 / d acc / d input), every input clipped to [lo, hi]; the plant
             receives the clipped input plus the noise row of the step.
             With command_limit > 0, the roll, pitch and yaw inputs stay within +-command_limit
             of hover (for rate-level inputs: a rate limit, as PX4's MC_*RATE_MAX).
ctrl (9,) = [g_x, g_y, max_angle, level, waypoint_radius, integral_limit, command_limit, 0, 0].
alphas (6,): each equation's lag factor (gpquad.engine.lag; 1 = none), from zero acceleration
at the start (the craft at rest).
scheme, substeps: the plant's integrator (gpquad.engine.kernels.step): EULER, one eq. 2 step
per control step, or RK4 with `substeps` steps per control step, the plant's equations at
every stage, the controller's inputs held over the step and the lags as their ODE.
"""

import math

import numpy as np

from gpquad.engine.kernels.fitness import STATE_LIMIT
from gpquad.engine.kernels.integrator import integrate_step
from gpquad.engine.kernels.quaternion import euler_from_quat, quat_from_euler
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
    lag_rate_kernel,
)
from gpquad.engine.kernels.tree_eval import STACK_ROWS, eval_lanes
from gpquad.engine.numba_config import njit

N_GAINS = 13


@njit
def plant_accelerations(
    codes, values, sizes, delays, trim, state, history, row, acc, features, stack, pred
):
    """acc (6,) from state (9,) and history (rows, n_in) of raw applied inputs; row is the
    current step's row (the delayed input of delay d is history[row - d]). delays (6, K n_in)
    may hold K taps per input (gpquad.engine.taps): slot s reads input s % n_in; features
    has 9 + K n_in rows."""
    n_in = trim.shape[0]
    for i in range(9):
        features[i, 0] = state[i]
    for t in range(6):
        for s in range(delays.shape[1]):
            j = s % n_in
            features[9 + s, 0] = history[row - delays[t, s], j] - trim[j]
        eval_lanes(codes[t], values[t], sizes[t], features, stack, pred, 1)
        acc[t] = pred[0]


@njit(inner=True)
def plant_rk4_sample(
    codes,
    values,
    sizes,
    delays,
    trim,
    alphas,
    history,
    row,
    y,
    work,
    dt,
    substeps,
    acc,
    features,
    stack,
    pred,
):
    """Advance the plant over one control step by RK4 with the inputs history[row] held.

    y (PLANT_ROWS + 6, 1): q, V, omega, x (gpquad.engine.kernels.step rows) and the six lag
    states; work (3, PLANT_ROWS + 6, 1) holds the stage state, slope and weighted sum.
    """
    n_rows = PLANT_ROWS + 6
    ys, slope, total = work[0], work[1], work[2]
    state = np.empty(9)
    h = dt / substeps
    for _ in range(substeps):
        for stage in range(N_STAGES):
            body_stage_state(y, slope, NODES[stage], h, ys, 0, n_rows)
            state[0], state[1], state[2] = euler_from_quat(
                ys[Q, 0], ys[Q + 1, 0], ys[Q + 2, 0], ys[Q + 3, 0]
            )
            for i in range(3):
                state[3 + i] = ys[V + i, 0]
                state[6 + i] = ys[W + i, 0]
            plant_accelerations(
                codes, values, sizes, delays, trim, state, history, row, acc, features, stack, pred
            )
            for t in range(6):
                slope[PLANT_ROWS + t, 0] = 0.0
                if alphas[t] < 1.0:
                    lagged = ys[PLANT_ROWS + t, 0]
                    slope[PLANT_ROWS + t, 0] = lag_rate_kernel(alphas[t], dt) * (acc[t] - lagged)
                    acc[t] = lagged
            body_derivative(ys, 0, acc[0], acc[1], acc[2], acc[3], acc[4], acc[5], True, slope)
            accumulate(total, slope, WEIGHTS[stage], stage, 0, n_rows)
        finish_step(y, total, h, 0, n_rows)


@njit
def constant_input_accelerations(codes, values, sizes, delays, trim, state, inputs):
    """acc (6,) of the plant in `state` (9,) with raw `inputs` (n_in,) held for all time."""
    n_in = trim.shape[0]
    hist = np.empty((int(delays.max()) + 1, n_in))
    for r in range(hist.shape[0]):
        hist[r] = inputs
    acc = np.empty(6)
    plant_accelerations(
        codes,
        values,
        sizes,
        delays,
        trim,
        state,
        hist,
        hist.shape[0] - 1,
        acc,
        np.empty((9 + delays.shape[1], 1)),
        np.empty((STACK_ROWS, 1)),
        np.empty(1),
    )
    return acc


@njit
def pid_command(gains, ctrl, err, vel, angles, rates, integral, cmd):
    """The four axis commands cmd (4,) [roll, pitch, yaw (rad/s^2), thrust (m/s^2)].

    err (3,) world NED distance to the waypoint; vel, angles, rates (3,) of the state;
    integral (1,) the altitude-error integral, updated by the caller.
    """
    phi, theta, psi = angles[0], angles[1], angles[2]
    c, s = math.cos(psi), math.sin(psi)
    ex = c * err[0] + s * err[1]
    ey = -s * err[0] + c * err[1]
    lim = ctrl[2]
    theta_sp = min(max((gains[6] * ex - gains[7] * vel[0]) / ctrl[0], -lim), lim)
    phi_sp = min(max((gains[8] * ey - gains[9] * vel[1]) / ctrl[1], -lim), lim)
    level = ctrl[3]
    yaw_err = math.atan2(math.sin(-psi), math.cos(-psi))
    cmd[0] = gains[0] * (phi_sp - level * phi) - gains[1] * rates[0]
    cmd[1] = gains[2] * (theta_sp - level * theta) - gains[3] * rates[1]
    cmd[2] = gains[4] * (level * yaw_err) - gains[5] * rates[2]
    cmd[3] = gains[10] * err[2] + gains[11] * integral[0] - gains[12] * vel[2]


@njit
def fly_course(
    codes,
    values,
    sizes,
    delays,
    alphas,
    trim,
    dt,
    gains,
    ctrl,
    chan,
    scale,
    hover,
    lo,
    hi,
    waypoints,
    noise,
    n_steps,
    scheme,
    substeps,
):
    """Fly the plant through waypoints (n_wp, 3) NED from rest at the origin, level.

    noise (n_steps, n_in) is added to the clipped inputs. Returns pos (n_steps + 1, 3),
    states (n_steps + 1, 9), inputs (n_steps, n_in) (clipped, before noise), target
    (n_steps + 1,) index of the waypoint being flown to (n_wp once the last is reached) and
    the number of steps flown before divergence (n_steps when none).
    """
    n_in = trim.shape[0]
    n_wp = waypoints.shape[0]
    offset = int(delays.max())
    history = np.empty((offset + n_steps, n_in))
    for r in range(offset):
        history[r] = hover  # the craft hovered before the course started
    pos_out = np.full((n_steps + 1, 3), np.nan)
    states = np.full((n_steps + 1, 9), np.nan)
    inputs = np.full((n_steps, n_in), np.nan)
    target = np.full(n_steps + 1, -1, dtype=np.int64)
    quat = np.empty(4)
    quat[0], quat[1], quat[2], quat[3] = quat_from_euler(0.0, 0.0, 0.0)
    vel = np.zeros(3)
    rates = np.zeros(3)
    pos = np.zeros(3)
    mat = np.empty((3, 3))
    acc = np.empty(6)
    applied = np.zeros(6)  # the lagged accelerations
    y = np.zeros((PLANT_ROWS + 6, 1))  # RK4: q, V, omega, x and the lag states
    work = np.zeros((3, PLANT_ROWS + 6, 1))
    err = np.empty(3)
    angles = np.empty(3)
    cmd = np.empty(4)
    integral = np.zeros(1)
    state = np.empty(9)
    features = np.empty((9 + delays.shape[1], 1))
    stack = np.empty((STACK_ROWS, 1))
    pred = np.empty(1)
    wp = 0
    flown = n_steps
    for k in range(n_steps + 1):
        angles[0], angles[1], angles[2] = euler_from_quat(quat[0], quat[1], quat[2], quat[3])
        for i in range(3):
            state[i] = angles[i]
            state[3 + i] = vel[i]
            state[6 + i] = rates[i]
        ok = True
        for i in range(9):
            if not abs(state[i]) < STATE_LIMIT:
                ok = False
        for i in range(3):
            if not abs(pos[i]) < STATE_LIMIT:
                ok = False
        if not ok:
            flown = k - 1 if k > 0 else 0
            break
        while wp < n_wp:  # waypoint switching: within the radius, or past the waypoint
            d2 = 0.0
            along = 0.0
            leg2 = 0.0
            for i in range(3):
                d2 += (waypoints[wp, i] - pos[i]) ** 2
                a = waypoints[wp - 1, i] if wp > 0 else 0.0
                along += (pos[i] - a) * (waypoints[wp, i] - a)
                leg2 += (waypoints[wp, i] - a) ** 2
            if d2 < ctrl[4] ** 2 or along >= leg2:
                wp += 1
            else:
                break
        for i in range(3):
            pos_out[k, i] = pos[i]
        for i in range(9):
            states[k, i] = state[i]
        target[k] = wp
        if k == n_steps:
            break
        goal = waypoints[min(wp, n_wp - 1)]
        for i in range(3):
            err[i] = goal[i] - pos[i]
        pid_command(gains, ctrl, err, vel, angles, rates, integral, cmd)
        integral[0] = min(max(integral[0] + err[2] * dt, -ctrl[5]), ctrl[5])
        row = offset + k
        for j in range(n_in):
            history[row, j] = hover[j]
        for a in range(4):
            dev = scale[a] * cmd[a]
            if a < 3 and ctrl[6] > 0.0:
                dev = min(max(dev, -ctrl[6]), ctrl[6])
            history[row, chan[a]] += dev
        for j in range(n_in):
            u = min(max(history[row, j], lo[j]), hi[j])
            inputs[k, j] = u
            history[row, j] = u + noise[k, j]
        if scheme == RK4:
            for i in range(4):
                y[Q + i, 0] = quat[i]
            for i in range(3):
                y[V + i, 0], y[W + i, 0], y[X + i, 0] = vel[i], rates[i], pos[i]
            plant_rk4_sample(
                codes,
                values,
                sizes,
                delays,
                trim,
                alphas,
                history,
                row,
                y,
                work,
                dt,
                substeps,
                acc,
                features,
                stack,
                pred,
            )
            for i in range(4):
                quat[i] = y[Q + i, 0]
            for i in range(3):
                vel[i], rates[i], pos[i] = y[V + i, 0], y[W + i, 0], y[X + i, 0]
            continue
        plant_accelerations(
            codes, values, sizes, delays, trim, state, history, row, acc, features, stack, pred
        )
        for t in range(6):
            if alphas[t] < 1.0:
                applied[t] += alphas[t] * (acc[t] - applied[t])
                acc[t] = applied[t]
        integrate_step(quat, vel, rates, pos, acc, dt, mat)
    return pos_out, states, inputs, target, flown
