"""The full-model RK4 rollout (gpquad.engine.kernels.fitness_rk4.rk4_rollout) with the
sensitivities of its scored states to the six trees' constants, by forward mode: the
joint refit's Jacobian in one flight, where forward differences fly one rollout per
constant.

The state is the rollout's: the attitude quaternion, the body velocity and rates, and one
lag state per target, flown by RK4 with `substeps` steps per sample; its arithmetic is the
rollout's, window by window. Each state row carries a tangent row (one column per constant);
the tangents go through every RK4 stage as the derivative of the stage's arithmetic:

- the stage state y + c h k, its attitude normalised: the tangent projected off the
  normalised quaternion and divided by the unnormalised one's length;
- the Euler angles' tangents from the quaternion's, the trees' leaves; each tree's value and
  gradient by reverse mode (gpquad.engine.kernels.tree_tangent), a constant's own column
  where it is fitted (`slots`);
- the rigid body's derivative: q_dot = q (0, omega) / 2 (quaternion product),
  V_dot = a - omega x V, omega_dot = a;
  a lag's tau a_dot = f - a;
- the step's first-order renormalisation q (1.5 - |q|^2 / 2).

Inputs are held over a sample (no tangent); a target without a tree takes the data's
acceleration (no tangent). A diverging window's states and tangents are what the
arithmetic gives (inf or NaN); the caller clips its residuals and zeroes their rows.
"""

import math

import numpy as np

from gpquad.engine.kernels.fitness_rk4 import body_from_data, stage_features
from gpquad.engine.kernels.quaternion import renormalize
from gpquad.engine.kernels.step import (
    BODY_ROWS,
    N_STAGES,
    NODES,
    WEIGHTS,
    Q,
    V,
    W,
    accumulate,
    body_derivative,
    body_stage_state,
    lag_rate_kernel,
    rk4_tangent_buffers,
)
from gpquad.engine.kernels.tree_tangent import eval_with_gradient, gradient_work
from gpquad.engine.numba_config import njit

#: The lag states' first row: one per target after the body's rows.
LAG_ROW = BODY_ROWS
N_ROWS = BODY_ROWS + 6


@njit(inline="always")
def _atan2_gradient(num, den, dnum, dden, out, row):
    """out[row, :4] = d atan2(num, den) / dq from num's and den's gradients (4,)."""
    scale = num * num + den * den
    if scale > 0.0:
        for i in range(4):
            out[row, i] = (den * dnum[i] - num * dden[i]) / scale
    else:
        for i in range(4):
            out[row, i] = 0.0


@njit(inner=True)
def euler_gradients(q0, q1, q2, q3, out, dnum, dden):
    """out (3, 4): the gradients of phi, theta, psi (quaternion.euler_phi, euler_theta,
    euler_psi) with respect to (q0, q1, q2, q3); theta's is zero where it is clamped."""
    # phi = atan2(2 (q0 q1 + q2 q3), 1 - 2 (q1^2 + q2^2))
    dnum[0], dnum[1], dnum[2], dnum[3] = 2.0 * q1, 2.0 * q0, 2.0 * q3, 2.0 * q2
    dden[0], dden[1], dden[2], dden[3] = 0.0, -4.0 * q1, -4.0 * q2, 0.0
    _atan2_gradient(2.0 * (q0 * q1 + q2 * q3), 1.0 - 2.0 * (q1 * q1 + q2 * q2), dnum, dden, out, 0)
    # theta = asin(2 (q0 q2 - q3 q1)), clamped
    s = 2.0 * (q0 * q2 - q3 * q1)
    if -1.0 < s < 1.0:
        c = 1.0 / math.sqrt(1.0 - s * s)
        out[1, 0], out[1, 1] = 2.0 * q2 * c, -2.0 * q3 * c
        out[1, 2], out[1, 3] = 2.0 * q0 * c, -2.0 * q1 * c
    else:
        for i in range(4):
            out[1, i] = 0.0
    # psi = atan2(2 (q0 q3 + q1 q2), 1 - 2 (q2^2 + q3^2))
    dnum[0], dnum[1], dnum[2], dnum[3] = 2.0 * q3, 2.0 * q2, 2.0 * q1, 2.0 * q0
    dden[0], dden[1], dden[2], dden[3] = 0.0, 0.0, -4.0 * q2, -4.0 * q3
    _atan2_gradient(2.0 * (q0 * q3 + q1 * q2), 1.0 - 2.0 * (q2 * q2 + q3 * q3), dnum, dden, out, 2)


