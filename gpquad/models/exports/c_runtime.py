"""The fixed part of the `c` export's source: the integrators and the public functions.

COMMON goes into every source; then EULER (the paper's eq. 2, repeating
gpquad.engine.kernels.rollout.rollout) or RK4 (repeating
gpquad.engine.kernels.fitness_rk4.rk4_rollout). @p@ is the function prefix, @P@ the macro
prefix, @DIV_EPS@ the protected division's threshold; the source defines before them
@p@_trim, @p@_alpha, @p@_lag_rate and @p@_equations (each equation's tree value).
"""

COMMON = """
static inline double @p@_pdiv(double a, double b)
{
    /* protected division: 1 where |b| < @DIV_EPS@ */
    return fabs(b) < @DIV_EPS@ ? 1.0 : a / b;
}

static void @p@_quat_from_euler(double phi, double theta, double psi, double q[4])
{
    double cr = cos(0.5 * phi), sr = sin(0.5 * phi);
    double cp = cos(0.5 * theta), sp = sin(0.5 * theta);
    double cy = cos(0.5 * psi), sy = sin(0.5 * psi);
    q[0] = cr * cp * cy + sr * sp * sy;
    q[1] = sr * cp * cy - cr * sp * sy;
    q[2] = cr * sp * cy + sr * cp * sy;
    q[3] = cr * cp * sy - sr * sp * cy;
}

static void @p@_euler(const double q[4], double *phi, double *theta, double *psi)
{
    double s = 2.0 * (q[0] * q[2] - q[3] * q[1]);
    *phi = atan2(2.0 * (q[0] * q[1] + q[2] * q[3]), 1.0 - 2.0 * (q[1] * q[1] + q[2] * q[2]));
    *theta = s != s ? s : asin(s > 1.0 ? 1.0 : (s < -1.0 ? -1.0 : s));
    *psi = atan2(2.0 * (q[0] * q[3] + q[1] * q[2]), 1.0 - 2.0 * (q[2] * q[2] + q[3] * q[3]));
}

static void @p@_trimmed(const double *raw, double *out)
{
    int i;
    for (i = 0; i < (@P@_HISTORY + 1) * @P@_N_INPUTS; ++i)
        out[i] = raw[i] - @p@_trim[i % @P@_N_INPUTS];
}

void @p@_commanded(const double state[9], const double *input_history, double out[6])
{
    double h[(@P@_HISTORY + 1) * @P@_N_INPUTS];
    @p@_trimmed(input_history, h);
    @p@_equations(state, h, out);
}

void @p@_rhs(const double state[9], const double *input_history, const double lag[6],
           double accel[6], double lag_dot[6])
{
    double f[6], a;
    int i;
    @p@_commanded(state, input_history, f);
    for (i = 0; i < 6; ++i) {
        a = lag != NULL ? lag[i] : 0.0;
        accel[i] = @p@_alpha[i] < 1.0 ? a : f[i];
        lag_dot[i] = @p@_alpha[i] < 1.0 ? @p@_lag_rate[i] * (f[i] - a) : 0.0;
    }
}
"""

