"""The integrator schemes: the one place where a step of the body's state is coded.

Every kernel that flies a state (fitness, sensitivity, rollout, the PID plant, the peers'
rollout, gpquad.engine.kernels.integrator) advances it with the functions here, so that a
change of scheme is a change of this module.

The state is the body-frame rigid body of paper section 3.2: attitude q (body -> world unit
quaternion), body velocity V (m/s), body rates omega (rad/s), and for the plants the world
position x (m), driven by body accelerations a (m/s^2) and angular accelerations alpha
(rad/s^2) that the equations (or the data) give.

"euler" (EULER, paper eq. 2): one step per sample of dt seconds, accelerations evaluated once
at the sample's state,

    dq = exp(omega dt / 2),  q' = q * dq,  V' = D^T (V + a dt),  omega' = omega + alpha dt,
    x' = x + R(q) V dt.

"rk4" (RK4): classical Runge-Kutta on the continuous-time ODE

    q_dot = q * (0, omega) / 2,  V_dot = a - omega x V,  omega_dot = alpha,  x_dot = R(q) V,

with `substeps` steps of h = dt / substeps per sample. The equations are evaluated at every
stage's state; inputs (and input delays, whole samples) are held over the sample, and so are
the data's accelerations where a kernel takes some from the data. An equation's first-order
lag (gpquad.engine.lag) becomes one more state, tau a_dot = f - a, integrated with the rest
(f the tree's value at the stage, a the applied acceleration); explicit RK4 holds it stable
for h < 2.78 tau only, so a lag much faster than the substep diverges and scores as such.
The quaternion is renormalised (first order) after each step.

The stage layout: y (n_rows, n_lanes) holds each lane's state in rows Q (4), V (3), W (3),
then X (3) where a kernel flies the position and lag rows after that. Stage s of a step is
y + NODES[s] h k_{s-1} with its quaternion normalised (body_stage_state; tangent rows use
stage_state), its derivative k_s is accumulated with WEIGHTS[s] (accumulate) and the step
ends with y + h sum (finish_step). A kernel loops `for s in range(N_STAGES)`, evaluating its
equations at the stage state between body_stage_state and accumulate. `first` (default Q):
rows before it are neither stepped nor read (a kernel whose equations never read the attitude,
or the velocity either, starts at V or W and saves their cost). The same three functions over
many lanes at once are in gpquad.engine.kernels.step_lanes.
"""

import math

import numpy as np

from gpquad.engine.kernels.quaternion import (
    SERIES_LIMIT,
    increment_series,
    quat_mul,
    rate_increment,
    renormalize,
    rotate_back,
    rotation_matrix,
)
from gpquad.engine.numba_config import njit

EULER = 0
RK4 = 1
#: Scheme names (config, model.json, CLI) and the kernels' codes.
SCHEMES = {"euler": EULER, "rk4": RK4}

#: Classical RK4 as stages y_s = y + NODES[s] h k_{s-1}, y' = y + h sum WEIGHTS[s] k_s.
N_STAGES = 4
NODES = np.array([0.0, 0.5, 0.5, 1.0])
WEIGHTS = np.array([1.0 / 6.0, 1.0 / 3.0, 1.0 / 3.0, 1.0 / 6.0])

#: Rows of the stage arrays: attitude, body velocity, body rates, world position.
#: The step functions are inline="always": a call per lane and stage costs more than its work.
Q, V, W, X = 0, 4, 7, 10
BODY_ROWS = 10  # q, V, omega
PLANT_ROWS = 13  # q, V, omega, x


def scheme_code(name: str) -> int:
    """The kernels' code of a scheme name; ValueError for an unknown one."""
    if name not in SCHEMES:
        raise ValueError(f"unknown integrator {name!r}; choose one of {sorted(SCHEMES)}")
    return SCHEMES[name]


