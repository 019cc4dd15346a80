"""Integrated-state fitness: fly a tree over data windows and measure the state error.

For a tree that models target k (0..5 = a_x .. r_dot), each window starts from
the data's state at `start`, integrates n_steps with the tree's acceleration
for k and the data's accelerations for the other five (paper section 3.2), and
scores |x_k(pred) - x_k(data)| (or its square) averaged over the steps.

Not in the paper: with att_weight > 0, an angular target's step error also counts the
Euler angle its rate integrates into (p -> phi, q -> theta, r -> psi):
|dx| + att_weight |d angle| (squared: dx^2 + (att_weight d angle)^2, the angle difference
wrapped to [-pi, pi]). A rate equation without the attitude feedback of a stiff loop leaks
a small bias into the rate that the rate error hardly sees but the angle integrates
(gpquad.engine.evolve.evaluator picks the weight from the data's scales).

Only the states that can influence the score are integrated, which is exact,
not an approximation:
- linear targets: rates and attitude are the data's (they are driven by data
  accelerations only), so the rotation R_{b_t}^{b_{t+1}} is read from
  FlightArrays.rot and Euler angles from the data;
- angular targets: the attitude is integrated only when the tree reads Euler
  angles or att_weight > 0, and the velocity only when it reads u, v or w.
`rollout` integrates everything and is the reference these paths are tested on. The
one-equation kernels' Euler angles (eq. 2 and RK4 alike) are gpquad.engine.kernels.arctrig's
atan2 and asin, vectorised over lanes: within 1 ulp of the rollout's (libm's), not always
its bits.

Not in the paper: an equation may have a first-order lag (gpquad.engine.lag): the
acceleration it applies follows the tree's value f as a_k = a_{k-1} + alpha (f_k - a_{k-1}),
from the data's acceleration of the step before the window (a motor that lags its command).
alpha = 1 is no lag and leaves every result bit-identical to the kernels without it.
"""

import numpy as np

from gpquad.engine.kernels.divergence import DIVERGED, STATE_LIMIT, read_leaves, uses_leaves
from gpquad.engine.kernels.fitness_rk4 import rk4_population_window_errors, rk4_tree_window_errors
from gpquad.engine.kernels.quaternion import euler_angle_lanes
from gpquad.engine.kernels.step import (
    RK4,
    euler_lanes_step,
    euler_rate_step,
    euler_velocity_step,
    wrap_angle,
)
from gpquad.engine.kernels.tree_eval import compile_program, run_program
from gpquad.engine.numba_config import njit, python_callable

__all__ = [
    "DIVERGED",
    "STATE_LIMIT",
    "wrap_angle",
    "tree_window_errors",
    "population_window_errors",
]


def tree_window_errors(
    codes,
    values,
    size,
    delays,
    target,
    flight,
    starts,
    n_steps,
    squared,
    att_weight,
    alpha,
    bound,
    out,
    scheme,
    substeps,
):
    """Mean per-step error of one tree on each window; fills out (n_windows,).

    alpha: the equation's lag factor in (0, 1] (module notes; 1 = no lag).
    scheme, substeps: the integrator (gpquad.engine.kernels.step: EULER, one step per
    sample, or RK4 with `substeps` steps per sample, gpquad.engine.kernels.fitness_rk4).
    The scheme is picked here, in Python, so that a process compiles only the kernels of
    the schemes it flies. (The population kernels call the same kernels from numba; this
    Python entry compiles their copies for Python, numba_config.python_callable.)

    bound: if the summed error of all windows exceeds bound * n_windows * n_steps the
    evaluation is abandoned (the tree cannot beat a parent of mean error `bound`)
    and every entry is set to inf. Pass np.inf to evaluate fully.
    A window whose state diverges (NaN or beyond STATE_LIMIT) scores inf and stops.
    Returns True when the evaluation stopped early.
    """
    if scheme == RK4:
        return python_callable(rk4_tree_window_errors)(
            codes,
            values,
            size,
            delays,
            target,
            flight,
            starts,
            n_steps,
            squared,
            att_weight,
            alpha,
            bound,
            out,
            substeps,
            np.empty(0),
        )
    return python_callable(euler_tree_window_errors)(
        codes,
        values,
        size,
        delays,
        target,
        flight,
        starts,
        n_steps,
        squared,
        att_weight,
        alpha,
        bound,
        out,
    )


