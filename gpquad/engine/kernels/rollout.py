"""The full-model rollout: every state integrated from each window start, all six
accelerations from the equations (or the data's), by the configured scheme
(gpquad.engine.kernels.step). Used by DiscoveredModel.simulate and fly."""

import numpy as np

from gpquad.engine.kernels.fitness_rk4 import rk4_rollout
from gpquad.engine.kernels.quaternion import euler_from_quat
from gpquad.engine.kernels.step import RK4, euler_step
from gpquad.engine.kernels.tree_eval import hold_inputs, model_programs, run_model_tree
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
    """rollout flown by eq. 2, every window at once: each tree a register program over the
    windows (tree_eval.model_programs), each window's arithmetic that of it flown alone."""
    quat_d, states, acc, inputs, rot, dt = flight
    n = starts.shape[0]
    regs, prog, n_ops, root, used = model_programs(
        codes, values, sizes, modelled, 9 + delays.shape[1], n
    )
    out = np.empty((n, n_steps + 1, 9))
    features = np.empty((9, n))
    a = np.empty((6, n))
    applied = np.empty((6, n))  # the lagged accelerations
    quat = np.empty((4, n))
    vel = np.empty((3, n))
    rates = np.empty((3, n))
    for lane in range(n):
        s = starts[lane]
        for t in range(6):
            applied[t, lane] = acc[s - 1, t] if s > 0 else 0.0
        for i in range(4):
            quat[i, lane] = quat_d[s, i]
        for i in range(3):
            vel[i, lane] = states[s, 3 + i]
            rates[i, lane] = states[s, 6 + i]
    for k in range(n_steps + 1):
        for lane in range(n):
            phi, theta, psi = euler_from_quat(
                quat[0, lane], quat[1, lane], quat[2, lane], quat[3, lane]
            )
            out[lane, k, 0], out[lane, k, 1], out[lane, k, 2] = phi, theta, psi
            for i in range(3):
                out[lane, k, 3 + i] = vel[i, lane]
                out[lane, k, 6 + i] = rates[i, lane]
            for i in range(9):
                features[i, lane] = out[lane, k, i]
        if k == n_steps:
            break
        hold_inputs(regs, used, modelled, delays, inputs, input_noise, starts, k, 9)
        for t in range(6):
            if modelled[t]:
                run_model_tree(regs, prog, n_ops, used, t, features, n)
            for lane in range(n):
                if not modelled[t]:
                    a[t, lane] = acc[starts[lane] + k, t]
                elif alphas[t] < 1.0:
                    applied[t, lane] += alphas[t] * (regs[t, root[t], lane] - applied[t, lane])
                    a[t, lane] = applied[t, lane]
                else:
                    a[t, lane] = regs[t, root[t], lane]
        for lane in range(n):
            (
                quat[0, lane],
                quat[1, lane],
                quat[2, lane],
                quat[3, lane],
                vel[0, lane],
                vel[1, lane],
                vel[2, lane],
                rates[0, lane],
                rates[1, lane],
                rates[2, lane],
            ) = euler_step(
                quat[0, lane],
                quat[1, lane],
                quat[2, lane],
                quat[3, lane],
                vel[0, lane],
                vel[1, lane],
                vel[2, lane],
                rates[0, lane],
                rates[1, lane],
                rates[2, lane],
                a[0, lane],
                a[1, lane],
                a[2, lane],
                a[3, lane],
                a[4, lane],
                a[5, lane],
                dt,
                True,
                True,
            )
    return out
