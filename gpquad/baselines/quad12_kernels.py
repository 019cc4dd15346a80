"""Numba kernels of the 12-state model (ga-gradient paper): closed-loop simulation and replay.

State X = [x, x_dot, y, y_dot, z, z_dot, phi, phi_dot, theta, theta_dot, psi, psi_dot]
(m, m/s, rad, rad/s; world frame, Euler angles), decoupled inputs u = [u_1 .. u_4] (V),
theta = [a_1 .. a_11, b_1, b_2, b_3]. RK4 with the input held over each sample.
"""

import numpy as np

from gpquad.engine.numba_config import njit


@njit(inner=True)
def quad12_rhs(th, x, u, out):
    """dX/dt of the paper's state-space model into out (12,)."""
    out[0] = x[1]
    out[1] = th[0] * x[1] + th[1] * u[1] + th[11] * u[0]
    out[2] = x[3]
    out[3] = th[2] * x[3] + th[3] * u[2] + th[12] * u[0]
    out[4] = x[5]
    out[5] = th[4] * x[5] + th[13] * u[0]
    out[6] = x[7]
    out[7] = th[5] * x[7] * x[9] + th[6] * u[1]
    out[8] = x[9]
    out[9] = th[7] * x[7] * x[11] + th[8] * u[2]
    out[10] = x[11]
    out[11] = th[9] * x[7] * x[9] + th[10] * u[3]


@njit(inner=True)
def _rk4(th, x, u, h, k1, k2, k3, k4, tmp):
    quad12_rhs(th, x, u, k1)
    for i in range(12):
        tmp[i] = x[i] + 0.5 * h * k1[i]
    quad12_rhs(th, tmp, u, k2)
    for i in range(12):
        tmp[i] = x[i] + 0.5 * h * k2[i]
    quad12_rhs(th, tmp, u, k3)
    for i in range(12):
        tmp[i] = x[i] + h * k3[i]
    quad12_rhs(th, tmp, u, k4)
    for i in range(12):
        x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])


@njit
def simulate_closed_loop(th, x0, excitation, gains, dt, substeps):
    """Fly the model with a PD pilot on attitude and vertical speed plus excitation.

    excitation (N, 4) V added to the pilot's decoupled inputs; gains (8,) =
    [k_zdot, k_phi, k_phidot, k_theta, k_thetadot, k_psi, k_psidot, unused].
    Returns X (N, 12) and u (N, 4) (u[k] is held from sample k to k+1).
    """
    n = excitation.shape[0]
    X = np.empty((n, 12))
    U = np.empty((n, 4))
    x = x0.copy()
    u = np.empty(4)
    k1, k2, k3, k4, tmp = (np.empty(12), np.empty(12), np.empty(12), np.empty(12), np.empty(12))
    h = dt / substeps
    for k in range(n):
        X[k] = x
        u[0] = gains[0] * x[5] + excitation[k, 0]
        u[1] = -gains[1] * x[6] - gains[2] * x[7] + excitation[k, 1]
        u[2] = -gains[3] * x[8] - gains[4] * x[9] + excitation[k, 2]
        u[3] = -gains[5] * x[10] - gains[6] * x[11] + excitation[k, 3]
        U[k] = u
        for _ in range(substeps):
            _rk4(th, x, u, h, k1, k2, k3, k4, tmp)
    return X, U


@njit
def replay(th, x0, u, dt, substeps):
    """Integrate from each start x0 (W, 12) with recorded inputs u (W, n, 4): (W, n + 1, 12)."""
    w, n = u.shape[0], u.shape[1]
    out = np.empty((w, n + 1, 12))
    k1, k2, k3, k4, tmp = (np.empty(12), np.empty(12), np.empty(12), np.empty(12), np.empty(12))
    h = dt / substeps
    for lane in range(w):
        x = x0[lane].copy()
        out[lane, 0] = x
        for k in range(n):
            for _ in range(substeps):
                _rk4(th, x, u[lane, k], h, k1, k2, k3, k4, tmp)
            out[lane, k + 1] = x
    return out