def lag_rate(alpha: float, dt: float) -> float:
    """1 / tau (1/s) of the lag whose one-sample factor is alpha (gpquad.engine.lag); 0 for
    alpha = 1 (no lag)."""
    return 0.0 if alpha >= 1.0 else float(-math.log1p(-alpha) / dt)


@njit(inner=True)
def lag_rate_kernel(alpha, dt):
    """lag_rate inside a kernel."""
    if alpha >= 1.0:
        return 0.0
    return -math.log1p(-alpha) / dt


# ---------------------------------------------------------------------------------------------
# euler: paper eq. 2


@njit(inline="always")  # a call per step costs more than the step
def euler_step(q0, q1, q2, q3, v0, v1, v2, p, q, r, a0, a1, a2, a3, a4, a5, dt, move_vel, move_att):
    """One eq. 2 step of the attitude (4), body velocity (3) and rates (3); returns the ten.

    move_vel / move_att False: the velocity / attitude are returned unchanged (a kernel that
    never reads them skips their cost).
    """
    if move_vel or move_att:
        d0, d1, d2, d3 = rate_increment(p, q, r, dt)
        if move_vel:
            v0, v1, v2 = rotate_back(d0, d1, d2, d3, v0 + a0 * dt, v1 + a1 * dt, v2 + a2 * dt)
        if move_att:
            n0, n1, n2, n3 = quat_mul(q0, q1, q2, q3, d0, d1, d2, d3)
            q0, q1, q2, q3 = renormalize(n0, n1, n2, n3)
    return (
        q0,
        q1,
        q2,
        q3,
        v0,
        v1,
        v2,
        euler_rate_step(p, a3, dt),
        euler_rate_step(q, a4, dt),
        euler_rate_step(r, a5, dt),
    )


@njit(inner=True)
def euler_lanes_step(
    quat, vel, rates, acc, starts, k, axis, pred, alive, dt, move_vel, move_att, inc
):
    """euler_step of every alive lane at step k of windows `starts` for an angular target,
    in place on quat (4, n), vel (3, n), rates (3, n): the velocity when move_vel, the
    attitude when move_att; rate `axis` driven by pred (n,), the others by the data's acc.
    inc (5, n) is a work buffer.

    The same bits as euler_step lane by lane, in loops over lanes without branches (which
    vectorise): the rate increments by their series (the rare lane beyond SERIES_LIMIT is
    redone by rate_increment), then the velocity, attitude and rates. A dead lane's state is
    stepped too, to no purpose: nothing reads it again.
    """
    n = starts.shape[0]
    big = 0
    for lane in range(n):
        d0, d1, d2, d3, h2 = increment_series(rates[0, lane], rates[1, lane], rates[2, lane], dt)
        inc[0, lane], inc[1, lane], inc[2, lane], inc[3, lane] = d0, d1, d2, d3
        inc[4, lane] = h2
        big += not (h2 < SERIES_LIMIT * SERIES_LIMIT)
    if big > 0:
        for lane in range(n):
            if alive[lane] and not (inc[4, lane] < SERIES_LIMIT * SERIES_LIMIT):
                inc[0, lane], inc[1, lane], inc[2, lane], inc[3, lane] = rate_increment(
                    rates[0, lane], rates[1, lane], rates[2, lane], dt
                )
    if move_vel:
        for lane in range(n):
            idx = starts[lane] + k
            vel[0, lane], vel[1, lane], vel[2, lane] = rotate_back(
                inc[0, lane],
                inc[1, lane],
                inc[2, lane],
                inc[3, lane],
                vel[0, lane] + acc[idx, 0] * dt,
                vel[1, lane] + acc[idx, 1] * dt,
                vel[2, lane] + acc[idx, 2] * dt,
            )
    for lane in range(n if move_att else 0):
        n0, n1, n2, n3 = quat_mul(
            quat[0, lane],
            quat[1, lane],
            quat[2, lane],
            quat[3, lane],
            inc[0, lane],
            inc[1, lane],
            inc[2, lane],
            inc[3, lane],
        )
        quat[0, lane], quat[1, lane], quat[2, lane], quat[3, lane] = renormalize(n0, n1, n2, n3)
    for i in range(3):
        if i == axis:
            for lane in range(n):
                rates[i, lane] = euler_rate_step(rates[i, lane], pred[lane], dt)
        else:
            for lane in range(n):
                rates[i, lane] = euler_rate_step(rates[i, lane], acc[starts[lane] + k, 3 + i], dt)