@njit
def rk4_rollout_sensitivities(
    codes,
    values,
    sizes,
    delays,
    modelled,
    alphas,
    slots,
    flight,
    starts,
    n_steps,
    substeps,
    out,
    sens,
):
    """Fly the full model as rk4_rollout does (no input noise, no position) and its
    sensitivities (module notes).

    codes, values (6, M), sizes (6,), delays (6, K), modelled (6,), alphas (6,): as
    rk4_rollout's. slots (6, M): the column of each constant node in the Jacobian (-1: not
    fitted, and every other node). out (n_windows, n_steps + 1, 9) receives the states
    [phi, theta, psi, u, v, w, p, q, r]; sens (n_windows, n_steps + 1, 6, n_columns) the
    derivatives of u, v, w, p, q, r."""
    quat_d, states, acc, inputs, rot, dt = flight
    n_in = inputs.shape[1]
    n_slots = delays.shape[1]
    n_c = sens.shape[3]
    h = dt / substeps
    n_leaves = 9 + n_slots
    rates = np.empty(6)
    for t in range(6):
        rates[t] = lag_rate_kernel(alphas[t], dt)
    lagged = alphas < 1.0
    works = []
    for t in range(6):
        works.append(gradient_work(codes[t], sizes[t], n_leaves))
    y, ys, slope, total, tan, tan_s, tan_slope, tan_total = rk4_tangent_buffers(N_ROWS, N_ROWS, n_c)
    features = np.empty((9, 1))
    leaf = np.zeros(n_leaves)
    leaf_tan = np.zeros((n_leaves, n_c))
    grads = np.zeros((6, n_c))
    pred = np.zeros(6)
    a = np.zeros(6)
    da = np.zeros((6, n_c))
    held = np.zeros((6, n_slots))
    every_state = np.ones(9, dtype=np.bool_)
    moving = np.arange(9)  # every state leaf is flown
    jac_euler = np.zeros((3, 4))
    dnum = np.empty(4)
    dden = np.empty(4)
    for w in range(starts.shape[0]):
        s = starts[w]
        for t in range(6):
            y[LAG_ROW + t, 0] = acc[s - 1, t] if s > 0 else 0.0
        body_from_data(y, 0, quat_d, states, s)
        tan[:, :] = 0.0
        tan_slope[:, :] = 0.0
        slope[:, :] = 0.0
        for k in range(n_steps + 1):
            stage_features(y, 0, every_state, features)
            for i in range(9):
                out[w, k, i] = features[i, 0]
            for i in range(3):
                for c in range(n_c):
                    sens[w, k, i, c] = tan[V + i, c]
                    sens[w, k, 3 + i, c] = tan[W + i, c]
            if k == n_steps:
                break
            idx = s + k
            for t in range(6):
                if modelled[t]:
                    for j in range(n_slots):
                        held[t, j] = inputs[idx - delays[t, j], j % n_in]
            for _ in range(substeps):
                for stage in range(N_STAGES):
                    node = NODES[stage]
                    _stage_tangent(y, slope, tan, tan_slope, node, h, ys, tan_s, n_c)
                    stage_features(ys, 0, every_state, features)
                    q0, q1, q2, q3 = ys[Q, 0], ys[Q + 1, 0], ys[Q + 2, 0], ys[Q + 3, 0]
                    euler_gradients(q0, q1, q2, q3, jac_euler, dnum, dden)
                    for c in range(n_c):
                        for i in range(3):
                            leaf_tan[i, c] = (
                                jac_euler[i, 0] * tan_s[Q, c]
                                + jac_euler[i, 1] * tan_s[Q + 1, c]
                                + jac_euler[i, 2] * tan_s[Q + 2, c]
                                + jac_euler[i, 3] * tan_s[Q + 3, c]
                            )
                            leaf_tan[3 + i, c] = tan_s[V + i, c]
                            leaf_tan[6 + i, c] = tan_s[W + i, c]
                    for i in range(9):
                        leaf[i] = features[i, 0]
                    for t in range(6):
                        if not modelled[t]:
                            a[t] = acc[idx, t]
                            for c in range(n_c):
                                da[t, c] = 0.0
                            continue
                        for j in range(n_slots):
                            leaf[9 + j] = held[t, j]
                        pred[t] = eval_with_gradient(
                            codes[t],
                            values[t],
                            sizes[t],
                            slots[t],
                            leaf,
                            leaf_tan,
                            works[t],
                            grads[t],
                            moving,
                        )
                        if lagged[t]:
                            a[t] = ys[LAG_ROW + t, 0]
                            for c in range(n_c):
                                da[t, c] = tan_s[LAG_ROW + t, c]
                        else:
                            a[t] = pred[t]
                            for c in range(n_c):
                                da[t, c] = grads[t, c]
                    body_derivative(ys, 0, a[0], a[1], a[2], a[3], a[4], a[5], False, slope)
                    for t in range(6):
                        lag = LAG_ROW + t
                        if modelled[t] and lagged[t]:
                            slope[lag, 0] = rates[t] * (pred[t] - ys[lag, 0])
                            for c in range(n_c):
                                tan_slope[lag, c] = rates[t] * (grads[t, c] - tan_s[lag, c])
                        else:
                            slope[lag, 0] = 0.0
                            for c in range(n_c):
                                tan_slope[lag, c] = 0.0
                    _body_tangent(ys, tan_s, da, tan_slope, n_c)
                    accumulate(total, slope, WEIGHTS[stage], stage, 0, N_ROWS)
                    for c in range(n_c):
                        accumulate(tan_total, tan_slope, WEIGHTS[stage], stage, c, N_ROWS)
                _finish_tangent(y, total, tan, tan_total, h, n_c)