EULER = """
static void @p@_rate_increment(double p, double q, double r, double dt, double d[4])
{
    /* exp(omega dt / 2) for body rates held over dt (series below h = 0.5) */
    double h2 = 0.25 * (p * p + q * q + r * r) * dt * dt;
    double sinc, cosh_, s;
    if (h2 < 0.5 * 0.5) {
        sinc = 1.0 + h2 * (-1.0 / 6.0 + h2 * (1.0 / 120.0 + h2 * (-1.0 / 5040.0 + h2 * (
            1.0 / 362880.0 + h2 * (-1.0 / 39916800.0 + h2 * (1.0 / 6227020800.0 + h2 * (
                -1.0 / 1307674368000.0)))))));
        cosh_ = 1.0 + h2 * (-0.5 + h2 * (1.0 / 24.0 + h2 * (-1.0 / 720.0 + h2 * (
            1.0 / 40320.0 + h2 * (-1.0 / 3628800.0 + h2 * (1.0 / 479001600.0 + h2 * (
                -1.0 / 87178291200.0)))))));
    } else {
        double h = sqrt(h2);
        sinc = sin(h) / h;
        cosh_ = cos(h);
    }
    s = 0.5 * dt * sinc;
    d[0] = cosh_;
    d[1] = p * s;
    d[2] = q * s;
    d[3] = r * s;
}

void @p@_accel(const double state[9], const double *input_history, const double previous[6],
             double accel[6])
{
    double f[6];
    int i;
    @p@_commanded(state, input_history, f);
    for (i = 0; i < 6; ++i)
        accel[i] = @p@_alpha[i] < 1.0 ? previous[i] + @p@_alpha[i] * (f[i] - previous[i]) : f[i];
}

int @p@_fly(const double *inputs, int n_rows, const double x0[9], double *states)
{
    double quat[4], d[4], n[4], f[6], a[6], applied[6] = {0.0, 0.0, 0.0, 0.0, 0.0, 0.0};
    double h[(@P@_HISTORY + 1) * @P@_N_INPUTS];
    double u, v, w, p, q, r, k_norm, b0, b1, b2, t0, t1, t2;
    int i, k, dly, row;
    if (inputs == NULL || x0 == NULL || states == NULL)
        return 1;
    if (n_rows < 1)
        return 2;
    for (i = 0; i < 9; ++i)
        if (!isfinite(x0[i]))
            return 3;
    @p@_quat_from_euler(x0[0], x0[1], x0[2], quat);
    u = x0[3]; v = x0[4]; w = x0[5]; p = x0[6]; q = x0[7]; r = x0[8];
    for (k = 0; k < n_rows; ++k) {
        double *x = states + 9 * (size_t)k;
        @p@_euler(quat, &x[0], &x[1], &x[2]);
        x[3] = u; x[4] = v; x[5] = w; x[6] = p; x[7] = q; x[8] = r;
        if (k == n_rows - 1)
            break;
        for (dly = 0; dly <= @P@_HISTORY; ++dly) {
            row = k - dly > 0 ? k - dly : 0;
            for (i = 0; i < @P@_N_INPUTS; ++i)
                h[dly * @P@_N_INPUTS + i] = inputs[(size_t)row * @P@_N_INPUTS + i] - @p@_trim[i];
        }
        @p@_equations(x, h, f);
        for (i = 0; i < 6; ++i) {
            a[i] = f[i];
            if (@p@_alpha[i] < 1.0) {
                applied[i] += @p@_alpha[i] * (f[i] - applied[i]);
                a[i] = applied[i];
            }
        }
        @p@_rate_increment(p, q, r, @P@_DT, d);
        /* velocity: rotate_back(d, vel + a dt) */
        b0 = u + a[0] * @P@_DT; b1 = v + a[1] * @P@_DT; b2 = w + a[2] * @P@_DT;
        t0 = 2.0 * (d[3] * b1 - d[2] * b2);
        t1 = 2.0 * (d[1] * b2 - d[3] * b0);
        t2 = 2.0 * (d[2] * b0 - d[1] * b1);
        u = b0 + d[0] * t0 + (d[3] * t1 - d[2] * t2);
        v = b1 + d[0] * t1 + (d[1] * t2 - d[3] * t0);
        w = b2 + d[0] * t2 + (d[2] * t0 - d[1] * t1);
        /* attitude: quat * d, renormalised to first order */
        n[0] = quat[0] * d[0] - quat[1] * d[1] - quat[2] * d[2] - quat[3] * d[3];
        n[1] = quat[0] * d[1] + quat[1] * d[0] + quat[2] * d[3] - quat[3] * d[2];
        n[2] = quat[0] * d[2] - quat[1] * d[3] + quat[2] * d[0] + quat[3] * d[1];
        n[3] = quat[0] * d[3] + quat[1] * d[2] - quat[2] * d[1] + quat[3] * d[0];
        k_norm = 1.5 - 0.5 * (n[0] * n[0] + n[1] * n[1] + n[2] * n[2] + n[3] * n[3]);
        for (i = 0; i < 4; ++i)
            quat[i] = n[i] * k_norm;
        p += a[3] * @P@_DT;
        q += a[4] * @P@_DT;
        r += a[5] * @P@_DT;
    }
    return 0;
}
"""

