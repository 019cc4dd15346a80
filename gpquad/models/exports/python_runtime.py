"""The fixed part of the `python` export's module: the integrators and the public functions.

COMMON goes into every module; then EULER (the paper's eq. 2, repeating
gpquad.engine.kernels.rollout.rollout) or RK4 (repeating
gpquad.engine.kernels.fitness_rk4.rk4_rollout), each a `fly` doing the kernel's
floating-point operations in the kernel's order, so that it gives the kernel's numbers.
"""

COMMON = '''
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


def _renormalize(q0, q1, q2, q3):
    k = 1.5 - 0.5 * (q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
    return q0 * k, q1 * k, q2 * k, q3 * k


def _trimmed_history(input_history):
    rows = np.asarray(input_history, dtype=float)
    if rows.shape != (HISTORY + 1, len(INPUT_NAMES)):
        raise ValueError(f"input_history must have shape ({HISTORY + 1}, {len(INPUT_NAMES)}): "
                         "row d holds the raw inputs d samples back")
    return (rows - np.asarray(TRIM)).tolist()


def _state_list(state):
    x = [float(v) for v in state]
    if len(x) != 9:
        raise ValueError("state needs 9 values [phi, theta, psi, u, v, w, p, q, r]")
    return x


def commanded(state, input_history):
    """Each equation's right-hand side f (the value a lagged equation follows), shape (6,).

    state: [phi, theta, psi, u, v, w, p, q, r]; input_history: (HISTORY + 1, n_inputs) raw
    inputs, row d read d samples back.
    """
    return np.array(_commanded(_state_list(state), _trimmed_history(input_history)))


def rhs(state, input_history, lag=None):
    """The equations' continuous-time right-hand side: (accelerations (6,), lag_dot (6,)).

    accelerations [a_x, a_y, a_z, p_dot, q_dot, r_dot]: f = commanded(), but for a lagged
    equation (TAU > 0) its lag state lag[i]; lag_dot: d(lag)/dt = LAG_RATE (f - lag) for a
    lagged equation, 0 otherwise. lag: the six lag states (zeros, the default, at the start
    of a flight; entries of equations without a lag are not read). An integrator of one's
    own flies the model as the ODE of the module notes with these.
    """
    f = commanded(state, input_history)
    a = np.zeros(6) if lag is None else np.asarray(lag, dtype=float)
    if a.shape != (6,):
        raise ValueError("lag needs 6 values, one per equation")
    lagged = np.asarray(ALPHA) < 1.0
    return (np.where(lagged, a, f),
            np.where(lagged, np.asarray(LAG_RATE) * (f - a), 0.0))


def _fly_arguments(inputs, x0):
    """(trimmed input rows, x0) of fly's arguments, checked."""
    inputs = np.asarray(inputs, dtype=float)
    if inputs.ndim != 2 or inputs.shape[1] != len(INPUT_NAMES) or len(inputs) < 1:
        raise ValueError(f"inputs must have shape (N >= 1, {len(INPUT_NAMES)}) for "
                         f"{INPUT_NAMES}")
    x0 = np.zeros(9) if x0 is None else np.asarray(x0, dtype=float)
    if x0.shape != (9,) or not np.all(np.isfinite(x0)):
        raise ValueError("x0 needs 9 finite values [phi, theta, psi, u, v, w, p, q, r]")
    return (inputs - np.asarray(TRIM)).tolist(), x0
'''