# The tangent helpers are called, not inlined (their loops over the constants outweigh a
# call): the kernel then compiles in less time and runs no slower.
@njit(inner=True)
def _stage_tangent(y, slope, tan, tan_slope, node, h, ys, tan_s, n_c):
    """ys = the stage state (step.body_stage_state) and tan_s its tangent."""
    body_stage_state(y, slope, node, h, ys, 0, N_ROWS)
    step = node * h
    for i in range(N_ROWS):
        for c in range(n_c):
            tan_s[i, c] = tan[i, c] + step * tan_slope[i, c]
    if node == 0.0:
        return
    # ys's attitude is u / |u| with u = y + step k: its tangent (du - q (q . du)) / |u|
    u0 = y[Q, 0] + step * slope[Q, 0]
    u1 = y[Q + 1, 0] + step * slope[Q + 1, 0]
    u2 = y[Q + 2, 0] + step * slope[Q + 2, 0]
    u3 = y[Q + 3, 0] + step * slope[Q + 3, 0]
    inv = 1.0 / math.sqrt(u0 * u0 + u1 * u1 + u2 * u2 + u3 * u3)
    q0, q1, q2, q3 = ys[Q, 0], ys[Q + 1, 0], ys[Q + 2, 0], ys[Q + 3, 0]
    for c in range(n_c):
        d0, d1, d2, d3 = tan_s[Q, c], tan_s[Q + 1, c], tan_s[Q + 2, c], tan_s[Q + 3, c]
        dot = q0 * d0 + q1 * d1 + q2 * d2 + q3 * d3
        tan_s[Q, c] = (d0 - q0 * dot) * inv
        tan_s[Q + 1, c] = (d1 - q1 * dot) * inv
        tan_s[Q + 2, c] = (d2 - q2 * dot) * inv
        tan_s[Q + 3, c] = (d3 - q3 * dot) * inv


