"""The fitness and rollout kernels of gpquad.engine.kernels.fitness flown by RK4.

The same windows, errors, bound and divergence rules as the eq. 2 kernels; the state is
advanced by classical RK4 on the continuous-time rigid body with `substeps` steps per sample
(gpquad.engine.kernels.step) and the tree is evaluated at every stage's state.

Held over each sample: the inputs (delays are whole samples), and for the targets that a
tree does not model the data's accelerations of that sample. The data's accelerations are
eq. 2's discrete inverse (gpquad.engine.kernels.integrator.body_accelerations): held, they
reproduce the data's rates at every sample exactly (alpha is constant over the sample and
RK4 integrates a linear rate exactly), and the data's velocity and attitude to O(dt^2) per
sample (eq. 2 rotates V + a dt by the sample's increment, the ODE rotates V as it goes).
For a linear target the attitude and rates start every sample from the data's (they do not
depend on the tree; integrated over a window from noisy data rates the attitude would random
walk), as the eq. 2 kernels read the data's; within the sample they are integrated. For an
angular target every state a tree reads is the integrated one.

The Euler angles a tree reads at the stage states, and the scored angle, are
quaternion.euler_angle_lanes' (vectorised, within 1 ulp of libm's) in the fitness and the
sensitivity flights alike, so that their residuals agree to the bit; the full-model rollouts
keep libm's.

A lag (alpha < 1) is one more state, tau a_dot = f - a from the data's acceleration of the
sample before the window, with 1 / tau from alpha (gpquad.engine.kernels.step.lag_rate).
"""

import numpy as np

from gpquad.engine.kernels.divergence import (
    DIVERGED,
    STATE_LIMIT,
    diverged_rows,
    read_leaves,
    uses_leaves,
)
from gpquad.engine.kernels.quaternion import (
    euler_angle_lanes,
    euler_phi,
    euler_psi,
    euler_theta,
)
from gpquad.engine.kernels.step import (
    BODY_ROWS,
    N_STAGES,
    NODES,
    PLANT_ROWS,
    WEIGHTS,
    Q,
    V,
    W,
    X,
    attitude_derivative,
    body_derivative,
    lag_rate_kernel,
    velocity_derivative,
    wrap_angle,
)
from gpquad.engine.kernels.step_lanes import lanes_accumulate, lanes_finish_step, lanes_stage_state
from gpquad.engine.kernels.tree_eval import (
    compile_program,
    hold_inputs,
    model_programs,
    run_model_tree,
    run_program,
)
from gpquad.engine.kernels.tree_tangent import residual_rows
from gpquad.engine.numba_config import njit

#: Row of the lag state after the body's rows.
LAG = BODY_ROWS


@njit(inline="always")
def stage_features(ys, lane, used, features):
    """The state leaves the tree reads (used (9 + n_in,) bool) at stage state ys[:, lane]."""
    q0, q1, q2, q3 = ys[Q, lane], ys[Q + 1, lane], ys[Q + 2, lane], ys[Q + 3, lane]
    if used[0]:
        features[0, lane] = euler_phi(q0, q1, q2, q3)
    if used[1]:
        features[1, lane] = euler_theta(q0, q1, q2, q3)
    if used[2]:
        features[2, lane] = euler_psi(q0, q1, q2, q3)
    for i in range(3):
        if used[3 + i]:
            features[3 + i, lane] = ys[V + i, lane]
        if used[6 + i]:
            features[6 + i, lane] = ys[W + i, lane]


@njit(inline="always")
def stage_features_lanes(ys, used, features, n, work):
    """stage_features of lanes [0, n), the angles by euler_angle_lanes (vectorised, within
    1 ulp of libm's; the single-equation RK4 flights, fitness and sensitivity alike, read
    these bits). work (2, n) is scratch."""
    for a in range(3):
        if used[a]:
            euler_angle_lanes(a, ys, Q, features[a], n, work[0], work[1])
    for i in range(3):
        if used[3 + i]:
            for lane in range(n):
                features[3 + i, lane] = ys[V + i, lane]
        if used[6 + i]:
            for lane in range(n):
                features[6 + i, lane] = ys[W + i, lane]


