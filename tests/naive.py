"""Slow, obviously correct references for every kernel (STUMPY's tests/naive.py habit).

Written independently of gpquad.engine.kernels: rotations come from scipy, trees are
evaluated recursively, and every window integrates the whole state.
"""

import numpy as np
from scipy.spatial.transform import Rotation

from gpquad.engine.tree.operators import CONST, DIV_EPS, VAR_BASE


def rotation(quat_wxyz) -> Rotation:
    w, x, y, z = quat_wxyz
    return Rotation.from_quat([x, y, z, w])


def quat_wxyz(rot: Rotation) -> np.ndarray:
    x, y, z, w = rot.as_quat()
    q = np.array([w, x, y, z])
    return q if w >= 0 else -q


def euler(quat) -> np.ndarray:
    """(phi, theta, psi) ZYX of a body-to-world quaternion."""
    yaw, pitch, roll = rotation(quat).as_euler("ZYX")
    return np.array([roll, pitch, yaw])


def step(quat, vel, rates, pos, acc, dt):
    """One step of the paper's eq. (2) with scipy rotations."""
    att = rotation(quat)
    increment = Rotation.from_rotvec(np.asarray(rates) * dt)
    new_pos = pos + att.apply(vel) * dt
    new_vel = increment.inv().apply(vel + acc[:3] * dt)
    new_rates = rates + acc[3:] * dt
    return quat_wxyz(att * increment), new_vel, new_rates, new_pos


def integrate(quat0, vel0, rates0, pos0, acc, dt):
    quat, vel = [np.array(quat0)], [np.array(vel0)]
    rates, pos = [np.array(rates0)], [np.array(pos0)]
    for a in acc:
        q, v, w, x = step(quat[-1], vel[-1], rates[-1], pos[-1], a, dt)
        quat.append(q)
        vel.append(v)
        rates.append(w)
        pos.append(x)
    return np.array(quat), np.array(vel), np.array(rates), np.array(pos)


def body_accelerations(vel, rates, dt):
    out = []
    for t in range(len(vel) - 1):
        increment = Rotation.from_rotvec(rates[t] * dt)
        a = (increment.apply(vel[t + 1]) - vel[t]) / dt
        alpha = (rates[t + 1] - rates[t]) / dt
        out.append(np.concatenate([a, alpha]))
    return np.array(out)


def eval_tree(codes, values, leaves):
    """Recursive evaluation; leaves[k] is the value of variable k."""
    pos = 0

    def rec():
        nonlocal pos
        c, v = int(codes[pos]), float(values[pos])
        pos += 1
        if c == CONST:
            return v
        if c >= VAR_BASE:
            return float(leaves[c - VAR_BASE])
        a = rec()
        b = rec()
        if c == 0:
            return a + b
        if c == 1:
            return a - b
        if c == 2:
            return a * b
        return 1.0 if abs(b) < DIV_EPS else a / b

    return rec()


def window_error(tree, target, arrays, start, n_steps, squared=False, att_weight=0.0, alpha=1.0):
    """Integrate every state from `start` with the tree's acceleration for `target`; with
    att_weight, angular targets also count their angle (phi, theta, psi for p, q, r); with
    alpha < 1 the acceleration lags the tree's value (a <- a + alpha (tree - a), from the
    data's acceleration before `start`)."""
    lagged = arrays.acc[start - 1, target]
    quat = arrays.quat[start].copy()
    vel = arrays.states[start, 3:6].copy()
    rates = arrays.states[start, 6:9].copy()
    pos = np.zeros(3)
    total = 0.0
    for k in range(n_steps):
        idx = start + k
        leaves = list(euler(quat)) + list(vel) + list(rates)
        leaves += [arrays.inputs[idx - d, j] for j, d in enumerate(tree.delays)]
        acc = arrays.acc[idx].copy()
        acc[target] = eval_tree(tree.codes, tree.values, leaves)
        if alpha < 1.0:
            lagged = lagged + alpha * (acc[target] - lagged)
            acc[target] = lagged
        quat, vel, rates, pos = step(quat, vel, rates, pos, acc, arrays.dt)
        x = np.concatenate([vel, rates])[target]
        if not abs(x) < 1e6:
            return np.inf
        e = x - arrays.states[idx + 1, 3 + target]
        total += e * e if squared else abs(e)
        if target >= 3 and att_weight > 0:
            d = euler(quat)[target - 3] - arrays.states[idx + 1, target - 3]
            d = att_weight * (np.mod(d + np.pi, 2 * np.pi) - np.pi)
            total += d * d if squared else abs(d)
    return total / n_steps


def evaluate_on_table(tree, table: np.ndarray) -> np.ndarray:
    """The kernel's value of `tree` on the rows 5.. of a (N, 9 + inputs) table of states
    and inputs (the kernel under test, fed from a plain table)."""
    from gpquad.engine.kernels.tree_eval import eval_on_samples

    samples = np.arange(5, len(table), dtype=np.int64)
    return eval_on_samples(
        tree.codes,
        tree.values,
        tree.size,
        tree.delays,
        np.ascontiguousarray(table[:, :9]),
        np.ascontiguousarray(table[:, 9:]),
        samples,
    )


