"""The body-frame quaternion integrator (paper eq. 2) and its discrete inverse.

Forward, for one step of dt seconds with body accelerations a (m/s^2) and
angular accelerations alpha (rad/s^2):

    dq        = exp(omega_t dt / 2)                 (body-frame increment)
    q_{t+1}   = q_t * dq                            (attitude, body -> world)
    V_{t+1}   = D^T (V_t + a_t dt)                  (D = R(dq); D^T = R_{b_t}^{b_{t+1}})
    omega_{t+1} = omega_t + alpha_t dt
    x_{t+1}   = x_t + R(q_t) V_t dt                 (world position)

`body_accelerations` is the exact inverse: integrating its output from the
data's first state reproduces the data's V and omega to round-off.
"""

import numpy as np

from gpquad.engine.kernels.quaternion import (
    quat_mul,
    rate_from_increment,
    rate_increment,
    rotation_matrix,
)
from gpquad.engine.kernels.step import N_STAGES, NODES, WEIGHTS, euler_position_step, euler_step
from gpquad.engine.numba_config import njit


@njit(inner=True)
def integrate_step(quat, vel, rates, pos, acc, dt, mat):
    """Advance one eq. 2 step in place (gpquad.engine.kernels.step.euler_step).

    quat (4,), vel (3,) m/s body, rates (3,) rad/s, pos (3,) m world,
    acc (6,) = [a_x, a_y, a_z, p_dot, q_dot, r_dot]; mat is a (3, 3) work buffer.
    """
    euler_position_step(quat, vel, pos, dt, mat)
    (quat[0], quat[1], quat[2], quat[3], vel[0], vel[1], vel[2], rates[0], rates[1], rates[2]) = (
        euler_step(
            quat[0],
            quat[1],
            quat[2],
            quat[3],
            vel[0],
            vel[1],
            vel[2],
            rates[0],
            rates[1],
            rates[2],
            acc[0],
            acc[1],
            acc[2],
            acc[3],
            acc[4],
            acc[5],
            dt,
            True,
            True,
        )
    )


@njit
def integrate(quat0, vel0, rates0, pos0, acc, dt):
    """Integrate accelerations acc (N, 6) from an initial state.

    Returns quat (N+1, 4), vel (N+1, 3), rates (N+1, 3), pos (N+1, 3).
    """
    n = acc.shape[0]
    quat = np.empty((n + 1, 4))
    vel = np.empty((n + 1, 3))
    rates = np.empty((n + 1, 3))
    pos = np.empty((n + 1, 3))
    q = quat0.copy()
    v = vel0.copy()
    w = rates0.copy()
    x = pos0.copy()
    mat = np.empty((3, 3))
    quat[0], vel[0], rates[0], pos[0] = q, v, w, x
    for t in range(n):
        integrate_step(q, v, w, x, acc[t], dt, mat)
        quat[t + 1], vel[t + 1], rates[t + 1], pos[t + 1] = q, v, w, x
    return quat, vel, rates, pos


@njit
def body_accelerations(vel, rates, dt):
    """Discrete inverse of the integrator: accelerations (N-1, 6) from vel and rates (N, 3).

    alpha_t = (omega_{t+1} - omega_t) / dt and a_t = (D_t V_{t+1} - V_t) / dt,
    with D_t the increment rotation of omega_t.
    """
    n = vel.shape[0]
    acc = np.empty((n - 1, 6))
    mat = np.empty((3, 3))
    for t in range(n - 1):
        d0, d1, d2, d3 = rate_increment(rates[t, 0], rates[t, 1], rates[t, 2], dt)
        rotation_matrix(d0, d1, d2, d3, mat)
        for i in range(3):
            rotated = (
                mat[i, 0] * vel[t + 1, 0] + mat[i, 1] * vel[t + 1, 1] + mat[i, 2] * vel[t + 1, 2]
            )
            acc[t, i] = (rotated - vel[t, i]) / dt
            acc[t, 3 + i] = (rates[t + 1, i] - rates[t, i]) / dt
    return acc


