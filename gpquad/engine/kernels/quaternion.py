"""Quaternion maths for the body-frame integrator (scalar-first, Hamilton product).

A quaternion q = (w, x, y, z) rotates body vectors into the world frame:
v_world = q * v_body * conj(q). Body rates omega (rad/s) held over dt give the
body-frame increment dq = exp(omega dt / 2), and q_{t+1} = q_t * dq.
The rotation matrix D of dq maps body_{t+1} vectors into body_t, so the
paper's R_{b_t}^{b_{t+1}} is D^T.
"""

import math

import numpy as np

from gpquad.engine.kernels.arctrig import asin, atan2_lanes
from gpquad.engine.numba_config import njit


@njit
def quat_mul(a0, a1, a2, a3, b0, b1, b2, b3):
    """Hamilton product a * b, as a 4-tuple."""
    return (
        a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3,
        a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2,
        a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1,
        a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0,
    )


# Taylor coefficients of sin(h)/h and cos(h) in powers of h^2, exact to double precision
# for h < SERIES_LIMIT (the last term kept is below 1e-19 there).
SERIES_LIMIT = 0.5


@njit(inline="always")
def increment_series(p, q, r, dt):
    """(d0, d1, d2, d3, h2): rate_increment by its series in h^2 = h2, exact only for
    h2 < SERIES_LIMIT^2 (rate_increment's hot path; without its sin/cos branch a loop over
    lanes vectorises)."""
    h2 = 0.25 * (p * p + q * q + r * r) * dt * dt
    sinc = 1.0 + h2 * (
        -1.0 / 6.0
        + h2
        * (
            1.0 / 120.0
            + h2
            * (
                -1.0 / 5040.0
                + h2
                * (
                    1.0 / 362880.0
                    + h2
                    * (
                        -1.0 / 39916800.0
                        + h2 * (1.0 / 6227020800.0 + h2 * (-1.0 / 1307674368000.0))
                    )
                )
            )
        )
    )
    cosh = 1.0 + h2 * (
        -0.5
        + h2
        * (
            1.0 / 24.0
            + h2
            * (
                -1.0 / 720.0
                + h2
                * (
                    1.0 / 40320.0
                    + h2
                    * (-1.0 / 3628800.0 + h2 * (1.0 / 479001600.0 + h2 * (-1.0 / 87178291200.0)))
                )
            )
        )
    )
    s = 0.5 * dt * sinc
    return cosh, p * s, q * s, r * s, h2


@njit(inner=True)
def rate_increment(p, q, r, dt):
    """dq = exp(omega dt / 2) for body rates (p, q, r) rad/s held over dt s.

    With h = |omega| dt / 2, dq = (cos h, sin(h)/h * omega dt / 2). Below SERIES_LIMIT
    both are evaluated as series in h^2 (increment_series: no sqrt, sin or cos, the hot
    path).
    """
    d0, d1, d2, d3, h2 = increment_series(p, q, r, dt)
    if h2 < SERIES_LIMIT * SERIES_LIMIT:
        return d0, d1, d2, d3
    h = math.sqrt(h2)
    s = 0.5 * dt * (math.sin(h) / h)
    return math.cos(h), p * s, q * s, r * s


