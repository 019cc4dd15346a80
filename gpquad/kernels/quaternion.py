"""Quaternion maths for the body-frame integrator (scalar-first, Hamilton product).

A quaternion q = (w, x, y, z) rotates body vectors into the world frame:
v_world = q * v_body * conj(q). Body rates omega (rad/s) held over dt give the
body-frame increment dq = exp(omega dt / 2), and q_{t+1} = q_t * dq.
The rotation matrix D of dq maps body_{t+1} vectors into body_t, so the
paper's R_{b_t}^{b_{t+1}} is D^T.
"""

import math

import numpy as np

from gpquad.numba_config import njit


@njit
def quat_mul(a0, a1, a2, a3, b0, b1, b2, b3):
    """Hamilton product a * b, as a 4-tuple."""
    return (
        a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3,
        a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2,
        a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1,
        a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0,
    )


@njit
def rate_increment(p, q, r, dt):
    """dq = exp(omega dt / 2) for body rates (p, q, r) rad/s held over dt s."""
    angle = math.sqrt(p * p + q * q + r * r) * dt
    half = 0.5 * angle
    if angle < 1e-12:
        # Second-order series; exact to round-off at these angles.
        s = 0.5 * dt
        return 1.0, p * s, q * s, r * s
    s = math.sin(half) * dt / angle
    return math.cos(half), p * s, q * s, r * s


@njit
def rate_from_increment(d0, d1, d2, d3, dt):
    """Inverse of rate_increment: body rates (rad/s) from a unit increment quaternion."""
    if d0 < 0.0:  # same rotation, shorter way round
        d0, d1, d2, d3 = -d0, -d1, -d2, -d3
    vnorm = math.sqrt(d1 * d1 + d2 * d2 + d3 * d3)
    if vnorm < 1e-15:
        return 2.0 * d1 / dt, 2.0 * d2 / dt, 2.0 * d3 / dt
    angle = 2.0 * math.atan2(vnorm, d0)
    scale = angle / (vnorm * dt)
    return d1 * scale, d2 * scale, d3 * scale


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


@njit
def euler_from_quat(q0, q1, q2, q3):
    """ZYX Euler angles (phi, theta, psi) in rad of a body-to-world quaternion."""
    phi = math.atan2(2.0 * (q0 * q1 + q2 * q3), 1.0 - 2.0 * (q1 * q1 + q2 * q2))
    s = 2.0 * (q0 * q2 - q3 * q1)
    s = min(1.0, max(-1.0, s))
    theta = math.asin(s)
    psi = math.atan2(2.0 * (q0 * q3 + q1 * q2), 1.0 - 2.0 * (q2 * q2 + q3 * q3))
    return phi, theta, psi


@njit
def euler_array(quat):
    """Euler angles, shape (N, 3) rad, of quaternions shape (N, 4)."""
    n = quat.shape[0]
    out = np.empty((n, 3))
    for i in range(n):
        out[i, 0], out[i, 1], out[i, 2] = euler_from_quat(quat[i, 0], quat[i, 1], quat[i, 2], quat[i, 3])
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