@njit(inline="always")
def euler_rate_step(rate, angular_acceleration, dt):
    """Eq. 2's step of one body rate: omega' = omega + alpha dt."""
    return rate + angular_acceleration * dt


@njit(inner=True)
def euler_position_step(quat, vel, pos, dt, mat):
    """Eq. 2's position step x' = x + R(q) V dt, in place on pos (3,); mat (3, 3) work."""
    rotation_matrix(quat[0], quat[1], quat[2], quat[3], mat)
    for i in range(3):
        pos[i] += (mat[i, 0] * vel[0] + mat[i, 1] * vel[1] + mat[i, 2] * vel[2]) * dt


@njit(inline="always")  # a call per step costs more than the step
def euler_velocity_step(rot, idx, v0, v1, v2, a0, a1, a2, dt):
    """Eq. 2's velocity step V' = D^T (V + a dt) with the data's D^T (rot (N, 9), row idx)."""
    b0 = v0 + a0 * dt
    b1 = v1 + a1 * dt
    b2 = v2 + a2 * dt
    return (
        rot[idx, 0] * b0 + rot[idx, 1] * b1 + rot[idx, 2] * b2,
        rot[idx, 3] * b0 + rot[idx, 4] * b1 + rot[idx, 5] * b2,
        rot[idx, 6] * b0 + rot[idx, 7] * b1 + rot[idx, 8] * b2,
    )


@njit(inner=True)
def euler_velocity_tangent(rot, idx, sens, target, grad, dt, tmp):
    """Tangent of euler_velocity_step: S <- D^T (S + e_target dt grad), in place on sens
    (3, n_c); tmp (3, n_c) is a work buffer."""
    n_c = sens.shape[1]
    for i in range(3):
        for c in range(n_c):
            tmp[i, c] = sens[i, c]
    for c in range(n_c):
        tmp[target, c] += grad[c] * dt
    for i in range(3):
        for c in range(n_c):
            sens[i, c] = (
                rot[idx, 3 * i] * tmp[0, c]
                + rot[idx, 3 * i + 1] * tmp[1, c]
                + rot[idx, 3 * i + 2] * tmp[2, c]
            )


@njit(inner=True)
def euler_rate_tangent(
    axis, phi0, theta0, phi1, theta1, q_rate, r_rate, sens, asens, grad, dt, track_angles, kin, jang
):
    """Tangent of an eq. 2 step for rate `axis`'s equation: the angles' sensitivities asens
    (3, n_c) by the Euler kinematics linearised at the step's mid-attitude (from angles
    phi0, theta0 before the step to phi1, theta1 after it, rates q_rate, r_rate), when
    track_angles, then the rate's sensitivity sens (n_c,) += dt grad. kin (3,), jang (3, 2)
    are work buffers."""
    n_c = sens.shape[0]
    if track_angles:  # the kinematics at the step's mid-attitude (2nd order)
        phi_mid = phi0 + 0.5 * wrap_angle(phi1 - phi0)
        theta_mid = 0.5 * (theta0 + theta1)
        euler_kinematics(axis, phi_mid, theta_mid, q_rate, r_rate, kin, jang)
        for c in range(n_c):
            a0, a1 = asens[0, c], asens[1, c]
            for i in range(3):
                asens[i, c] += dt * (jang[i, 0] * a0 + jang[i, 1] * a1 + kin[i] * sens[c])
    for c in range(n_c):
        sens[c] += grad[c] * dt