@njit(inner=True)
def flown_rows(codes, size, linear, angle_read, n_rows):
    """The rows a flight steps, ascending (the others keep the window's start): the
    attitude where an angle is read (by the tree, or angle_read: the angle is scored or its
    tangents followed), the velocity for a linear target or a tree that reads it, the rates
    always, and the rows after the body's (a lag) up to n_rows."""
    attitude = uses_leaves(codes, size, 0, 2) or angle_read
    velocity = linear or uses_leaves(codes, size, 3, 5)
    rows = np.empty(n_rows, dtype=np.int64)
    n = 0
    for i in range(n_rows):
        if (i < V and not attitude) or (V <= i < W and not velocity):
            continue
        rows[n] = i
        n += 1
    return rows[:n]


@njit(inline="always")
def body_from_data(y, lane, quat_d, states, idx):
    """y's attitude, velocity and rate rows of `lane` set to the data's at sample idx: a
    window's start."""
    for i in range(4):
        y[Q + i, lane] = quat_d[idx, i]
    for i in range(3):
        y[V + i, lane] = states[idx, 3 + i]
        y[W + i, lane] = states[idx, 6 + i]


@njit(inline="always")
def attitude_and_rates_from_data(y, lane, quat_d, states, idx):
    """y's attitude and rate rows of `lane` set to the data's at sample idx: a linear
    target's tree does not drive them, and integrating them over a window from noisy data
    rates would let the attitude random-walk away (the eq. 2 kernels read them likewise)."""
    for i in range(4):
        y[Q + i, lane] = quat_d[idx, i]
    for i in range(3):
        y[W + i, lane] = states[idx, 6 + i]


@njit(inner=True)
def lanes_body_slope(ys, slope, pred, acc, starts, first, k, target, lagged, rate, n, rows):
    """The slopes of the flown `rows` (flown_rows) and the lag's, lanes 0..n-1, at a stage:
    the tree's acceleration (or the lag's state) for the target, the data's for the other
    five, held over the sample (step.body_derivative's arithmetic, row by row over the
    lanes). A row not flown is not written."""
    attitude = rows[0] == Q
    velocity = False
    for r in range(rows.shape[0]):
        velocity = velocity or rows[r] == V
    if attitude:
        for lane in range(n):
            attitude_derivative(ys, lane, slope)
    if velocity:
        for lane in range(n):
            idx = starts[first + lane] + k
            own = ys[LAG, lane] if lagged else pred[lane]
            a0 = own if target == 0 else acc[idx, 0]
            a1 = own if target == 1 else acc[idx, 1]
            a2 = own if target == 2 else acc[idx, 2]
            velocity_derivative(ys, lane, a0, a1, a2, slope)
    for i in range(3):
        if target == 3 + i:
            for lane in range(n):
                slope[W + i, lane] = ys[LAG, lane] if lagged else pred[lane]
        else:
            for lane in range(n):
                slope[W + i, lane] = acc[starts[first + lane] + k, 3 + i]
    for lane in range(n):
        slope[LAG, lane] = rate * (pred[lane] - ys[LAG, lane]) if lagged else 0.0


