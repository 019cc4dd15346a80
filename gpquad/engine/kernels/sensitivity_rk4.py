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
"""

import numpy as np

from gpquad.engine.kernels.divergence import DIVERGED_RESIDUAL, STATE_LIMIT, read_leaves
from gpquad.engine.kernels.fitness_rk4 import (
    LAG,
    attitude_and_rates_from_data,
    body_from_data,
    stage_features,
)
from gpquad.engine.kernels.quaternion import euler_angle
from gpquad.engine.kernels.step import (
    BODY_ROWS,
    N_STAGES,
    NODES,
    WEIGHTS,
    Q,
    V,
    W,
    accumulate,
    advance,
    body_derivative,
    body_stage_state,
    euler_kinematics,
    finish_step,
    lag_rate_kernel,
    rk4_tangent_buffers,
    stage_state,
    wrap_angle,
)
from gpquad.engine.kernels.tree_tangent import (
    constant_slots,
    eval_with_gradient,
    gradient_work,
    residual_rows,
    tangent_leaves,
)
from gpquad.engine.numba_config import njit

#: Tangent rows: body velocity (linear targets), the target rate, the Euler angles, the lag.
TV, TR, TA, TL = 0, 3, 4, 7
TANGENT_ROWS = 8


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
    """gpquad.engine.kernels.sensitivity.window_residuals flown by RK4 (module notes)."""
    quat_d, states, acc, inputs, rot, dt = flight
    n_in = inputs.shape[1]
    n_c = jac.shape[1]
    linear = target < 3
    axis = target - 3
    n_rows = residual_rows(target, att_weight)
    track_angles = (not linear) and (angle_tangents or n_rows == 2)
    lagged = alpha < 1.0
    rate = lag_rate_kernel(alpha, dt)
    h = dt / substeps
    slot_of = constant_slots(codes, size)
    n_y = BODY_ROWS + 1
    features = np.zeros((9 + n_in, 1))
    leaf = np.zeros(9 + n_in)
    tangents = np.zeros((9 + n_in, n_c))
    work = gradient_work(codes, size, 9 + n_in)
    moving = tangent_leaves(linear, axis, angle_tangents)
    grad = np.empty(n_c)
    y, ys, slope, total, tan, tan_s, tan_slope, tan_total = rk4_tangent_buffers(
        n_y, TANGENT_ROWS, n_c
    )
    # the leaves computed at each stage: those the tree reads, and the angles the Euler
    # kinematics of the angles' tangents read
    used = read_leaves(codes, size, 9 + n_in)
    used[0] = used[0] or track_angles
    used[1] = used[1] or track_angles
    uses_state = used[:9].any()
    # tangent rows followed: the velocity's (linear) or the rate's, the angles' where they
    # are tracked, the lag's when there is one
    t_first = TV if linear else TR
    t_end = TANGENT_ROWS if lagged else (TV + 3 if linear else (TA + 3 if track_angles else TR + 1))
    a = np.empty(6)
    kin = np.zeros(3)
    jang = np.zeros((3, 2))
    n_diverged = 0
    for w in range(starts.shape[0]):
        s = starts[w]
        y[LAG, 0] = acc[s - 1, target] if s > 0 else 0.0
        body_from_data(y, 0, quat_d, states, s)
        tan[:, :] = 0.0
        tan_slope[:, :] = 0.0
        alive = True
        for k in range(n_steps):
            row = (w * n_steps + k) * n_rows
            if not alive:
                for extra in range(n_rows):
                    res[row + extra] = DIVERGED_RESIDUAL
                    jac[row + extra, :] = 0.0
                continue
            idx = s + k
            if linear and k > 0:
                attitude_and_rates_from_data(y, 0, quat_d, states, idx)
            for jj in range(n_in):  # the input leaves the tree reads, held over the sample
                if used[9 + jj]:
                    leaf[9 + jj] = inputs[idx - delays[jj], jj]
            for _ in range(substeps):
                for stage in range(N_STAGES):
                    node = NODES[stage]
                    body_stage_state(y, slope, node, h, ys, 0, n_y)
                    for c in range(n_c):
                        stage_state(tan, tan_slope, node, h, tan_s, c, t_end, t_first)
                    if uses_state:
                        stage_features(ys, 0, used, features)
                        for i in range(9):
                            leaf[i] = features[i, 0]
                    for c in range(n_c):  # the other rows stay zero
                        if linear:
                            for i in range(3):
                                tangents[3 + i, c] = tan_s[TV + i, c]
                        else:
                            tangents[6 + axis, c] = tan_s[TR, c]
                            if angle_tangents:
                                for i in range(3):
                                    tangents[i, c] = tan_s[TA + i, c]
                    pred = eval_with_gradient(
                        codes, values, size, slot_of, leaf, tangents, work, grad, moving
                    )
                    f = ys[LAG, 0] if lagged else pred
                    for i in range(6):
                        a[i] = acc[idx, i]
                    a[target] = f
                    body_derivative(ys, 0, a[0], a[1], a[2], a[3], a[4], a[5], False, slope)
                    slope[LAG, 0] = rate * (pred - ys[LAG, 0]) if lagged else 0.0
                    accumulate(total, slope, WEIGHTS[stage], stage, 0, n_y)
                    p_s, q_s, r_s = ys[W, 0], ys[W + 1, 0], ys[W + 2, 0]
                    if track_angles:
                        euler_kinematics(axis, leaf[0], leaf[1], q_s, r_s, kin, jang)
                    for c in range(n_c):
                        df = tan_s[TL, c] if lagged else grad[c]
                        tan_slope[TL, c] = rate * (grad[c] - tan_s[TL, c]) if lagged else 0.0
                        if linear:
                            s0, s1, s2 = tan_s[TV, c], tan_s[TV + 1, c], tan_s[TV + 2, c]
                            tan_slope[TV, c] = -(q_s * s2 - r_s * s1)
                            tan_slope[TV + 1, c] = -(r_s * s0 - p_s * s2)
                            tan_slope[TV + 2, c] = -(p_s * s1 - q_s * s0)
                            tan_slope[TV + target, c] += df
                        else:
                            tan_slope[TR, c] = df
                            if track_angles:
                                a0, a1 = tan_s[TA, c], tan_s[TA + 1, c]
                                for i in range(3):
                                    tan_slope[TA + i, c] = (
                                        jang[i, 0] * a0 + jang[i, 1] * a1 + kin[i] * tan_s[TR, c]
                                    )
                        accumulate(tan_total, tan_slope, WEIGHTS[stage], stage, c, t_end, t_first)
                finish_step(y, total, h, 0, n_y)
                for c in range(n_c):
                    advance(tan, tan_total, h, c, t_end, t_first)
            x = y[V + target, 0] if linear else y[W + axis, 0]
            if not abs(x) < STATE_LIMIT:
                alive = False
                n_diverged += 1
                for extra in range(n_rows):
                    res[row + extra] = DIVERGED_RESIDUAL
                    jac[row + extra, :] = 0.0
                continue
            res[row] = x - states[idx + 1, 3 + target]
            for c in range(n_c):
                jac[row, c] = tan[TV + target, c] if linear else tan[TR, c]
            if n_rows == 2:
                angle = euler_angle(axis, y[Q, 0], y[Q + 1, 0], y[Q + 2, 0], y[Q + 3, 0])
                res[row + 1] = att_weight * wrap_angle(angle - states[idx + 1, axis])
                for c in range(n_c):
                    jac[row + 1, c] = att_weight * tan[TA + axis, c]
    return n_diverged