@njit(inner=True)
def wrap_angle(a):
    """a wrapped to [-pi, pi]."""
    return (a + np.pi) % (2.0 * np.pi) - np.pi


@njit(inner=True)
def euler_kinematics(axis, phi, theta, q, r, column, jang):
    """Partials of the Euler-angle rates (phi, theta, psi)_dot (ZYX) at the current state:
    column (3,) w.r.t. body rate `axis` (0 p, 1 q, 2 r), jang (3, 2) w.r.t. phi and theta.

    phi_dot = p + tan(theta) (q sin(phi) + r cos(phi)), theta_dot = q cos(phi) - r sin(phi),
    psi_dot = (q sin(phi) + r cos(phi)) / cos(theta)."""
    sp, cp = np.sin(phi), np.cos(phi)
    ct = np.cos(theta)
    tt = np.sin(theta) / ct
    if axis == 0:
        column[0], column[1], column[2] = 1.0, 0.0, 0.0
    elif axis == 1:
        column[0], column[1], column[2] = sp * tt, cp, sp / ct
    else:
        column[0], column[1], column[2] = cp * tt, -sp, cp / ct
    lead = q * sp + r * cp  # the yaw-plane rate
    cross = q * cp - r * sp
    jang[0, 0], jang[0, 1] = tt * cross, lead / (ct * ct)
    jang[1, 0], jang[1, 1] = -lead, 0.0
    jang[2, 0], jang[2, 1] = cross / ct, lead * tt / ct


# ---------------------------------------------------------------------------------------------
# rk4: classical Runge-Kutta on the continuous-time ODE


@njit(inner=True)
def rk4_tangent_buffers(n_rows, n_tangent_rows, n_c):
    """The work of one lane of RK4 with tangents: the state, its stage state, slope and
    weighted sum (n_rows, 1), and the same four for the tangents (n_tangent_rows, n_c)."""
    return (
        np.empty((n_rows, 1)),
        np.empty((n_rows, 1)),
        np.zeros((n_rows, 1)),
        np.empty((n_rows, 1)),
        np.zeros((n_tangent_rows, n_c)),
        np.zeros((n_tangent_rows, n_c)),
        np.zeros((n_tangent_rows, n_c)),
        np.zeros((n_tangent_rows, n_c)),
    )


@njit(inline="always")
def stage_state(y, k, node, h, out, lane, n_rows, first=0):
    """out[:n_rows, lane] = y + node h k (the stage's state; node 0 copies y)."""
    if node == 0.0:
        for i in range(first, n_rows):
            out[i, lane] = y[i, lane]
    else:
        step = node * h
        for i in range(first, n_rows):
            out[i, lane] = y[i, lane] + step * k[i, lane]


@njit(inline="always")
def body_stage_state(y, k, node, h, out, lane, n_rows, first=0):
    """stage_state of a body state, its attitude rows normalised: the ODE keeps |q| = 1, and
    the Euler angles and R(q) that the stage's equations read assume it (a stage state
    y + c h k is off by O(h^2), which would cost the scheme two orders)."""
    stage_state(y, k, node, h, out, lane, n_rows, first)
    if node != 0.0 and first == Q:
        unit_attitude(out, lane)


@njit(inline="always")
def unit_attitude(out, lane):
    """out's attitude rows of `lane` divided by their norm (a stage state's)."""
    q0, q1, q2, q3 = out[Q, lane], out[Q + 1, lane], out[Q + 2, lane], out[Q + 3, lane]
    scale = 1.0 / math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
    for i in range(4):
        out[Q + i, lane] *= scale