@njit(inner=True)
def euler_tree_window_errors(
    codes,
    values,
    size,
    delays,
    target,
    flight,
    starts,
    n_steps,
    squared,
    att_weight,
    alpha,
    bound,
    out,
):
    """tree_window_errors flown by eq. 2, one step per sample (module notes)."""
    quat_d, states, acc, inputs, rot, dt = flight
    n = starts.shape[0]
    n_in = inputs.shape[1]
    linear = target < 3
    uses_euler = uses_leaves(codes, size, 0, 2)
    uses_vel = uses_leaves(codes, size, 3, 5)
    need_vel = linear or uses_vel
    att_err = (not linear) and att_weight > 0.0
    need_att = (not linear) and (uses_euler or att_err)
    budget = bound * n * n_steps
    body_step = (not linear) and (need_vel or need_att)  # an angular target's full eq. 2 step

    # the leaves, then one row per node (tree_eval.compile_program)
    features = np.zeros((9 + n_in + size, n))
    prog = np.empty((size, 4), dtype=np.int64)
    n_ops, root = compile_program(codes, values, size, 9 + n_in, features, prog)
    pred = np.empty(n)
    work = np.empty((3, n))
    quat = np.empty((4, n))
    vel = np.empty((3, n))
    rates = np.empty((3, n))
    err = np.zeros(n)
    inc = np.empty((5, n))
    alive = np.ones(n, dtype=np.bool_)
    n_alive = n
    lagged = alpha < 1.0
    applied = np.zeros(n)  # the lagged acceleration of each lane
    for lane in range(n):
        s = starts[lane]
        applied[lane] = acc[s - 1, target] if s > 0 else 0.0
        for i in range(4):
            quat[i, lane] = quat_d[s, i]
        for i in range(3):
            vel[i, lane] = states[s, 3 + i]
            rates[i, lane] = states[s, 6 + i]

    # Only the leaves the tree reads are filled.
    used = read_leaves(codes, size, 9 + n_in)
    data_cols = np.empty(6, dtype=np.int64)  # states read straight from the data
    n_data = 0
    if linear:
        for i in (0, 1, 2, 6, 7, 8):
            if used[i]:
                data_cols[n_data] = i
                n_data += 1
    rate_cols = np.empty(3, dtype=np.int64)  # integrated rates (angular targets)
    n_rate = 0
    if not linear:
        for i in range(3):
            if used[6 + i]:
                rate_cols[n_rate] = i
                n_rate += 1
    input_cols = np.empty(n_in, dtype=np.int64)
    n_used_in = 0
    for j in range(n_in):
        if used[9 + j]:
            input_cols[n_used_in] = j
            n_used_in += 1

    for k in range(n_steps):
        # the leaves column by column (loops without branches; a dead lane's are not read)
        for c in range(n_data):
            col = data_cols[c]
            for lane in range(n):
                features[col, lane] = states[starts[lane] + k, col]
        if need_att:  # every lane's (vectorised; a dead lane's are not read)
            for a in range(3):
                if used[a]:
                    euler_angle_lanes(a, quat, 0, features[a], n, work[0], work[1])
        for c in range(n_rate):
            col = rate_cols[c]
            for lane in range(n):
                features[6 + col, lane] = rates[col, lane]
        if uses_vel:
            for i in range(3):
                for lane in range(n):
                    features[3 + i, lane] = vel[i, lane]
        for c in range(n_used_in):
            j = input_cols[c]
            shift = k - delays[j]
            for lane in range(n):
                features[9 + j, lane] = inputs[starts[lane] + shift, j]
        run_program(prog, n_ops, features, n)
        for lane in range(n):
            pred[lane] = features[root, lane]
        if lagged:
            for lane in range(n):
                applied[lane] += alpha * (pred[lane] - applied[lane])
                pred[lane] = applied[lane]

        # the state of every lane at once (loops that vectorise; a dead lane's is not read)
        if body_step:
            euler_lanes_step(
                quat,
                vel,
                rates,
                acc,
                starts,
                k,
                target - 3,
                pred,
                alive,
                dt,
                need_vel,
                need_att,
                inc,
            )
        elif linear:
            for lane in range(n):
                idx = starts[lane] + k
                a0 = pred[lane] if target == 0 else acc[idx, 0]
                a1 = pred[lane] if target == 1 else acc[idx, 1]
                a2 = pred[lane] if target == 2 else acc[idx, 2]
                vel[0, lane], vel[1, lane], vel[2, lane] = euler_velocity_step(
                    rot, idx, vel[0, lane], vel[1, lane], vel[2, lane], a0, a1, a2, dt
                )
        else:  # nothing reads the attitude or the velocity: eq. 2's rate steps alone
            for i in range(3):
                if i == target - 3:
                    for lane in range(n):
                        rates[i, lane] = euler_rate_step(rates[i, lane], pred[lane], dt)
                else:
                    for lane in range(n):
                        rates[i, lane] = euler_rate_step(
                            rates[i, lane], acc[starts[lane] + k, 3 + i], dt
                        )
        if att_err:  # the integrated Euler angle of the target's rate
            euler_angle_lanes(target - 3, quat, 0, work[2], n, work[0], work[1])
        total = 0.0
        for lane in range(n):
            if not alive[lane]:
                total += err[lane]
                continue
            idx = starts[lane] + k
            x = vel[target, lane] if linear else rates[target - 3, lane]
            e = x - states[idx + 1, 3 + target]
            if squared:
                e = e * e
            else:
                e = abs(e)
            if att_err:
                da = wrap_angle(work[2, lane] - states[idx + 1, target - 3]) * att_weight
                e += da * da if squared else abs(da)
            if not abs(x) < STATE_LIMIT:  # also catches NaN
                e = DIVERGED
                alive[lane] = False
                n_alive -= 1
            err[lane] += e
            total += err[lane]
        if total > budget or n_alive == 0:
            for lane in range(n):
                out[lane] = DIVERGED
            return True
    for lane in range(n):
        out[lane] = err[lane] / n_steps
    return False