def rigid_body_derivative(y, acc):
    """d/dt of y = [q (4), V (3), omega (3), x (3)] under body accelerations acc (6,):
    q_dot = q * (0, omega) / 2, V_dot = a - omega x V, omega_dot = alpha, x_dot = R(q) V,
    at the state with its quaternion normalised (the ODE keeps |q| = 1)."""
    q, v, w = y[:4] / np.linalg.norm(y[:4]), y[4:7], y[7:10]
    dq = 0.5 * np.concatenate([[-q[1:] @ w], q[0] * w + np.cross(q[1:], w)])
    out = [dq, acc[:3] - np.cross(w, v), acc[3:6]]
    if len(y) >= 13:
        out.append(rotation(q).apply(v))
    return np.concatenate(out)


def rk4_step(f, y, h):
    """One classical Runge-Kutta step of y_dot = f(y); the quaternion y[:4] normalised."""
    k1 = f(y)
    k2 = f(y + 0.5 * h * k1)
    k3 = f(y + 0.5 * h * k2)
    k4 = f(y + h * k3)
    out = y + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    out[:4] /= np.linalg.norm(out[:4])
    return out


def rk4_window_error(
    tree, target, arrays, start, n_steps, substeps, squared=False, att_weight=0.0, alpha=1.0
):
    """window_error flown by RK4 on the continuous-time ODE: `substeps` steps per sample, the
    tree at every stage, inputs and the data's other accelerations held over the sample, a
    lag as the state l with tau l_dot = tree - l (1 / tau = -log(1 - alpha) / dt); for a
    linear target the attitude and rates restart from the data's at every sample."""
    dt = arrays.dt
    rate = -np.log1p(-alpha) / dt if alpha < 1.0 else 0.0
    y = np.concatenate(
        [
            arrays.quat[start],
            arrays.states[start, 3:6],
            arrays.states[start, 6:9],
            [arrays.acc[start - 1, target]],
        ]
    )
    total = 0.0
    for k in range(n_steps):
        idx = start + k
        held = [arrays.inputs[idx - d, j] for j, d in enumerate(tree.delays)]
        if target < 3:  # a linear target: attitude and rates start each sample at the data's
            y[:4], y[7:10] = arrays.quat[idx], arrays.states[idx, 6:9]

        def f(state, idx=idx, held=held):
            leaves = list(euler(state[:4])) + list(state[4:10])
            value = eval_tree(tree.codes, tree.values, leaves + held)
            acc = arrays.acc[idx].copy()
            acc[target] = state[10] if alpha < 1.0 else value
            lag = rate * (value - state[10]) if alpha < 1.0 else 0.0
            return np.concatenate([rigid_body_derivative(state[:10], acc), [lag]])

        for _ in range(substeps):
            y = rk4_step(f, y, dt / substeps)
        x = y[4 + target]
        if not abs(x) < 1e6:
            return np.inf
        e = x - arrays.states[idx + 1, 3 + target]
        total += e * e if squared else abs(e)
        if target >= 3 and att_weight > 0:
            d = euler(y[:4])[target - 3] - arrays.states[idx + 1, target - 3]
            d = att_weight * (np.mod(d + np.pi, 2 * np.pi) - np.pi)
            total += d * d if squared else abs(d)
    return total / n_steps


def right_operands(codes):
    """Index of each operator node's right operand in a prefix tree, -1 for leaves, by a
    recursive parse."""
    out = [-1] * len(codes)
    pos = 0

    def rec():
        nonlocal pos
        here = pos
        pos += 1
        if int(codes[here]) < CONST:
            rec()
            out[here] = pos
            rec()

    rec()
    return out


def eval_with_tangent(codes, values, leaves, tangents):
    """(value, gradient w.r.t. the constants) by forward mode: every node carries its
    derivative vector; a leaf k carries tangents[k], the j-th constant the unit vector j."""
    n_c = tangents.shape[1]
    pos, slot = 0, 0

    def rec():
        nonlocal pos, slot
        c, v = int(codes[pos]), float(values[pos])
        pos += 1
        if c == CONST:
            d = np.zeros(n_c)
            d[slot] = 1.0
            slot += 1
            return v, d
        if c >= VAR_BASE:
            return float(leaves[c - VAR_BASE]), np.array(tangents[c - VAR_BASE], dtype=float)
        (a, da), (b, db) = rec(), rec()
        if c == 0:
            return a + b, da + db
        if c == 1:
            return a - b, da - db
        if c == 2:
            return a * b, da * b + a * db
        if abs(b) < DIV_EPS:
            return 1.0, np.zeros(n_c)
        return a / b, (da - (a / b) * db) / b

    return rec()
