"""Forward-mode sensitivities of the integrated target state w.r.t. a tree's constants.

For a tree modelling target k flown as in gpquad.engine.kernels.fitness (the tree supplies
acceleration k, the data the other five), `window_residuals` returns for every window
and step the residual x_k(pred) - x_k(data) (the fitness's error before abs/square) and
its Jacobian with respect to the constants of the tree (one column per CONST node, in
prefix order), for a Gauss-Newton / Levenberg-Marquardt fit on the integrated error.

At each step the tree's gradient is that of the tree with tangents: a constant leaf j
carries the unit tangent e_j, a leaf that the integrator produces from the tree carries the
current sensitivity of that state, every other leaf (data, inputs) carries zero; the
operators apply the chain rule (protected division: zero derivative where the division is
replaced by 1). It is computed by one reverse pass over the tree
(gpquad.engine.kernels.tree_tangent.eval_with_gradient); the sensitivities go forward in
time. The state
sensitivity is then advanced through the integrator step:

- linear targets (a_x, a_y, a_z): the body velocity's sensitivity S (3, n_c) follows
  S <- D^T (S + e_k dt da/dtheta), the rotation taken from the data, exactly as the
  velocity itself; leaves u, v, w read rows of S. This is the exact derivative.
- angular targets: the target rate's sensitivity s follows s <- s + dt da/dtheta and the
  target's rate leaf reads it; the other rates come from the data's accelerations and do not
  depend on the constants. The Euler angles' sensitivities A (3, n_c) follow the Euler
  kinematics linearised at the current state, A <- A + dt (J A + e s) (e: d(phi, theta,
  psi)_dot / d(target rate), J: d(phi, theta, psi)_dot / d(phi, theta)). With
  angle_tangents the Euler leaves read them: this is what lets LM see that k in
  k (u_R - phi) closes a loop (within a few per cent of central differences; the
  Euler-rate form differs from the integrator's exponential map by O(dt) per step).
  Without, the Euler leaves get zero tangent (off by 90-600 % on stiff-loop trees): the
  engine's default, because the exact Jacobian lets LM fit attitude loops as stiff as
  the data allow (gains ~1800 where the truth is 544, at 25 Hz), which fly alone but
  diverge together (gpquad.models.stability). The velocity leaves of angular targets get
  zero tangent; the Jacobian is exact for trees that read only rates, inputs and data
  states.

With att_weight > 0 (angular targets; gpquad.engine.kernels.fitness) every step has a
second row, att_weight * (angle - angle(data)) for the angle the target's rate integrates
into (wrapped), with Jacobian att_weight * A of that angle: rows 2 (w n_steps + k) and
2 (w n_steps + k) + 1.

With a lag (alpha < 1, gpquad.engine.kernels.fitness) the applied acceleration and its
gradient follow the same filter: a <- a + alpha (f - a), da <- da + alpha (df - da).

Flat arrays only: codes, values, size, delays as the fitness kernel; flight is FlightArrays.
"""

import numpy as np

