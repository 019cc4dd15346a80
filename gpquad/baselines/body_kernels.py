"""Numba kernels of the body-centric model, eq. (10), flown in closed or open loop.

theta = [I_xx, I_yy, I_zz, J_r, b, d] (kg m^2, kg m^2, kg m^2, kg m^2, N s^2, N m s^2);
vehicle = [l (m), m (kg), g (m/s^2), omega_min, omega_max (rad/s)].
The rigid body is advanced by the engine's integrator (`integrate_step`) with the body
accelerations a = [a_x, a_y, a_z] of eq. (24) (which equal V_dot + omega x V of eq. 10)
and the angular accelerations of eq. (10).
Closed loop: the known stabilising controller maps the references
[phi_r, theta_r, psi_r, Omega_T] (rad, rad, rad, rad/s) to motor speeds
Omega_i = Omega_T - sum_j K_ij e_j, e = [phi - phi_r, theta - theta_r, psi - psi_r, p, q, r],
clipped to [omega_min, omega_max]; it runs at every integration substep.
"""

import math

import numpy as np

from gpquad.engine.kernels.integrator import integrate_step
from gpquad.engine.kernels.quaternion import euler_from_quat
from gpquad.engine.numba_config import njit


@njit
def model_accelerations(theta, vehicle, phi, th, rates, omega, out):
    """Eq. (10)/(24): out (6,) = [a_x, a_y, a_z, p_dot, q_dot, r_dot]; omega (4,) rad/s."""
    ixx, iyy, izz, jr, b, d = theta[0], theta[1], theta[2], theta[3], theta[4], theta[5]
    ell, m, g = vehicle[0], vehicle[1], vehicle[2]
    w1, w2, w3, w4 = omega[0] ** 2, omega[1] ** 2, omega[2] ** 2, omega[3] ** 2
    u1 = w1 + w2 + w3 + w4
    u2 = w4 - w2
    u3 = w1 - w3
    u4 = w2 + w4 - w1 - w3
    om_r = omega[1] + omega[3] - omega[0] - omega[2]
    p, q, r = rates[0], rates[1], rates[2]
    out[0] = -g * math.sin(th)
    out[1] = g * math.cos(th) * math.sin(phi)
    out[2] = g * math.cos(th) * math.cos(phi) - b * u1 / m
    out[3] = (q * r * (iyy - izz) + jr * q * om_r + ell * b * u2) / ixx
    out[4] = (p * r * (izz - ixx) - jr * p * om_r + ell * b * u3) / iyy
    out[5] = (p * q * (ixx - iyy) + d * u4) / izz


@njit
def controller(gain, vehicle, ref, phi, th, psi, rates, omega):
    """Motor speeds omega (4,) rad/s from references ref (4,) and the state."""
    e = np.empty(6)
    e[0] = phi - ref[0]
    e[1] = th - ref[1]
    e[2] = math.atan2(math.sin(psi - ref[2]), math.cos(psi - ref[2]))
    e[3], e[4], e[5] = rates[0], rates[1], rates[2]
    for i in range(4):
        w = ref[3]
        for j in range(6):
            w -= gain[i, j] * e[j]
        omega[i] = min(max(w, vehicle[3]), vehicle[4])


@njit
def fly(theta, vehicle, gain, drive, closed, quat0, vel0, rates0, dt, substeps):
    """Fly N samples from an initial state.

    drive (N, 4): references (closed=True) or motor speeds held over each sample (False).
    Returns states (N, 9) [phi, theta, psi, u, v, w, p, q, r], acc (N, 3) [a_x, a_y, a_z]
    and motor speeds (N, 4), all at the sample instants. Non-finite states stop the
    flight and fill the rest with NaN.
    """
    n = drive.shape[0]
    states = np.full((n, 9), np.nan)
    acc = np.full((n, 3), np.nan)
    speeds = np.full((n, 4), np.nan)
    q = quat0.copy()
    v = vel0.copy()
    w = rates0.copy()
    pos = np.zeros(3)
    mat = np.empty((3, 3))
    a = np.empty(6)
    omega = np.empty(4)
    h = dt / substeps
    for k in range(n):
        for s in range(substeps):
            phi, th, psi = euler_from_quat(q[0], q[1], q[2], q[3])
            if closed:
                controller(gain, vehicle, drive[k], phi, th, psi, w, omega)
            else:
                for i in range(4):
                    omega[i] = drive[k, i]
            model_accelerations(theta, vehicle, phi, th, w, omega, a)
            if s == 0:
                states[k, 0], states[k, 1], states[k, 2] = phi, th, psi
                for i in range(3):
                    states[k, 3 + i] = v[i]
                    states[k, 6 + i] = w[i]
                    acc[k, i] = a[i]
                for i in range(4):
                    speeds[k, i] = omega[i]
            integrate_step(q, v, w, pos, a, h, mat)
        if not (
            np.isfinite(w[0])
            and np.isfinite(w[1])
            and np.isfinite(w[2])
            and abs(w[0]) + abs(w[1]) + abs(w[2]) < 1e3
        ):
            break
    return states, acc, speeds
