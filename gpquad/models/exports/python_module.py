"""`python` export: a self-contained module (numpy and the standard library only).

The module holds DT, INPUT_NAMES, TRIM, HISTORY, TAU, ALPHA and
- commanded(state, input_history) -> (6,): each equation's right-hand side;
- accel(state, input_history, previous=None) -> (6,): the accelerations applied, a lagged
  equation's filtered from `previous` (the step before's; zeros at the start);
- fly(inputs, x0=None) -> states (N, 9): DiscoveredModel.fly_states of raw inputs.
input_history has HISTORY + 1 rows of raw inputs, row d read d samples back (row 0 the
current inputs). The quaternion integrator and the tree evaluation repeat the numba kernels'
floating-point operations in their order (gpquad.engine.kernels.rollout.rollout).
"""

from __future__ import annotations

from gpquad.engine.tree.operators import DIV_EPS
from gpquad.engine.variables import STATE_NAMES, TARGET_NAMES
from gpquad.models.exports.codegen import Leaf, describe, model_spec, source_expression

_RUNTIME = '''
def _pdiv(a, b):
    """Protected division: 1 where |b| < DIV_EPS."""
    return 1.0 if abs(b) < DIV_EPS else a / b


def _quat_from_euler(phi, theta, psi):
    cr, sr = math.cos(0.5 * phi), math.sin(0.5 * phi)
    cp, sp = math.cos(0.5 * theta), math.sin(0.5 * theta)
    cy, sy = math.cos(0.5 * psi), math.sin(0.5 * psi)
    return (cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy)


def _euler(q0, q1, q2, q3):
    phi = math.atan2(2.0 * (q0 * q1 + q2 * q3), 1.0 - 2.0 * (q1 * q1 + q2 * q2))
    s = 2.0 * (q0 * q2 - q3 * q1)
    theta = math.asin(min(1.0, max(-1.0, s))) if s == s else math.nan
    psi = math.atan2(2.0 * (q0 * q3 + q1 * q2), 1.0 - 2.0 * (q2 * q2 + q3 * q3))
    return phi, theta, psi


def _rate_increment(p, q, r, dt):
    """exp(omega dt / 2) for body rates held over dt (series below h = 0.5)."""
    h2 = 0.25 * (p * p + q * q + r * r) * dt * dt
    if h2 < 0.5 * 0.5:
        sinc = 1.0 + h2 * (-1.0 / 6.0 + h2 * (1.0 / 120.0 + h2 * (-1.0 / 5040.0 + h2 * (
            1.0 / 362880.0 + h2 * (-1.0 / 39916800.0 + h2 * (1.0 / 6227020800.0 + h2 * (
                -1.0 / 1307674368000.0)))))))
        cosh = 1.0 + h2 * (-0.5 + h2 * (1.0 / 24.0 + h2 * (-1.0 / 720.0 + h2 * (
            1.0 / 40320.0 + h2 * (-1.0 / 3628800.0 + h2 * (1.0 / 479001600.0 + h2 * (
                -1.0 / 87178291200.0)))))))
    elif math.isfinite(h2):
        h = math.sqrt(h2)
        sinc = math.sin(h) / h
        cosh = math.cos(h)
    else:
        sinc = cosh = math.nan
    s = 0.5 * dt * sinc
    return cosh, p * s, q * s, r * s


def _quat_mul(a0, a1, a2, a3, b0, b1, b2, b3):
    return (a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3, a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2,
            a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1, a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0)


def _renormalize(q0, q1, q2, q3):
    k = 1.5 - 0.5 * (q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
    return q0 * k, q1 * k, q2 * k, q3 * k


def _rotate_back(d0, d1, d2, d3, b0, b1, b2):
    t0 = 2.0 * (d3 * b1 - d2 * b2)
    t1 = 2.0 * (d1 * b2 - d3 * b0)
    t2 = 2.0 * (d2 * b0 - d1 * b1)
    return (b0 + d0 * t0 + (d3 * t1 - d2 * t2), b1 + d0 * t1 + (d1 * t2 - d3 * t0),
            b2 + d0 * t2 + (d2 * t0 - d1 * t1))


def _trimmed_history(input_history):
    rows = np.asarray(input_history, dtype=float)
    if rows.shape != (HISTORY + 1, len(INPUT_NAMES)):
        raise ValueError(f"input_history must have shape ({HISTORY + 1}, {len(INPUT_NAMES)}): "
                         "row d holds the raw inputs d samples back")
    return (rows - np.asarray(TRIM)).tolist()


def commanded(state, input_history):
    """Each equation's right-hand side (the value a lagged equation follows), shape (6,).

    state: [phi, theta, psi, u, v, w, p, q, r]; input_history: (HISTORY + 1, n_inputs) raw
    inputs, row d read d samples back.
    """
    x = [float(v) for v in state]
    if len(x) != 9:
        raise ValueError("state needs 9 values [phi, theta, psi, u, v, w, p, q, r]")
    return np.array(_commanded(x, _trimmed_history(input_history)))


def accel(state, input_history, previous=None):
    """The accelerations the model applies, shape (6,) [a_x, a_y, a_z, p_dot, q_dot, r_dot]:
    commanded(), a lagged equation's (ALPHA < 1) filtered from `previous`, the accelerations
    applied the step before (zeros, the default, at the start of a flight)."""
    f = commanded(state, input_history)
    prev = np.zeros(6) if previous is None else np.asarray(previous, dtype=float)
    return np.array([prev[i] + ALPHA[i] * (f[i] - prev[i]) if ALPHA[i] < 1.0 else f[i]
                     for i in range(6)])


def fly(inputs, x0=None):
    """Fly the model: states (N, 9) [phi, theta, psi, u, v, w, p, q, r] for raw inputs
    (N, n_inputs), one row per DT; rows before the first held at the first; lags start
    from zero acceleration; x0 the state at row 0 (default zeros)."""
    inputs = np.asarray(inputs, dtype=float)
    if inputs.ndim != 2 or inputs.shape[1] != len(INPUT_NAMES) or len(inputs) < 1:
        raise ValueError(f"inputs must have shape (N >= 1, {len(INPUT_NAMES)}) for "
                         f"{INPUT_NAMES}")
    x0 = np.zeros(9) if x0 is None else np.asarray(x0, dtype=float)
    if x0.shape != (9,) or not np.all(np.isfinite(x0)):
        raise ValueError("x0 needs 9 finite values [phi, theta, psi, u, v, w, p, q, r]")
    rows = (inputs - np.asarray(TRIM)).tolist()
    n = len(rows)
    q0, q1, q2, q3 = _quat_from_euler(float(x0[0]), float(x0[1]), float(x0[2]))
    u, v, w, p, q, r = (float(x) for x in x0[3:])
    applied = [0.0] * 6
    out = np.empty((n, 9))
    for k in range(n):
        phi, theta, psi = _euler(q0, q1, q2, q3)
        x = [phi, theta, psi, u, v, w, p, q, r]
        out[k] = x
        if k == n - 1:
            break
        f = _commanded(x, [rows[max(k - d, 0)] for d in range(HISTORY + 1)])
        a = list(f)
        for i in range(6):
            if ALPHA[i] < 1.0:
                applied[i] += ALPHA[i] * (f[i] - applied[i])
                a[i] = applied[i]
        d0, d1, d2, d3 = _rate_increment(p, q, r, DT)
        u, v, w = _rotate_back(d0, d1, d2, d3, u + a[0] * DT, v + a[1] * DT, w + a[2] * DT)
        q0, q1, q2, q3 = _renormalize(*_quat_mul(q0, q1, q2, q3, d0, d1, d2, d3))
        p += a[3] * DT
        q += a[4] * DT
        r += a[5] * DT
    return out
'''