RK4 = """
static void @p@_state_of(const double y[16], double x[9])
{
    /* [phi theta psi u v w p q r] of a flown state y (quaternion, u v w, p q r, lags) */
    int i;
    @p@_euler(y, &x[0], &x[1], &x[2]);
    for (i = 0; i < 6; ++i)
        x[3 + i] = y[4 + i];
}

static void @p@_derivative(const double y[16], const double f[6], double k[16])
{
    /* d/dt of the flown state y under the right-hand sides f (the header's ODE) */
    double a[6];
    int i;
    for (i = 0; i < 6; ++i)
        a[i] = @p@_alpha[i] < 1.0 ? y[10 + i] : f[i];
    k[0] = -0.5 * (y[1] * y[7] + y[2] * y[8] + y[3] * y[9]);
    k[1] = 0.5 * (y[0] * y[7] + y[2] * y[9] - y[3] * y[8]);
    k[2] = 0.5 * (y[0] * y[8] + y[3] * y[7] - y[1] * y[9]);
    k[3] = 0.5 * (y[0] * y[9] + y[1] * y[8] - y[2] * y[7]);
    k[4] = a[0] - (y[8] * y[6] - y[9] * y[5]);
    k[5] = a[1] - (y[9] * y[4] - y[7] * y[6]);
    k[6] = a[2] - (y[7] * y[5] - y[8] * y[4]);
    k[7] = a[3];
    k[8] = a[4];
    k[9] = a[5];
    for (i = 0; i < 6; ++i)
        k[10 + i] = @p@_alpha[i] < 1.0 ? @p@_lag_rate[i] * (f[i] - y[10 + i]) : 0.0;
}

int @p@_fly(const double *inputs, int n_rows, const double x0[9], double *states)
{
    /* classical RK4, @P@_SUBSTEPS steps per sample, inputs held over the sample */
    static const double nodes[4] = {0.0, 0.5, 0.5, 1.0};
    static const double weights[4] = {1.0 / 6.0, 1.0 / 3.0, 1.0 / 3.0, 1.0 / 6.0};
    const double step_h = @P@_DT / @P@_SUBSTEPS;
    double y[16], ys[16], slope[16], total[16], x[9], f[6];
    double h[(@P@_HISTORY + 1) * @P@_N_INPUTS];
    double step, scale, k_norm;
    int i, k, sub, stage, dly, row;
    if (inputs == NULL || x0 == NULL || states == NULL)
        return 1;
    if (n_rows < 1)
        return 2;
    for (i = 0; i < 9; ++i)
        if (!isfinite(x0[i]))
            return 3;
    @p@_quat_from_euler(x0[0], x0[1], x0[2], y);
    for (i = 0; i < 6; ++i) {
        y[4 + i] = x0[3 + i];
        y[10 + i] = 0.0;
    }
    for (i = 0; i < 16; ++i)
        slope[i] = total[i] = 0.0;
    for (k = 0; k < n_rows; ++k) {
        @p@_state_of(y, states + 9 * (size_t)k);
        if (k == n_rows - 1)
            break;
        for (dly = 0; dly <= @P@_HISTORY; ++dly) {
            row = k - dly > 0 ? k - dly : 0;
            for (i = 0; i < @P@_N_INPUTS; ++i)
                h[dly * @P@_N_INPUTS + i] = inputs[(size_t)row * @P@_N_INPUTS + i] - @p@_trim[i];
        }
        for (sub = 0; sub < @P@_SUBSTEPS; ++sub) {
            for (stage = 0; stage < 4; ++stage) {
                /* the stage's state, its quaternion normalised */
                if (nodes[stage] == 0.0) {
                    for (i = 0; i < 16; ++i)
                        ys[i] = y[i];
                } else {
                    step = nodes[stage] * step_h;
                    for (i = 0; i < 16; ++i)
                        ys[i] = y[i] + step * slope[i];
                    scale = ys[0] * ys[0] + ys[1] * ys[1] + ys[2] * ys[2] + ys[3] * ys[3];
                    scale = 1.0 / sqrt(scale);
                    for (i = 0; i < 4; ++i)
                        ys[i] *= scale;
                }
                @p@_state_of(ys, x);
                @p@_equations(x, h, f);
                @p@_derivative(ys, f, slope);
                for (i = 0; i < 16; ++i)
                    total[i] = stage == 0 ? weights[stage] * slope[i]
                                          : total[i] + weights[stage] * slope[i];
            }
            for (i = 0; i < 16; ++i)
                y[i] += step_h * total[i];
            /* renormalised to first order */
            k_norm = 1.5 - 0.5 * (y[0] * y[0] + y[1] * y[1] + y[2] * y[2] + y[3] * y[3]);
            for (i = 0; i < 4; ++i)
                y[i] *= k_norm;
        }
    }
    return 0;
}
"""