@njit(inner=True)
def rk4_tree_window_errors(
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
    res,
):
    """gpquad.engine.kernels.fitness.tree_window_errors flown by RK4 (module notes). res:
    empty, or (n_windows * n_steps * rows,) to receive the residuals of
    gpquad.engine.kernels.sensitivity_rk4 (rows = residual_rows(target, att_weight), the
    same bits, diverged windows likewise) when bound is inf."""
    quat_d, states, acc, inputs, rot, dt = flight
    n = starts.shape[0]
    n_in = inputs.shape[1]
    linear = target < 3
    att_err = (not linear) and att_weight > 0.0
    budget = bound * n * n_steps
    lagged = alpha < 1.0
    rate = lag_rate_kernel(alpha, dt)
    n_rows = BODY_ROWS + 1
    h = dt / substeps

    # the leaves, then one row per node: the tree as a register program over the lanes
    # (tree_eval.compile_program: eval_lanes' operations, the same bits)
    regs = np.zeros((9 + n_in + size, n))
    prog = np.empty((size, 4), dtype=np.int64)
    n_ops, root = compile_program(codes, values, size, 9 + n_in, regs, prog)
    features = regs[: 9 + n_in]
    pred = regs[root]
    angle_work, angles = np.empty((2, n)), np.empty(n)
    # the windows' first lane (an int64 as the sensitivity kernel's, not the literal 0:
    # one compiled lanes_body_slope for both)
    first = np.int64(0)
    y = np.empty((n_rows, n))
    ys = np.empty((n_rows, n))
    slope = np.zeros((n_rows, n))
    total = np.empty((n_rows, n))
    err = np.zeros(n)
    alive = np.ones(n, dtype=np.bool_)
    write = res.shape[0] > 0
    n_res = residual_rows(target, att_weight)  # the sensitivity kernel's rows
    n_alive = n
    for lane in range(n):
        s = starts[lane]
        y[LAG, lane] = acc[s - 1, target] if s > 0 else 0.0
        body_from_data(y, lane, quat_d, states, s)
    used = read_leaves(codes, size, 9 + n_in)
    uses_state = uses_leaves(codes, size, 0, 8)
    rows = flown_rows(codes, size, linear, att_err, n_rows)
    for i in range(n_rows):  # element by element: a broadcast copy compiles shape checks
        for lane in range(n):
            ys[i, lane] = y[i, lane]

    for k in range(n_steps):
        for lane in range(n):  # inputs held over the sample
            idx = starts[lane] + k
            if linear and k > 0:
                attitude_and_rates_from_data(y, lane, quat_d, states, idx)
            for j in range(n_in):
                if used[9 + j]:
                    features[9 + j, lane] = inputs[idx - delays[j], j]
        for _ in range(substeps):
            for stage in range(N_STAGES):
                lanes_stage_state(y, slope, NODES[stage], h, ys, n, rows)
                if uses_state:  # every lane's (vectorised; a dead lane's are not read)
                    stage_features_lanes(ys, used, features, n, angle_work)
                run_program(prog, n_ops, regs, n)
                # a dead lane's slopes too, to no purpose (its error is no longer read)
                lanes_body_slope(
                    ys, slope, pred, acc, starts, first, k, target, lagged, rate, n, rows
                )
                lanes_accumulate(total, slope, WEIGHTS[stage], stage, n, rows)
            lanes_finish_step(y, total, h, n, rows)

        if att_err:  # the integrated Euler angle of the target's rate, every lane's
            euler_angle_lanes(target - 3, y, Q, angles, n, angle_work[0], angle_work[1])
        step_total = 0.0
        for lane in range(n):
            row = (lane * n_steps + k) * n_res
            if not alive[lane]:
                step_total += err[lane]
                if write:
                    diverged_rows(res, row, n_res)
                continue
            idx = starts[lane] + k
            x = y[V + target, lane] if linear else y[W + target - 3, lane]
            e = x - states[idx + 1, 3 + target]
            if write:
                res[row] = e
            e = e * e if squared else abs(e)
            if att_err:
                a = target - 3
                da = wrap_angle(angles[lane] - states[idx + 1, a]) * att_weight
                if write:
                    res[row + 1] = da
                e += da * da if squared else abs(da)
            if not abs(x) < STATE_LIMIT:  # also catches NaN
                e = DIVERGED
                alive[lane] = False
                n_alive -= 1
                if write:
                    diverged_rows(res, row, n_res)
            err[lane] += e
            step_total += err[lane]
        if step_total > budget or n_alive == 0:
            for lane in range(n):
                out[lane] = DIVERGED
                if write:  # every later step of every window, as the sensitivity kernel's
                    for later in range(k + 1, n_steps):
                        diverged_rows(res, (lane * n_steps + later) * n_res, n_res)
            return True
    for lane in range(n):
        out[lane] = err[lane] / n_steps
    return False