def population_window_errors(
    codes,
    values,
    sizes,
    delays,
    target,
    flight,
    starts,
    n_steps,
    squared,
    att_weight,
    alpha,
    bounds,
    out,
    scheme,
    substeps,
    res=None,
):
    """tree_window_errors for each tree i of a population (codes (P, M) ...); out (P, n_windows).
    res (RK4 and a one-tree population only, bound inf): receives the sensitivity kernel's
    residuals of the windows, to the bit (gpquad.engine.kernels.fitness_rk4)."""
    if res is not None and (scheme != RK4 or codes.shape[0] != 1):
        raise ValueError("residuals are written for one tree flown by RK4 only")
    if scheme == RK4:
        rk4_population_window_errors(
            codes,
            values,
            sizes,
            delays,
            target,
            flight,
            starts,
            n_steps,
            squared,
            att_weight,
            alpha,
            bounds,
            out,
            substeps,
            np.empty(0) if res is None else res,
        )
    else:
        euler_population_window_errors(
            codes,
            values,
            sizes,
            delays,
            target,
            flight,
            starts,
            n_steps,
            squared,
            att_weight,
            alpha,
            bounds,
            out,
        )


@njit
def euler_population_window_errors(
    codes,
    values,
    sizes,
    delays,
    target,
    flight,
    starts,
    n_steps,
    squared,
    att_weight,
    alpha,
    bounds,
    out,
):
    """population_window_errors flown by eq. 2."""
    for i in range(codes.shape[0]):
        euler_tree_window_errors(
            codes[i],
            values[i],
            sizes[i],
            delays[i],
            target,
            flight,
            starts,
            n_steps,
            squared,
            att_weight,
            alpha,
            bounds[i],
            out[i],
        )
