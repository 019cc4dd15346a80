"""`c` export: a C99 source and header (libm only) that fly the model.

The header declares, for prefix P (default "gpquad"):
    int  P_fly(const double *inputs, int n_rows, const double x0[9], double *states);
    void P_commanded(const double state[9], const double *input_history, double out[6]);
    void P_accel(const double state[9], const double *input_history,
                 const double previous[6], double accel[6]);
inputs row-major n_rows x P_N_INPUTS in raw units; states n_rows x 9 [phi theta psi u v w p
q r]; input_history (P_HISTORY + 1) x P_N_INPUTS raw inputs, row d read d samples back;
previous: the accelerations applied the step before (zeros at the start; only lagged
equations read it). P_fly returns 0 on success, 1 for a NULL pointer, 2 for n_rows < 1,
3 for a non-finite x0. The operations repeat the numba kernels' in their order; compile
without -ffast-math and with -ffp-contract=off (the default of -std=c99) to get the
kernels' numbers, not only their equations.
"""

from __future__ import annotations

from gpquad.engine.tree.operators import DIV_EPS
from gpquad.engine.variables import STATE_NAMES, TARGET_NAMES
from gpquad.errors import GpquadError
from gpquad.models.exports.codegen import Leaf, describe, model_spec, source_expression

_RUNTIME = """
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
    @p@_rhs(state, h, out);
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
        @p@_rhs(x, h, f);
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


def _c_array(values) -> str:
    return "{" + ", ".join(repr(float(v)) for v in values) + "}"


def _comment(lines: list[str]) -> str:
    text = "\n".join((" * " + line).rstrip() for line in lines).replace("*/", "* /")
    return "/*\n" + text + "\n */"


def export_c(model, name: str = "gpquad_model", prefix: str = "gpquad") -> dict[str, str]:
    """{name.c: source, name.h: header} of a C99 implementation of `model` (module notes).
    `prefix` names the functions and macros (P_fly, P_N_INPUTS, ...), so that several
    models link into one program."""
    if not prefix.isidentifier() or not name.replace("-", "_").isidentifier():
        raise GpquadError(
            f"prefix '{prefix}' and name '{name}' must be C identifiers (letters, digits, _)",
            field="name",
        )
    spec = model_spec(model)
    upper = prefix.upper()
    about = [
        "A gpquad model, exported as C99 (libm only). Generated by gpquad.models.exports.",
        "",
    ] + describe(spec)
    guard = f"{name.upper().replace('-', '_')}_H"
    header = "\n".join(
        [
            _comment(
                about
                + [
                    "",
                    f"{prefix}_fly(inputs, n_rows, x0, states): inputs row-major "
                    f"n_rows x {upper}_N_INPUTS (raw units), states n_rows x 9 "
                    f"[{' '.join(STATE_NAMES)}]; returns 0, or 1 (NULL pointer), 2 "
                    "(n_rows < 1), 3 (x0 not finite).",
                    f"{prefix}_accel(state, input_history, previous, accel): input_history "
                    f"({upper}_HISTORY + 1) x {upper}_N_INPUTS raw inputs, row d read d "
                    "samples back; previous: accelerations applied the step before "
                    "(zeros at the start); accel in the order "
                    f"{' '.join(TARGET_NAMES)}.",
                ]
            ),
            f"#ifndef {guard}",
            f"#define {guard}",
            "",
            f"#define {upper}_DT {spec.dt!r}",
            f"#define {upper}_N_INPUTS {spec.n_inputs}",
            f"#define {upper}_HISTORY {spec.history}",
            "",
            "#ifdef __cplusplus",
            'extern "C" {',
            "#endif",
            "",
            f"extern const char *const {prefix}_input_names[{upper}_N_INPUTS];",
            f"int {prefix}_fly(const double *inputs, int n_rows, const double x0[9], "
            "double *states);",
            f"void {prefix}_commanded(const double state[9], const double *input_history, "
            "double out[6]);",
            f"void {prefix}_accel(const double state[9], const double *input_history, "
            "const double previous[6], double accel[6]);",
            "",
            "#ifdef __cplusplus",
            "}",
            "#endif",
            "",
            f"#endif /* {guard} */",
            "",
        ]
    )

    def leaf_source(leaf: Leaf) -> str:
        if leaf.kind == "state":
            return f"x[{leaf.index}]"
        return f"h[{leaf.delay * spec.n_inputs + leaf.index}]"

    rhs = []
    for i, t in enumerate(spec.targets):
        expr = source_expression(t.tree, spec.n_inputs, leaf_source, pdiv=f"{prefix}_pdiv")
        rhs.append(f"    out[{i}] = {expr};  /* {t.target} */")
    runtime = (
        _RUNTIME.replace("@P@", upper).replace("@p@", prefix).replace("@DIV_EPS@", repr(DIV_EPS))
    )
    names = ", ".join(f'"{n}"' for n in spec.input_names)
    source = "\n".join(
        [
            _comment(about),
            "",
            "#include <math.h>",
            "#include <stddef.h>",
            "",
            f'#include "{name}.h"',
            "",
            f"const char *const {prefix}_input_names[{upper}_N_INPUTS] = {{{names}}};",
            f"static const double {prefix}_trim[{upper}_N_INPUTS] = {_c_array(spec.trim)};",
            "/* lag factors alpha = 1 - exp(-dt / tau) per target; 1 = no lag */",
            f"static const double {prefix}_alpha[6] = {_c_array(t.alpha for t in spec.targets)};",
            "",
            f"static inline double {prefix}_pdiv(double a, double b);",
            "",
            f"static void {prefix}_rhs(const double x[9], const double *h, double out[6])",
            "{",
            "    /* x: state; h: trimmed inputs, h[d * N_INPUTS + i] = input i, d samples back */",
            *rhs,
            "}",
            runtime,
        ]
    )
    return {f"{name}.c": source, f"{name}.h": header}
