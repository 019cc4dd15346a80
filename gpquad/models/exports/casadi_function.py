"""`casadi` export (optional: needs the `casadi` package, `pip install gpquad[casadi]`).

casadi_functions(model) gives casadi.Function objects built from the prefix trees:
- commanded(x[9], H[(HISTORY + 1) x n_inputs]) -> f[6]: each equation's right-hand side;
- rhs(x[9], H, lag[6]) -> (a[6], lag_dot[6]): the continuous-time right-hand side, as the
  python export's `rhs`: a = f, but for a lagged equation its lag state lag[i], and
  lag_dot[i] = (f[i] - lag[i]) / tau for a lagged equation (else 0);
- for an euler model also accel(x[9], H, prev[6]) -> a[6]: the accelerations eq. 2 applies
  over one step, a lagged equation's filtered from prev (the step before's; zeros at the
  start), as the python export's `accel`.
x = [phi theta psi u v w p q r]; H holds raw inputs, row d read d samples back (trim
subtracted inside). Protected division is if_else(|b| < DIV_EPS, 1, a/b).

For an MPC: an rk4 model (model.integrator) is an ODE, [u v w]_dot = a[:3] - omega x [u v w],
[p q r]_dot = a[3:], the attitude by the body rates (the kinematics of the exports'
headers), the lag states by lag_dot, with the inputs held over each sample of DT; any
casadi integrator of it (e.g. RK4 with model.substeps steps per sample) flies the model.
An euler model's one step is eq. 2 with accel (gpquad.engine.kernels.step.euler_step).
export_casadi(model) is the serialised `exported_function` (casadi.Function.deserialize
reads it): rhs for an rk4 model, accel for an euler one.
"""

from __future__ import annotations

from gpquad.engine.tree.operators import ADD, DIV, DIV_EPS, MUL, SUB
from gpquad.errors import GpquadError
from gpquad.models.exports.codegen import Leaf, fold, model_spec


def _casadi():
    try:
        import casadi
    except ImportError:
        raise GpquadError(
            "the casadi export needs the casadi package: pip install "
            "'gpquad[casadi]' (or pip install casadi)",
            field="--format",
        ) from None
    return casadi


def casadi_functions(model) -> dict:
    """{"commanded", "rhs" and, for an euler model, "accel": casadi.Function} of `model`
    (module notes)."""
    ca = _casadi()
    spec = model_spec(model)
    x = ca.SX.sym("x", 9)
    hist = ca.SX.sym("H", spec.history + 1, spec.n_inputs)
    prev = ca.SX.sym("prev", 6)
    trimmed = ca.SX(spec.history + 1, spec.n_inputs)
    for d in range(spec.history + 1):
        for i in range(spec.n_inputs):
            trimmed[d, i] = hist[d, i] - spec.trim[i]

    def leaf(leaf_: Leaf):
        if leaf_.kind == "state":
            return x[leaf_.index]
        return trimmed[leaf_.delay, leaf_.index]

    ops = {
        ADD: lambda a, b: a + b,
        SUB: lambda a, b: a - b,
        MUL: lambda a, b: a * b,
        DIV: lambda a, b: ca.if_else(ca.fabs(b) < DIV_EPS, 1.0, a / b),
    }
    rhs = [
        fold(t.tree, spec.n_inputs, leaf, ca.SX, lambda c, a, b: ops[c](a, b)) for t in spec.targets
    ]
    f = ca.vertcat(*rhs)
    applied = ca.vertcat(
        *[
            prev[i] + t.alpha * (rhs[i] - prev[i]) if t.alpha < 1.0 else rhs[i]
            for i, t in enumerate(spec.targets)
        ]
    )
    lag = ca.SX.sym("lag", 6)
    lagged = [t.alpha < 1.0 for t in spec.targets]
    state_accel = ca.vertcat(*[lag[i] if lagged[i] else rhs[i] for i in range(6)])
    lag_dot = ca.vertcat(
        *[
            t.rate * (rhs[i] - lag[i]) if lagged[i] else ca.SX(0.0)
            for i, t in enumerate(spec.targets)
        ]
    )
    functions = {
        "commanded": ca.Function("commanded", [x, hist], [f], ["x", "H"], ["f"]),
        "rhs": ca.Function(
            "rhs", [x, hist, lag], [state_accel, lag_dot], ["x", "H", "lag"], ["a", "lag_dot"]
        ),
    }
    if spec.integrator == "euler":
        functions["accel"] = ca.Function(
            "accel", [x, hist, prev], [applied], ["x", "H", "prev"], ["a"]
        )
    return functions


def exported_function(model):
    """The Function that `gpquad export --format casadi` writes: rhs for an rk4 model (the
    continuous-time right-hand side), accel for an euler one (eq. 2's step)."""
    return casadi_functions(model)["accel" if model.integrator == "euler" else "rhs"]


def export_casadi(model) -> str:
    """The serialised exported_function of `model` (casadi.Function.deserialize)."""
    return exported_function(model).serialize()
