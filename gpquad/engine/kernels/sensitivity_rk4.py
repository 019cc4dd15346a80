"""gpquad.engine.kernels.sensitivity's residuals and Jacobian, flown by RK4.

The windows, residual rows and divergence rule are the eq. 2 kernel's; the state is flown
as in gpquad.engine.kernels.fitness_rk4 (RK4, `substeps` steps per sample, the tree at every
stage, inputs and the data's other accelerations held over the sample). The sensitivities
w.r.t. the tree's constants are the same ones, propagated through the same RK4 stages as
the derivative of the continuous-time ODE (forward mode, one tangent row per state):

- linear targets: the body velocity's sensitivity S (3, n_c), S_dot = e_k da - omega x S
  (omega follows the data's angular accelerations and does not depend on the constants);
  the u, v, w leaves read S. Exact for the discrete RK4 map.
- angular targets: the target rate's sensitivity s, s_dot = da; with angle tangents (or an
  angle row) the Euler angles' sensitivities A (3, n_c), A_dot = J A + e s, the ZYX Euler
  kinematics linearised at the stage's state (gpquad.engine.kernels.step.euler_kinematics);
  the rate leaf reads s, the Euler leaves A when angle_tangents. As in the eq. 2 kernel the
  velocity leaves get zero tangent; the attitude is flown as a quaternion, so A is the
  kinematics' tangent, not the discrete map's (they agree to the scheme's order).
- a lag: its state's sensitivity dl, dl_dot = (df - dl) / tau, and da = dl.

The windows are flown LANES at a time, as lanes: their states step together, and the tree
and its gradient are evaluated once per stage for all of them
(gpquad.engine.kernels.tree_tangent.lanes_eval_with_gradient), each window's arithmetic
its own (docs/decisions/2026-11-28-sensitivity-lanes.md).
"""

import numpy as np

from gpquad.engine.kernels.divergence import STATE_LIMIT, diverged_jacobian_rows, read_leaves
from gpquad.engine.kernels.fitness_rk4 import (
    LAG,
    attitude_and_rates_from_data,
    body_from_data,
    flown_rows,
    lanes_body_slope,
    stage_features_lanes,
)
from gpquad.engine.kernels.quaternion import euler_angle_lanes
from gpquad.engine.kernels.step import (
    BODY_ROWS,
    N_STAGES,
    NODES,
    WEIGHTS,
    Q,
    V,
    W,
    euler_kinematics,
    lag_rate_kernel,
    wrap_angle,
)
from gpquad.engine.kernels.step_lanes import lanes_accumulate, lanes_finish_step, lanes_stage_state
from gpquad.engine.kernels.tree_tangent import (
    constant_slots,
    lanes_eval_with_gradient,
    lanes_gradient_program,
    residual_rows,
    right_children,
    tangent_leaves,
)
from gpquad.engine.numba_config import njit

#: Tangent rows: body velocity (linear targets), the target rate, the Euler angles, the lag.
TV, TR, TA, TL = 0, 3, 4, 7
TANGENT_ROWS = 8
#: Windows flown side by side (lanes): the tree is walked once per stage for all of them.
#: A block of lanes stays in cache; the growing horizon's short windows come by the hundreds
#: (docs/decisions/2026-11-28-sensitivity-lanes.md).
LANES = 64


@njit(inner=True)
def tangent_row(leaf, linear, axis):
    """The tangent row a moving leaf (tangent_leaves) reads."""
    if linear:
        return TV + leaf - 3
    return TR if leaf == 6 + axis else TA + leaf


@njit(inner=True)
def tangent_rows(linear, n_angles, lagged):
    """The tangent rows a flight follows, ascending: the velocity's (linear) or the rate's,
    the first n_angles Euler angles' (phi, theta: the kinematics read them; psi where it is
    read or scored), the lag's when there is one. The others stay zero and nothing reads
    them."""
    rows = np.empty(TANGENT_ROWS, dtype=np.int64)
    n = 0
    for i in range(TANGENT_ROWS):
        if (
            (TV <= i < TR and linear)
            or (i == TR and not linear)
            or (TA <= i < TA + n_angles)
            or (i == TL and lagged)
        ):
            rows[n] = i
            n += 1
    return rows[:n]


@njit(inner=True)
def lanes_tangent_stage(tan, tan_slope, node, h, tan_s, n, n_c, t_rows):
    """The tangents' stage state of lanes 0..n-1 on rows t_rows (stage_state's arithmetic,
    element by element; tangents are (row, constant, lane))."""
    if node == 0.0:
        for r in range(t_rows.shape[0]):
            i = t_rows[r]
            for c in range(n_c):
                for lane in range(n):
                    tan_s[i, c, lane] = tan[i, c, lane]
        return
    step = node * h
    for r in range(t_rows.shape[0]):
        i = t_rows[r]
        for c in range(n_c):
            for lane in range(n):
                tan_s[i, c, lane] = tan[i, c, lane] + step * tan_slope[i, c, lane]