@njit(cache=True)
def rk4_body_accelerations(vel, rates, dt, substeps):
    """The accelerations (N-1, 6) that, held over each sample, carry the data from sample t
    to t+1 under RK4 with `substeps` steps (gpquad.engine.kernels.step), as eq. 2's
    `body_accelerations` do under eq. 2.

    alpha_t = (omega_{t+1} - omega_t) / dt (RK4 integrates a held angular acceleration
    exactly). V_dot = a - omega(t) x V with omega linear over the sample is linear in V and a,
    so RK4 maps V_{t+1} = Phi V_t + Gamma a; a_t = Gamma^-1 (V_{t+1} - Phi V_t), with Phi and
    Gamma from the same RK4 stages on the 3 x 6 matrix [Phi | Gamma].
    """
    n = vel.shape[0]
    acc = np.empty((n - 1, 6))
    h = dt / substeps
    y = np.empty((3, 6))
    ys = np.empty((3, 6))
    k = np.zeros((3, 6))
    total = np.empty((3, 6))
    gamma = np.empty((3, 3))
    rhs = np.empty(3)
    for t in range(n - 1):
        alpha = np.empty(3)
        for i in range(3):
            alpha[i] = (rates[t + 1, i] - rates[t, i]) / dt
            acc[t, 3 + i] = alpha[i]
        y[:, :] = 0.0
        for i in range(3):
            y[i, i] = 1.0
        for m in range(substeps):
            for stage in range(N_STAGES):
                tau = (m + NODES[stage]) * h
                p = rates[t, 0] + tau * alpha[0]
                q = rates[t, 1] + tau * alpha[1]
                r = rates[t, 2] + tau * alpha[2]
                for j in range(6):
                    for i in range(3):
                        ys[i, j] = y[i, j] + NODES[stage] * h * k[i, j] if stage else y[i, j]
                for j in range(6):  # d/dt = -omega x Y + [0 | I]
                    k[0, j] = -(q * ys[2, j] - r * ys[1, j])
                    k[1, j] = -(r * ys[0, j] - p * ys[2, j])
                    k[2, j] = -(p * ys[1, j] - q * ys[0, j])
                for i in range(3):
                    k[i, 3 + i] += 1.0
                for j in range(6):
                    for i in range(3):
                        if stage == 0:
                            total[i, j] = WEIGHTS[stage] * k[i, j]
                        else:
                            total[i, j] += WEIGHTS[stage] * k[i, j]
            for j in range(6):
                for i in range(3):
                    y[i, j] += h * total[i, j]
        for i in range(3):
            rhs[i] = vel[t + 1, i] - (
                y[i, 0] * vel[t, 0] + y[i, 1] * vel[t, 1] + y[i, 2] * vel[t, 2]
            )
        for i in range(3):
            for j in range(3):
                gamma[i, j] = y[i, 3 + j]
        solve3(gamma, rhs)
        for i in range(3):
            acc[t, i] = rhs[i]
    return acc


@njit(inner=True)
def solve3(m, b):
    """b <- m^-1 b for a 3 x 3 m, by Gaussian elimination with partial pivoting (m is
    overwritten). numpy.linalg.solve's LAPACK path costs seconds of compilation per kernel
    that uses it, for the same arithmetic."""
    for c in range(3):
        p = c
        for r in range(c + 1, 3):
            if abs(m[r, c]) > abs(m[p, c]):
                p = r
        if p != c:
            for j in range(3):
                m[c, j], m[p, j] = m[p, j], m[c, j]
            b[c], b[p] = b[p], b[c]
        for r in range(c + 1, 3):
            f = m[r, c] / m[c, c]
            for j in range(c, 3):
                m[r, j] -= f * m[c, j]
            b[r] -= f * b[c]
    for c in range(2, -1, -1):
        s = b[c]
        for j in range(c + 1, 3):
            s -= m[c, j] * b[j]
        b[c] = s / m[c, c]


@njit
def rates_from_quaternions(quat, dt):
    """Body rates (N-1, 3) rad/s such that q_{t+1} = q_t * exp(omega_t dt / 2) exactly."""
    n = quat.shape[0]
    out = np.empty((n - 1, 3))
    for t in range(n - 1):
        d0, d1, d2, d3 = quat_mul(
            quat[t, 0],
            -quat[t, 1],
            -quat[t, 2],
            -quat[t, 3],
            quat[t + 1, 0],
            quat[t + 1, 1],
            quat[t + 1, 2],
            quat[t + 1, 3],
        )
        out[t, 0], out[t, 1], out[t, 2] = rate_from_increment(d0, d1, d2, d3, dt)
    return out


@njit
def world_to_body(quat, world):
    """Rotate world vectors (N, 3) into the body frame with quaternions (N, 4)."""
    n = quat.shape[0]
    out = np.empty((n, 3))
    mat = np.empty((3, 3))
    for t in range(n):
        rotation_matrix(quat[t, 0], quat[t, 1], quat[t, 2], quat[t, 3], mat)
        for i in range(3):
            out[t, i] = mat[0, i] * world[t, 0] + mat[1, i] * world[t, 1] + mat[2, i] * world[t, 2]
    return out