@njit(inline="always")
def attitude_derivative(y, lane, k):
    """k[Q:Q + 4, lane] = q_dot = q * (0, omega) / 2 at state y[:, lane]."""
    q0, q1, q2, q3 = y[Q, lane], y[Q + 1, lane], y[Q + 2, lane], y[Q + 3, lane]
    p, q, r = y[W, lane], y[W + 1, lane], y[W + 2, lane]
    k[Q, lane] = -0.5 * (q1 * p + q2 * q + q3 * r)
    k[Q + 1, lane] = 0.5 * (q0 * p + q2 * r - q3 * q)
    k[Q + 2, lane] = 0.5 * (q0 * q + q3 * p - q1 * r)
    k[Q + 3, lane] = 0.5 * (q0 * r + q1 * q - q2 * p)


@njit(inline="always")
def velocity_derivative(y, lane, a0, a1, a2, k):
    """k[V:V + 3, lane] = V_dot = a - omega x V at state y[:, lane]."""
    u, v, w = y[V, lane], y[V + 1, lane], y[V + 2, lane]
    p, q, r = y[W, lane], y[W + 1, lane], y[W + 2, lane]
    k[V, lane] = a0 - (q * w - r * v)
    k[V + 1, lane] = a1 - (r * u - p * w)
    k[V + 2, lane] = a2 - (p * v - q * u)


@njit(inline="always")
def body_derivative(y, lane, a0, a1, a2, a3, a4, a5, with_pos, k):
    """k[:, lane] = d/dt of the rigid body at state y[:, lane] (rows Q, V, W and X when
    with_pos) under body accelerations (a0, a1, a2) and angular ones (a3, a4, a5)."""
    attitude_derivative(y, lane, k)
    velocity_derivative(y, lane, a0, a1, a2, k)
    k[W, lane] = a3
    k[W + 1, lane] = a4
    k[W + 2, lane] = a5
    if with_pos:  # x_dot = R(q) V
        q0, q1, q2, q3 = y[Q, lane], y[Q + 1, lane], y[Q + 2, lane], y[Q + 3, lane]
        u, v, w = y[V, lane], y[V + 1, lane], y[V + 2, lane]
        k[X, lane] = (
            (1.0 - 2.0 * (q2 * q2 + q3 * q3)) * u
            + 2.0 * (q1 * q2 - q0 * q3) * v
            + 2.0 * (q1 * q3 + q0 * q2) * w
        )
        k[X + 1, lane] = (
            2.0 * (q1 * q2 + q0 * q3) * u
            + (1.0 - 2.0 * (q1 * q1 + q3 * q3)) * v
            + 2.0 * (q2 * q3 - q0 * q1) * w
        )
        k[X + 2, lane] = (
            2.0 * (q1 * q3 - q0 * q2) * u
            + 2.0 * (q2 * q3 + q0 * q1) * v
            + (1.0 - 2.0 * (q1 * q1 + q2 * q2)) * w
        )


@njit(inline="always")
def accumulate(total, k, weight, stage, lane, n_rows, first=0):
    """total += weight k over the first n_rows rows (stage 0 overwrites)."""
    if stage == 0:
        for i in range(first, n_rows):
            total[i, lane] = weight * k[i, lane]
    else:
        for i in range(first, n_rows):
            total[i, lane] += weight * k[i, lane]


@njit(inline="always")
def advance(y, total, h, lane, n_rows, first=0):
    """y[:n_rows, lane] += h total (a step of rows without an attitude, e.g. tangents)."""
    for i in range(first, n_rows):
        y[i, lane] += h * total[i, lane]


@njit(inline="always")
def finish_step(y, total, h, lane, n_rows, first=0):
    """y += h total, then renormalise the attitude rows."""
    advance(y, total, h, lane, n_rows, first)
    if first != Q:
        return
    y[Q, lane], y[Q + 1, lane], y[Q + 2, lane], y[Q + 3, lane] = renormalize(
        y[Q, lane], y[Q + 1, lane], y[Q + 2, lane], y[Q + 3, lane]
    )