@njit(inner=True)
def lanes_leaf_tangents(grad, leaf_adjoint, tan_s, moving, rows_of, n, n_c):
    """grad[c, lane] += (the leaf's adjoint) x (its tangent) for the moving leaves in order,
    where the adjoint is not zero: eval_with_gradient's sum, a select so that it runs over
    the lanes together."""
    for m in range(moving.shape[0]):
        lf, r = moving[m], rows_of[m]
        for c in range(n_c):
            for lane in range(n):
                g = leaf_adjoint[lf, lane]
                v = grad[c, lane]
                t = v + g * tan_s[r, c, lane]
                grad[c, lane] = t if g != 0.0 else v


@njit(inner=True)
def lanes_tangent_slopes(
    tan_s, tan_slope, grad, ys, kins, jangs, rate, lagged, linear, target, n_angles, n, n_c
):
    """The tangents' slopes of lanes 0..n-1 at a stage (module notes), element by element."""
    for c in range(n_c):
        if lagged:
            for lane in range(n):
                tan_slope[TL, c, lane] = rate * (grad[c, lane] - tan_s[TL, c, lane])
        if linear:
            for lane in range(n):
                df = tan_s[TL, c, lane] if lagged else grad[c, lane]
                p_s, q_s, r_s = ys[W, lane], ys[W + 1, lane], ys[W + 2, lane]
                s0, s1, s2 = tan_s[TV, c, lane], tan_s[TV + 1, c, lane], tan_s[TV + 2, c, lane]
                d0 = -(q_s * s2 - r_s * s1)
                d1 = -(r_s * s0 - p_s * s2)
                d2 = -(p_s * s1 - q_s * s0)
                if target == 0:
                    d0 += df
                elif target == 1:
                    d1 += df
                else:
                    d2 += df
                tan_slope[TV, c, lane] = d0
                tan_slope[TV + 1, c, lane] = d1
                tan_slope[TV + 2, c, lane] = d2
        else:
            for lane in range(n):
                tan_slope[TR, c, lane] = tan_s[TL, c, lane] if lagged else grad[c, lane]
            if n_angles > 0:
                for lane in range(n):
                    a0, a1, s = tan_s[TA, c, lane], tan_s[TA + 1, c, lane], tan_s[TR, c, lane]
                    for i in range(n_angles):
                        tan_slope[TA + i, c, lane] = (
                            jangs[i, 0, lane] * a0 + jangs[i, 1, lane] * a1 + kins[i, lane] * s
                        )


@njit(inner=True)
def lanes_tangent_accumulate(tan_total, tan_slope, weight, stage, n, n_c, t_rows):
    """accumulate of the tangents of lanes 0..n-1 on rows t_rows (stage 0 overwrites)."""
    for r in range(t_rows.shape[0]):
        i = t_rows[r]
        for c in range(n_c):
            if stage == 0:
                for lane in range(n):
                    tan_total[i, c, lane] = weight * tan_slope[i, c, lane]
            else:
                for lane in range(n):
                    tan_total[i, c, lane] += weight * tan_slope[i, c, lane]