@njit(inner=True)
def _body_tangent(ys, tan_s, da, tan_slope, n_c):
    """tan_slope's body rows: the derivative of step.body_derivative at ys along tan_s,
    with the accelerations' tangents da (6, n_c)."""
    q0, q1, q2, q3 = ys[Q, 0], ys[Q + 1, 0], ys[Q + 2, 0], ys[Q + 3, 0]
    u, v, w = ys[V, 0], ys[V + 1, 0], ys[V + 2, 0]
    p, q, r = ys[W, 0], ys[W + 1, 0], ys[W + 2, 0]
    for c in range(n_c):
        d0, d1, d2, d3 = tan_s[Q, c], tan_s[Q + 1, c], tan_s[Q + 2, c], tan_s[Q + 3, c]
        du, dv, dw = tan_s[V, c], tan_s[V + 1, c], tan_s[V + 2, c]
        dp, dq, dr = tan_s[W, c], tan_s[W + 1, c], tan_s[W + 2, c]
        tan_slope[Q, c] = -0.5 * (d1 * p + q1 * dp + d2 * q + q2 * dq + d3 * r + q3 * dr)
        tan_slope[Q + 1, c] = 0.5 * (d0 * p + q0 * dp + d2 * r + q2 * dr - d3 * q - q3 * dq)
        tan_slope[Q + 2, c] = 0.5 * (d0 * q + q0 * dq + d3 * p + q3 * dp - d1 * r - q1 * dr)
        tan_slope[Q + 3, c] = 0.5 * (d0 * r + q0 * dr + d1 * q + q1 * dq - d2 * p - q2 * dp)
        tan_slope[V, c] = da[0, c] - (dq * w + q * dw - dr * v - r * dv)
        tan_slope[V + 1, c] = da[1, c] - (dr * u + r * du - dp * w - p * dw)
        tan_slope[V + 2, c] = da[2, c] - (dp * v + p * dv - dq * u - q * du)
        tan_slope[W, c] = da[3, c]
        tan_slope[W + 1, c] = da[4, c]
        tan_slope[W + 2, c] = da[5, c]


@njit(inner=True)
def _finish_tangent(y, total, tan, tan_total, h, n_c):
    """y += h total, renormalised as step.finish_step does, and its tangent likewise."""
    for i in range(N_ROWS):
        y[i, 0] += h * total[i, 0]
        for c in range(n_c):
            tan[i, c] += h * tan_total[i, c]
    q0, q1, q2, q3 = y[Q, 0], y[Q + 1, 0], y[Q + 2, 0], y[Q + 3, 0]
    # renormalize: q k with k = 1.5 - |q|^2 / 2, so d(q k) = k dq - q (q . dq)
    k = 1.5 - 0.5 * (q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
    for c in range(n_c):
        d0, d1, d2, d3 = tan[Q, c], tan[Q + 1, c], tan[Q + 2, c], tan[Q + 3, c]
        dot = q0 * d0 + q1 * d1 + q2 * d2 + q3 * d3
        tan[Q, c] = k * d0 - q0 * dot
        tan[Q + 1, c] = k * d1 - q1 * dot
        tan[Q + 2, c] = k * d2 - q2 * dot
        tan[Q + 3, c] = k * d3 - q3 * dot
    y[Q, 0], y[Q + 1, 0], y[Q + 2, 0], y[Q + 3, 0] = renormalize(q0, q1, q2, q3)
