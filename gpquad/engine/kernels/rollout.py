"""The full-model rollout: every state integrated from each window start, all six
accelerations from the equations (or the data's), by the configured scheme
(gpquad.engine.kernels.step). Used by DiscoveredModel.simulate and fly."""

import numpy as np

from gpquad.engine.kernels.fitness_rk4 import rk4_rollout
from gpquad.engine.kernels.quaternion import euler_from_quat
from gpquad.engine.kernels.step import RK4, euler_step
from gpquad.engine.kernels.tree_eval import STACK_ROWS, eval_lanes
from gpquad.engine.numba_config import njit


def rollout(
    codes,
    values,
    sizes,
    delays,
    modelled,
    alphas,
    flight,
    starts,
    n_steps,
    input_noise,
    scheme,
    substeps,
    pos=None,
):
    """Fly a full model: integrate every state from each window start, all six accelerations.

    codes (6, M), values (6, M), sizes (6,), delays (6, K n_inputs): one tree per target,
    K taps per input (gpquad.engine.taps; leaf slot j reads input j % n_inputs);
    modelled (6,) bool: use the tree for this target, else the data's acceleration;
    alphas (6,): each equation's lag factor (module notes; 1 = no lag).
    input_noise: (n_windows, n_steps, n_inputs) added to the recorded inputs, or shape (0, 0, 0).
    scheme, substeps: the integrator (gpquad.engine.kernels.step), picked here in Python so
    that a process compiles only the kernels of the schemes it flies.
    pos: None, or (n_windows, n_steps + 1, 3) that an RK4 rollout fills with the world position
    from each window start (x = 0), flown as part of the RK4 state. Eq. 2 has none to give:
    its position step x' = x + R(q) V dt reads only the flown states (DiscoveredModel.fly).
    Returns states (n_windows, n_steps + 1, 9) [phi, theta, psi, u, v, w, p, q, r].
    """
    if scheme == RK4:
        return rk4_rollout(
            codes,
            values,
            sizes,
            delays,
            modelled,
            alphas,
            flight,
            starts,
            n_steps,
            input_noise,
            substeps,
            np.empty((0, 0, 3)) if pos is None else pos,
        )
    if pos is not None:
        raise ValueError("eq. 2's position is x' = x + R(q) V dt of the flown states")
    return euler_rollout(
        codes,
        values,
        sizes,
        delays,
        modelled,
        alphas,
        flight,
        starts,
        n_steps,
        input_noise,
    )


@njit
def euler_rollout(
    codes,
    values,
    sizes,
    delays,
    modelled,
    alphas,
    flight,
    starts,
    n_steps,
    input_noise,
):
    """rollout flown by eq. 2."""
    quat_d, states, acc, inputs, rot, dt = flight
    n = starts.shape[0]
    n_in = inputs.shape[1]
    n_slots = delays.shape[1]
    noisy = input_noise.shape[0] > 0
    out = np.empty((n, n_steps + 1, 9))
    features = np.empty((9 + n_slots, 1))
    stack = np.empty((STACK_ROWS, 1))
    pred = np.empty(1)
    a = np.empty(6)
    applied = np.empty(6)  # the lagged accelerations
    for lane in range(n):
        s = starts[lane]
        for t in range(6):
            applied[t] = acc[s - 1, t] if s > 0 else 0.0
        q0, q1, q2, q3 = quat_d[s, 0], quat_d[s, 1], quat_d[s, 2], quat_d[s, 3]
        vel = states[s, 3:6].copy()
        rates = states[s, 6:9].copy()
        for k in range(n_steps + 1):
            idx = s + k
            phi, theta, psi = euler_from_quat(q0, q1, q2, q3)
            out[lane, k, 0], out[lane, k, 1], out[lane, k, 2] = phi, theta, psi
            for i in range(3):
                out[lane, k, 3 + i] = vel[i]
                out[lane, k, 6 + i] = rates[i]
            if k == n_steps:
                break
            for i in range(9):
                features[i, 0] = out[lane, k, i]
            for t in range(6):
                a[t] = acc[idx, t]
                if modelled[t]:
                    for j in range(n_slots):
                        c = j % n_in
                        u = inputs[idx - delays[t, j], c]
                        if noisy and k - delays[t, j] >= 0:
                            u += input_noise[lane, k - delays[t, j], c]
                        features[9 + j, 0] = u
                    eval_lanes(codes[t], values[t], sizes[t], features, stack, pred, 1)
                    a[t] = pred[0]
                    if alphas[t] < 1.0:
                        applied[t] += alphas[t] * (pred[0] - applied[t])
                        a[t] = applied[t]
            (q0, q1, q2, q3, vel[0], vel[1], vel[2], rates[0], rates[1], rates[2]) = euler_step(
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
                a[0],
                a[1],
                a[2],
                a[3],
                a[4],
                a[5],
                dt,
                True,
                True,
            )
    return out