@njit
def rk4_window_residuals(
    codes,
    values,
    size,
    delays,
    target,
    flight,
    starts,
    n_steps,
    att_weight,
    angle_tangents,
    alpha,
    res,
    jac,
    substeps,
):
    """gpquad.engine.kernels.sensitivity.window_residuals flown by RK4 (module notes), the
    windows LANES at a time, each window's arithmetic its own."""
    quat_d, states, acc, inputs, rot, dt = flight
    n_in = inputs.shape[1]
    n_c = jac.shape[1]
    n_windows = starts.shape[0]
    linear = target < 3
    axis = target - 3
    n_rows = residual_rows(target, att_weight)
    track_angles = (not linear) and (angle_tangents or n_rows == 2)
    lagged = alpha < 1.0
    rate = lag_rate_kernel(alpha, dt)
    h = dt / substeps
    slot_of = constant_slots(codes, size)
    right = right_children(codes, size)
    moving = tangent_leaves(linear, axis, angle_tangents)
    rows_of = np.array([tangent_row(k, linear, axis) for k in moving])
    n_y = BODY_ROWS + 1
    width = max(1, min(LANES, n_windows))
    program = lanes_gradient_program(codes, values, size, 9 + n_in, width)
    regs, _, _, _, _, _, leaf_adjoint = program
    leaf = regs[: 9 + n_in]  # the register program's leaf rows
    grad = np.empty((n_c, width))
    pred = np.empty(width)
    y, ys, total = np.empty((n_y, width)), np.empty((n_y, width)), np.empty((n_y, width))
    slope = np.zeros((n_y, width))
    # tangents as (row, constant, lane): each stage's arithmetic runs over the lanes together
    tan = np.zeros((TANGENT_ROWS, n_c, width))
    tan_s = np.zeros((TANGENT_ROWS, n_c, width))
    tan_slope = np.zeros((TANGENT_ROWS, n_c, width))
    tan_total = np.zeros((TANGENT_ROWS, n_c, width))
    kins = np.zeros((3, width))
    angle_work, angles = np.empty((2, width)), np.empty(width)
    jangs = np.zeros((3, 2, width))
    alive = np.ones(width, dtype=np.bool_)
    # the leaves computed at each stage: those the tree reads, and the angles the Euler
    # kinematics of the angles' tangents read
    used = read_leaves(codes, size, 9 + n_in)
    used[0] = used[0] or track_angles
    used[1] = used[1] or track_angles
    uses_state = used[:9].any()
    # the body rows stepped, as the fitness kernel steps them (an angle row or the angles'
    # tangents read the angles)
    flown = flown_rows(codes, size, linear, track_angles, n_y)
    # the angles' tangents followed: phi's and theta's (the kinematics read them), psi's
    # where the tree reads psi or its angle is scored
    psi_read = (angle_tangents and used[2]) or (n_rows == 2 and axis == 2)
    n_angles = (3 if psi_read else 2) if track_angles else 0
    t_rows = tangent_rows(linear, n_angles, lagged)
    kin = np.zeros(3)
    jang = np.zeros((3, 2))
    n_diverged = 0
    for first in range(0, n_windows, width):
        n = min(width, n_windows - first)
        for lane in range(n):
            s = starts[first + lane]
            y[LAG, lane] = acc[s - 1, target] if s > 0 else 0.0
            body_from_data(y, lane, quat_d, states, s)
            for i in range(n_y):  # rows not flown keep the start in the stage state
                ys[i, lane] = y[i, lane]
        tan[:, :, :] = 0.0
        tan_slope[:, :, :] = 0.0
        alive[:] = True
        for k in range(n_steps):
            for lane in range(n):
                if not alive[lane]:
                    row = ((first + lane) * n_steps + k) * n_rows
                    diverged_jacobian_rows(res, jac, row, n_rows)
                    continue
                idx = starts[first + lane] + k
                if linear and k > 0:
                    attitude_and_rates_from_data(y, lane, quat_d, states, idx)
                for jj in range(n_in):  # the input leaves the tree reads, held over the sample
                    if used[9 + jj]:
                        leaf[9 + jj, lane] = inputs[idx - delays[jj], jj]
            for _ in range(substeps):
                for stage in range(N_STAGES):
                    node = NODES[stage]
                    # a diverged lane is stepped too, to no purpose
                    lanes_stage_state(y, slope, node, h, ys, n, flown)
                    lanes_tangent_stage(tan, tan_slope, node, h, tan_s, n, n_c, t_rows)
                    if uses_state:
                        stage_features_lanes(ys, used, leaf, n, angle_work)
                    lanes_eval_with_gradient(codes, size, slot_of, right, program, grad, pred, n)
                    lanes_leaf_tangents(grad, leaf_adjoint, tan_s, moving, rows_of, n, n_c)
                    lanes_body_slope(
                        ys, slope, pred, acc, starts, first, k, target, lagged, rate, n, flown
                    )
                    if track_angles:
                        for lane in range(n):
                            q_s, r_s = ys[W + 1, lane], ys[W + 2, lane]
                            euler_kinematics(
                                axis, leaf[0, lane], leaf[1, lane], q_s, r_s, kin, jang
                            )
                            for i in range(3):
                                kins[i, lane] = kin[i]
                                jangs[i, 0, lane] = jang[i, 0]
                                jangs[i, 1, lane] = jang[i, 1]
                    lanes_tangent_slopes(
                        tan_s,
                        tan_slope,
                        grad,
                        ys,
                        kins,
                        jangs,
                        rate,
                        lagged,
                        linear,
                        target,
                        n_angles,
                        n,
                        n_c,
                    )
                    lanes_tangent_accumulate(
                        tan_total, tan_slope, WEIGHTS[stage], stage, n, n_c, t_rows
                    )
                    lanes_accumulate(total, slope, WEIGHTS[stage], stage, n, flown)
                lanes_finish_step(y, total, h, n, flown)
                for r in range(t_rows.shape[0]):
                    i = t_rows[r]
                    for c in range(n_c):
                        for lane in range(n):
                            tan[i, c, lane] += h * tan_total[i, c, lane]
            if n_rows == 2:  # the scored Euler angle, every lane's
                euler_angle_lanes(axis, y, Q, angles, n, angle_work[0], angle_work[1])
            for lane in range(n):
                if not alive[lane]:
                    continue
                idx = starts[first + lane] + k
                row = ((first + lane) * n_steps + k) * n_rows
                x = y[V + target, lane] if linear else y[W + axis, lane]
                if not abs(x) < STATE_LIMIT:
                    alive[lane] = False
                    n_diverged += 1
                    diverged_jacobian_rows(res, jac, row, n_rows)
                    continue
                res[row] = x - states[idx + 1, 3 + target]
                for c in range(n_c):
                    jac[row, c] = tan[TV + target, c, lane] if linear else tan[TR, c, lane]
                if n_rows == 2:
                    res[row + 1] = att_weight * wrap_angle(angles[lane] - states[idx + 1, axis])
                    for c in range(n_c):
                        jac[row + 1, c] = att_weight * tan[TA + axis, c, lane]
    return n_diverged