def _leaf_source(leaf: Leaf) -> str:
    if leaf.kind == "state":
        return STATE_NAMES[leaf.index]
    return f"h[{leaf.delay}][{leaf.index}]"


def export_python(model) -> str:
    """Source of a self-contained python module (numpy only) that flies `model` as
    DiscoveredModel.fly_states does (module notes)."""
    spec = model_spec(model)
    header = "\n".join(
        ["A gpquad model, exported as a self-contained module (numpy only).", ""]
        + describe(spec)
        + [
            "",
            "fly(inputs, x0) -> states (N, 9); accel(state, input_history, previous=None) -> (6,);",
            "commanded(state, input_history) -> (6,) right-hand sides. input_history: HISTORY + 1",
            "rows of raw inputs, row d read d samples back. Generated by gpquad.models.exports.",
        ]
    )
    header = header.replace("\\", "\\\\").replace('"""', "'''")
    body = [
        f'"""{header}\n"""',
        "",
        "import math",
        "",
        "import numpy as np",
        "",
        f"DT = {spec.dt!r}",
        f"INPUT_NAMES = {spec.input_names!r}",
        f"TRIM = {spec.trim!r}",
        f"STATE_NAMES = {STATE_NAMES!r}",
        f"TARGET_NAMES = {TARGET_NAMES!r}",
        f"HISTORY = {spec.history}",
        f"TAU = {tuple(t.tau for t in spec.targets)!r}",
        f"ALPHA = {tuple(t.alpha for t in spec.targets)!r}",
        f"DIV_EPS = {DIV_EPS!r}",
        f"EQUATIONS = {tuple(t.text for t in spec.targets)!r}",
        _RUNTIME.rstrip("\n"),
        "",
        "",
        "def _commanded(x, h):",
        '    """Right-hand sides of x (9 states) and h (trimmed input rows, row d = d back)."""',
        "    phi, theta, psi, u, v, w, p, q, r = x",
        "    return (",
    ]
    for t in spec.targets:
        expr = source_expression(t.tree, spec.n_inputs, _leaf_source)
        body.append(f"        {expr},  # {t.target}")
    body.append("    )")
    return "\n".join(body) + "\n"