@njit(inner=True)
def renormalize(q0, q1, q2, q3):
    """First-order renormalisation of a nearly unit quaternion (no sqrt or division)."""
    k = 1.5 - 0.5 * (q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
    return q0 * k, q1 * k, q2 * k, q3 * k


@njit(inner=True)
def rate_from_increment(d0, d1, d2, d3, dt):
    """Inverse of rate_increment: body rates (rad/s) from a unit increment quaternion.

    Unique for rotations below half a turn per step (|omega| dt < pi).
    """
    if d0 < 0.0:  # same rotation, shorter way round
        d0, d1, d2, d3 = -d0, -d1, -d2, -d3
    vnorm = math.sqrt(d1 * d1 + d2 * d2 + d3 * d3)
    if vnorm < 1e-15:
        return 2.0 * d1 / dt, 2.0 * d2 / dt, 2.0 * d3 / dt
    angle = 2.0 * math.atan2(vnorm, d0)
    scale = angle / (vnorm * dt)
    return d1 * scale, d2 * scale, d3 * scale


@njit(inner=True)
def rotate_back(d0, d1, d2, d3, b0, b1, b2):
    """R(d)^T b: express body_t vector b in body_{t+1} for the increment d (rotation by conj(d))."""
    # v' = b + w t + u' x t with u' = -u and t = 2 (u' x b)
    t0 = 2.0 * (d3 * b1 - d2 * b2)
    t1 = 2.0 * (d1 * b2 - d3 * b0)
    t2 = 2.0 * (d2 * b0 - d1 * b1)
    return (
        b0 + d0 * t0 + (d3 * t1 - d2 * t2),
        b1 + d0 * t1 + (d1 * t2 - d3 * t0),
        b2 + d0 * t2 + (d2 * t0 - d1 * t1),
    )


@njit
def rotation_matrix(q0, q1, q2, q3, out):
    """Fill out (3, 3) with the rotation matrix of unit quaternion q (body -> world)."""
    out[0, 0] = 1.0 - 2.0 * (q2 * q2 + q3 * q3)
    out[0, 1] = 2.0 * (q1 * q2 - q0 * q3)
    out[0, 2] = 2.0 * (q1 * q3 + q0 * q2)
    out[1, 0] = 2.0 * (q1 * q2 + q0 * q3)
    out[1, 1] = 1.0 - 2.0 * (q1 * q1 + q3 * q3)
    out[1, 2] = 2.0 * (q2 * q3 - q0 * q1)
    out[2, 0] = 2.0 * (q1 * q3 - q0 * q2)
    out[2, 1] = 2.0 * (q2 * q3 + q0 * q1)
    out[2, 2] = 1.0 - 2.0 * (q1 * q1 + q2 * q2)


@njit(inner=True)
def euler_phi(q0, q1, q2, q3):
    """Roll (rad) of a body-to-world quaternion, ZYX convention."""
    return math.atan2(2.0 * (q0 * q1 + q2 * q3), 1.0 - 2.0 * (q1 * q1 + q2 * q2))


@njit(inner=True)
def euler_theta(q0, q1, q2, q3):
    """Pitch (rad), ZYX convention; clamped at +-pi/2."""
    s = 2.0 * (q0 * q2 - q3 * q1)
    return math.asin(min(1.0, max(-1.0, s)))


@njit(inner=True)
def euler_psi(q0, q1, q2, q3):
    """Yaw (rad), ZYX convention."""
    return math.atan2(2.0 * (q0 * q3 + q1 * q2), 1.0 - 2.0 * (q2 * q2 + q3 * q3))


@njit(inner=True)
def euler_angle(axis, q0, q1, q2, q3):
    """Euler angle `axis` (0 phi, 1 theta, 2 psi) of the attitude."""
    if axis == 0:
        return euler_phi(q0, q1, q2, q3)
    if axis == 1:
        return euler_theta(q0, q1, q2, q3)
    return euler_psi(q0, q1, q2, q3)


@njit(inner=True)
def euler_angle_lanes(axis, quat, row, out, n, y, x):
    """out[:n] = euler_angle(axis) of the attitudes quat[row:row + 4, :n] within 1 ulp, in
    loops that vectorise: gpquad.engine.kernels.arctrig's atan2 and asin (not libm's bits,
    which euler_angle keeps for the full-model rollouts and exports). y, x (n,) are work
    buffers."""
    if axis == 1:
        for lane in range(n):
            s = 2.0 * (
                quat[row, lane] * quat[row + 2, lane] - quat[row + 3, lane] * quat[row + 1, lane]
            )
            out[lane] = asin(min(1.0, max(-1.0, s)))  # as euler_theta
        return
    for lane in range(n):
        q0, q1 = quat[row, lane], quat[row + 1, lane]
        q2, q3 = quat[row + 2, lane], quat[row + 3, lane]
        if axis == 0:
            y[lane] = 2.0 * (q0 * q1 + q2 * q3)
            x[lane] = 1.0 - 2.0 * (q1 * q1 + q2 * q2)
        else:
            y[lane] = 2.0 * (q0 * q3 + q1 * q2)
            x[lane] = 1.0 - 2.0 * (q2 * q2 + q3 * q3)
    atan2_lanes(y, x, out, n)


@njit(inner=True)
def euler_from_quat(q0, q1, q2, q3):
    """ZYX Euler angles (phi, theta, psi) in rad of a body-to-world quaternion."""
    return euler_phi(q0, q1, q2, q3), euler_theta(q0, q1, q2, q3), euler_psi(q0, q1, q2, q3)


@njit
def euler_array(quat):
    """Euler angles, shape (N, 3) rad, of quaternions shape (N, 4)."""
    n = quat.shape[0]
    out = np.empty((n, 3))
    for i in range(n):
        out[i, 0], out[i, 1], out[i, 2] = euler_from_quat(
            quat[i, 0], quat[i, 1], quat[i, 2], quat[i, 3]
        )
    return out


@njit
def quat_from_euler(phi, theta, psi):
    """Body-to-world quaternion of ZYX Euler angles (rad)."""
    cr, sr = math.cos(0.5 * phi), math.sin(0.5 * phi)
    cp, sp = math.cos(0.5 * theta), math.sin(0.5 * theta)
    cy, sy = math.cos(0.5 * psi), math.sin(0.5 * psi)
    return (
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    )


@njit
def body_rotations(rates, dt):
    """Per-sample D^T = R_{b_t}^{b_{t+1}}, shape (N, 9) row-major, from rates (N, 3) rad/s."""
    n = rates.shape[0]
    out = np.empty((n, 9))
    mat = np.empty((3, 3))
    for i in range(n):
        d0, d1, d2, d3 = rate_increment(rates[i, 0], rates[i, 1], rates[i, 2], dt)
        rotation_matrix(d0, d1, d2, d3, mat)
        for a in range(3):
            for b in range(3):
                out[i, 3 * a + b] = mat[b, a]
    return out
