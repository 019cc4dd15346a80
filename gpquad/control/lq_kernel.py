"""Numba kernel: the LQ tracker flying the non-linear body-centric model, eq. (10)/(24).

Every dt: x = [phi, theta, psi, p, q, r] from the state, u = Omega_h + (-K x + F y_r(n+1))
clipped to [omega_min, omega_max] (vehicle[3:5]), accelerations from
gpquad.baselines.body_kernels.model_accelerations, one step of the engine's integrator.
"""

import numpy as np

from gpquad.baselines.body_kernels import model_accelerations
from gpquad.engine.kernels.integrator import integrate_step
from gpquad.engine.kernels.quaternion import euler_from_quat
from gpquad.engine.numba_config import njit


@njit
def fly_tracker(theta, vehicle, K, F, omega_h, refs, dt):
    """refs (N + 1, 4) = [psi_r, a_xr, a_yr, a_zr]; returns x (N, 6), y (N, 4) outputs
    [psi, a_x, a_y, a_z] and motor speeds (N, 4), at steps 0..N-1 (NaN after divergence)."""
    n = refs.shape[0] - 1
    xs = np.full((n, 6), np.nan)
    ys = np.full((n, 4), np.nan)
    speeds = np.full((n, 4), np.nan)
    quat = np.array([1.0, 0.0, 0.0, 0.0])
    vel = np.zeros(3)
    rates = np.zeros(3)
    pos = np.zeros(3)
    mat = np.empty((3, 3))
    acc = np.empty(6)
    x = np.empty(6)
    omega = np.empty(4)
    for k in range(n):
        phi, th, psi = euler_from_quat(quat[0], quat[1], quat[2], quat[3])
        x[0], x[1], x[2], x[3], x[4], x[5] = phi, th, psi, rates[0], rates[1], rates[2]
        if not (np.isfinite(x).all() and np.abs(x).max() < 1e3):
            break
        for i in range(4):
            w = omega_h
            for j in range(6):
                w -= K[i, j] * x[j]
            for j in range(4):
                w += F[i, j] * refs[k + 1, j]
            omega[i] = min(max(w, vehicle[3]), vehicle[4])
        model_accelerations(theta, vehicle, phi, th, rates, omega, acc)
        for i in range(6):
            xs[k, i] = x[i]
        ys[k, 0], ys[k, 1], ys[k, 2], ys[k, 3] = psi, acc[0], acc[1], acc[2]
        for i in range(4):
            speeds[k, i] = omega[i]
        integrate_step(quat, vel, rates, pos, acc, dt, mat)
    return xs, ys, speeds