@njit
def rk4_population_window_errors(
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
    res,
):
    """population_window_errors flown by RK4 (gpquad.engine.kernels.fitness_rk4); res:
    empty, or a one-tree population's residuals (rk4_tree_window_errors: LM's trial points,
    through the one compiled entry point of the fitness kernel)."""
    for i in range(codes.shape[0]):
        rk4_tree_window_errors(
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
            substeps,
            res,
        )


@njit
def rk4_rollout(
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
    pos,
):
    """gpquad.engine.kernels.rollout.rollout flown by RK4 (module notes): states
    (n_windows, n_steps + 1, 9); every lagged equation carries its own lag state.

    The windows are the lanes of each tree's evaluation (a tree_eval.compile_program
    register program, as in the eq. 2 fitness kernel): each lane's arithmetic is that of a
    window flown alone.

    The world position x_dot = R(q) V is one more part of the RK4 state (rows X, from x = 0
    at each window start); pos (n_windows, n_steps + 1, 3) receives it, or has no rows
    (it is then not flown).
    """
    quat_d, states, acc, inputs, rot, dt = flight
    n = starts.shape[0]
    n_slots = delays.shape[1]
    keep_pos = pos.shape[0] > 0
    lag = PLANT_ROWS  # each target's lag state: row lag + t
    n_rows = PLANT_ROWS + 6
    h = dt / substeps
    out = np.empty((n, n_steps + 1, 9))
    features = np.empty((9, n))
    # each tree's leaves (the states, then its input slots), then one row per node
    # (tree_eval.compile_program); the inputs are held over a sample, written once
    regs, prog, n_ops, root, used = model_programs(codes, values, sizes, modelled, 9 + n_slots, n)
    a = np.empty((6, n))
    rates = np.empty(6)
    for t in range(6):
        rates[t] = lag_rate_kernel(alphas[t], dt)
    y = np.empty((n_rows, n))
    ys = np.empty((n_rows, n))
    slope = np.zeros((n_rows, n))
    total = np.empty((n_rows, n))
    every_state = np.ones(9, dtype=np.bool_)
    rows = np.arange(n_rows)  # every row flies
    for lane in range(n):
        s = starts[lane]
        for t in range(6):
            y[lag + t, lane] = acc[s - 1, t] if s > 0 else 0.0
        body_from_data(y, lane, quat_d, states, s)
        for i in range(3):
            y[X + i, lane] = 0.0
    for k in range(n_steps + 1):
        for lane in range(n):
            stage_features(y, lane, every_state, features)
            for i in range(9):
                out[lane, k, i] = features[i, lane]
            if keep_pos:
                for i in range(3):
                    pos[lane, k, i] = y[X + i, lane]
        if k == n_steps:
            break
        hold_inputs(regs, used, modelled, delays, inputs, input_noise, starts, k, 9)
        for _ in range(substeps):
            for stage in range(N_STAGES):
                lanes_stage_state(y, slope, NODES[stage], h, ys, n, rows)
                for lane in range(n):
                    stage_features(ys, lane, every_state, features)
                for t in range(6):
                    if modelled[t]:
                        run_model_tree(regs, prog, n_ops, used, t, features, n)
                    for lane in range(n):
                        slope[lag + t, lane] = 0.0
                        if not modelled[t]:
                            a[t, lane] = acc[starts[lane] + k, t]
                        elif alphas[t] < 1.0:
                            a[t, lane] = ys[lag + t, lane]
                            slope[lag + t, lane] = rates[t] * (regs[t, root[t], lane] - a[t, lane])
                        else:
                            a[t, lane] = regs[t, root[t], lane]
                for lane in range(n):
                    body_derivative(
                        ys,
                        lane,
                        a[0, lane],
                        a[1, lane],
                        a[2, lane],
                        a[3, lane],
                        a[4, lane],
                        a[5, lane],
                        keep_pos,
                        slope,
                    )
                lanes_accumulate(total, slope, WEIGHTS[stage], stage, n, rows)
            lanes_finish_step(y, total, h, n, rows)
    return out