EULER = '''

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


def _rotate_back(d0, d1, d2, d3, b0, b1, b2):
    t0 = 2.0 * (d3 * b1 - d2 * b2)
    t1 = 2.0 * (d1 * b2 - d3 * b0)
    t2 = 2.0 * (d2 * b0 - d1 * b1)
    return (b0 + d0 * t0 + (d3 * t1 - d2 * t2), b1 + d0 * t1 + (d1 * t2 - d3 * t0),
            b2 + d0 * t2 + (d2 * t0 - d1 * t1))


def accel(state, input_history, previous=None):
    """The accelerations eq. 2 applies over one step, shape (6,) [a_x, a_y, a_z, p_dot,
    q_dot, r_dot]: commanded(), a lagged equation's (ALPHA < 1) filtered from `previous`,
    the accelerations applied the step before (zeros, the default, at the start)."""
    f = commanded(state, input_history)
    prev = np.zeros(6) if previous is None else np.asarray(previous, dtype=float)
    return np.array([prev[i] + ALPHA[i] * (f[i] - prev[i]) if ALPHA[i] < 1.0 else f[i]
                     for i in range(6)])


def fly(inputs, x0=None):
    """Fly the model by eq. 2: states (N, 9) [phi, theta, psi, u, v, w, p, q, r] for raw
    inputs (N, n_inputs), one row per DT; rows before the first held at the first; lags
    start from zero acceleration; x0 the state at row 0 (default zeros)."""
    rows, x0 = _fly_arguments(inputs, x0)
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

RK4 = '''

#: Classical RK4: stage s at y + NODES[s] h k_(s-1), the step y + h sum WEIGHTS[s] k_s.
NODES = (0.0, 0.5, 0.5, 1.0)
WEIGHTS = (1.0 / 6.0, 1.0 / 3.0, 1.0 / 3.0, 1.0 / 6.0)


def _stage_state(y, slope, node, h):
    """y + node h slope, its quaternion normalised (node 0: y itself)."""
    if node == 0.0:
        return list(y)
    step = node * h
    ys = [a + step * b for a, b in zip(y, slope)]
    scale = 1.0 / math.sqrt(ys[0] * ys[0] + ys[1] * ys[1] + ys[2] * ys[2] + ys[3] * ys[3])
    for i in range(4):
        ys[i] *= scale
    return ys


def _state_of(y):
    """[phi, theta, psi, u, v, w, p, q, r] of a flown state y (quaternion, u v w, p q r,
    six lag states)."""
    return list(_euler(y[0], y[1], y[2], y[3])) + y[4:10]


def _derivative(y, f):
    """d/dt of the flown state y under the right-hand sides f (the module's ODE)."""
    q0, q1, q2, q3, u, v, w, p, q, r = y[:10]
    a = [y[10 + i] if ALPHA[i] < 1.0 else f[i] for i in range(6)]
    return [
        -0.5 * (q1 * p + q2 * q + q3 * r),
        0.5 * (q0 * p + q2 * r - q3 * q),
        0.5 * (q0 * q + q3 * p - q1 * r),
        0.5 * (q0 * r + q1 * q - q2 * p),
        a[0] - (q * w - r * v),
        a[1] - (r * u - p * w),
        a[2] - (p * v - q * u),
        a[3],
        a[4],
        a[5],
    ] + [LAG_RATE[i] * (f[i] - y[10 + i]) if ALPHA[i] < 1.0 else 0.0 for i in range(6)]


def fly(inputs, x0=None):
    """Fly the model by SUBSTEPS classical RK4 steps per sample: states (N, 9) [phi, theta,
    psi, u, v, w, p, q, r] for raw inputs (N, n_inputs), one row per DT, each row held over
    its sample; rows before the first held at the first; lag states start at zero; x0 the
    state at row 0 (default zeros)."""
    rows, x0 = _fly_arguments(inputs, x0)
    n = len(rows)
    h = DT / SUBSTEPS
    y = list(_quat_from_euler(float(x0[0]), float(x0[1]), float(x0[2])))
    y += [float(x) for x in x0[3:]] + [0.0] * 6
    slope = [0.0] * 16
    out = np.empty((n, 9))
    for k in range(n):
        out[k] = _state_of(y)
        if k == n - 1:
            break
        held = [rows[max(k - d, 0)] for d in range(HISTORY + 1)]
        for _ in range(SUBSTEPS):
            for stage in range(4):
                ys = _stage_state(y, slope, NODES[stage], h)
                slope = _derivative(ys, _commanded(_state_of(ys), held))
                weight = WEIGHTS[stage]
                if stage == 0:
                    total = [weight * b for b in slope]
                else:
                    total = [t + weight * b for t, b in zip(total, slope)]
            y = [a + h * t for a, t in zip(y, total)]
            y[0], y[1], y[2], y[3] = _renormalize(y[0], y[1], y[2], y[3])
    return out
'''