from gpquad.engine.kernels.divergence import (
    DIVERGED_RESIDUAL,
    STATE_LIMIT,
    diverged_jacobian_rows,
    read_leaves,
    uses_leaves,
)
from gpquad.engine.kernels.quaternion import euler_phi, euler_psi, euler_theta
from gpquad.engine.kernels.sensitivity_rk4 import rk4_window_residuals
from gpquad.engine.kernels.step import (
    RK4,
    euler_kinematics,
    euler_rate_tangent,
    euler_step,
    euler_velocity_step,
    euler_velocity_tangent,
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

__all__ = [
    "DIVERGED_RESIDUAL",
    "eval_with_gradient",
    "euler_kinematics",
    "residual_rows",
    "window_residuals",
]


def window_residuals(
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
    scheme,
    substeps,
):
    """Residuals res (n_windows * n_steps * rows,) and Jacobian jac (same rows, n_c), rows =
    residual_rows(target, att_weight); angle_tangents: the Euler leaves read their
    sensitivities (module notes); alpha: the equation's lag factor (1 = no lag).

    Row (w * n_steps + k) * rows is window w after k + 1 steps. n_c = number of CONST
    nodes. A window whose state diverges (NaN or beyond STATE_LIMIT) gets DIVERGED_RESIDUAL
    and zero Jacobian rows from that step on. Returns the number of diverged windows.
    scheme, substeps: the integrator (gpquad.engine.kernels.step; RK4 in
    gpquad.engine.kernels.sensitivity_rk4), picked here in Python so that a process compiles
    only the kernels of the schemes it flies.
    """
    if scheme == RK4:
        return rk4_window_residuals(
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
        )
    return euler_window_residuals(
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
    )


@njit
def euler_window_residuals(
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
):
    """window_residuals flown by eq. 2 (module notes)."""
    quat_d, states, acc, inputs, rot, dt = flight
    n_in = inputs.shape[1]
    n_c = jac.shape[1]
    linear = target < 3
    n_rows = residual_rows(target, att_weight)
    # the angles' sensitivities are followed only where something reads them
    track_angles = (not linear) and (angle_tangents or n_rows == 2)
    # an angle is computed where the tree or the angles' tangents read it; the step's
    # angles after it are the next step's before it
    need_phi = track_angles or uses_leaves(codes, size, 0, 0)
    need_theta = track_angles or uses_leaves(codes, size, 1, 1)
    need_psi = uses_leaves(codes, size, 2, 2)
    # an angular target's attitude and velocity are stepped only where something reads them
    # (the rates and their residuals do not depend on them)
    move_att = need_phi or need_theta or need_psi or n_rows == 2
    move_vel = uses_leaves(codes, size, 3, 5)
    slot_of = constant_slots(codes, size)
    used = read_leaves(codes, size, 9 + n_in)
    features = np.zeros(9 + n_in)
    tangents = np.zeros((9 + n_in, n_c))
    work = gradient_work(codes, size, 9 + n_in)
    moving = tangent_leaves(linear, target - 3, angle_tangents)
    grad = np.empty(n_c)
    sens = np.zeros((3, n_c))  # linear: d vel / d theta; angular: row 0 = d rate_k / d theta
    asens = np.zeros((3, n_c))  # angular: d (phi, theta, psi) / d theta
    kin = np.zeros(3)
    jang = np.zeros((3, 2))
    tmp = np.empty((3, n_c))
    vel = np.empty(3)
    rates = np.empty(3)
    lagged = alpha < 1.0
    dapplied = np.zeros(n_c)  # gradient of the lagged acceleration
    n_diverged = 0
    for w in range(starts.shape[0]):
        s = starts[w]
        applied = acc[s - 1, target] if s > 0 else 0.0
        dapplied[:] = 0.0
        q0, q1, q2, q3 = quat_d[s, 0], quat_d[s, 1], quat_d[s, 2], quat_d[s, 3]
        for i in range(3):
            vel[i] = states[s, 3 + i]
            rates[i] = states[s, 6 + i]
        sens[:, :] = 0.0
        asens[:, :] = 0.0
        alive = True
        phi1 = euler_phi(q0, q1, q2, q3) if need_phi else 0.0
        theta1 = euler_theta(q0, q1, q2, q3) if need_theta else 0.0
        for k in range(n_steps):
            row = (w * n_steps + k) * n_rows
            if not alive:
                diverged_jacobian_rows(res, jac, row, n_rows)
                continue
            idx = s + k
            if linear:  # the leaves' tangents below are set every step, the others stay zero
                for i in (0, 1, 2, 6, 7, 8):
                    features[i] = states[idx, i]
                for i in range(3):
                    features[3 + i] = vel[i]
                    for c in range(n_c):
                        tangents[3 + i, c] = sens[i, c]
            else:
                features[0] = phi1
                features[1] = theta1
                if need_psi:
                    features[2] = euler_psi(q0, q1, q2, q3)
                for i in range(3):
                    features[3 + i] = vel[i]
                    features[6 + i] = rates[i]
                for c in range(n_c):
                    tangents[6 + target - 3, c] = sens[0, c]
                    if angle_tangents:
                        for i in range(3):
                            tangents[i, c] = asens[i, c]
            for jj in range(n_in):  # the input leaves the tree reads
                if used[9 + jj]:
                    features[9 + jj] = inputs[idx - delays[jj], jj]
            pred = eval_with_gradient(
                codes, values, size, slot_of, features, tangents, work, grad, moving
            )
            if lagged:
                applied += alpha * (pred - applied)
                pred = applied
                for c in range(n_c):
                    dapplied[c] += alpha * (grad[c] - dapplied[c])
                    grad[c] = dapplied[c]
            if linear:
                a0, a1, a2 = acc[idx, 0], acc[idx, 1], acc[idx, 2]
                if target == 0:
                    a0 = pred
                elif target == 1:
                    a1 = pred
                else:
                    a2 = pred
                vel[0], vel[1], vel[2] = euler_velocity_step(
                    rot, idx, vel[0], vel[1], vel[2], a0, a1, a2, dt
                )
                euler_velocity_tangent(rot, idx, sens, target, grad, dt, tmp)
                x = vel[target]
                for c in range(n_c):
                    jac[row, c] = sens[target, c]
            else:
                a3, a4, a5 = acc[idx, 3], acc[idx, 4], acc[idx, 5]
                if target == 3:
                    a3 = pred
                elif target == 4:
                    a4 = pred
                else:
                    a5 = pred
                q0, q1, q2, q3, vel[0], vel[1], vel[2], rates[0], rates[1], rates[2] = euler_step(
                    q0,
                    q1,
                    q2,
                    q3,
                    vel[0],
                    vel[1],
                    vel[2],
                    rates[0],
                    rates[1],
                    rates[2],
                    acc[idx, 0],
                    acc[idx, 1],
                    acc[idx, 2],
                    a3,
                    a4,
                    a5,
                    dt,
                    move_vel,
                    move_att,
                )
                phi1 = euler_phi(q0, q1, q2, q3) if need_phi else 0.0
                theta1 = euler_theta(q0, q1, q2, q3) if need_theta else 0.0
                euler_rate_tangent(
                    target - 3,
                    features[0],
                    features[1],
                    phi1,
                    theta1,
                    features[7],
                    features[8],
                    sens[0],
                    asens,
                    grad,
                    dt,
                    track_angles,
                    kin,
                    jang,
                )
                for c in range(n_c):
                    jac[row, c] = sens[0, c]
                x = rates[target - 3]
            if not abs(x) < STATE_LIMIT:
                alive = False
                n_diverged += 1
                diverged_jacobian_rows(res, jac, row, n_rows)
                continue
            res[row] = x - states[idx + 1, 3 + target]
            if n_rows == 2:
                a = target - 3
                angle = phi1 if a == 0 else theta1 if a == 1 else euler_psi(q0, q1, q2, q3)
                res[row + 1] = att_weight * wrap_angle(angle - states[idx + 1, a])
                for c in range(n_c):
                    jac[row + 1, c] = att_weight * asens[a, c]
    return n_diverged
