"""`casadi` export (optional: needs the `casadi` package, `pip install gpquad[casadi]`).

casadi_functions(model) gives two casadi.Function objects built from the prefix trees:
- commanded(x[9], H[(HISTORY + 1) x n_inputs]) -> f[6]: each equation's right-hand side;
- accel(x[9], H, prev[6]) -> a[6]: the accelerations applied, a lagged equation's filtered
  from prev (the step before's; zeros at the start), as the python export's `accel`.
x = [phi theta psi u v w p q r]; H holds raw inputs, row d read d samples back (trim
subtracted inside). Protected division is if_else(|b| < DIV_EPS, 1, a/b). For an MPC, the
model's one step is x' = integrate(x, accel) with dt = DT (gpquad.engine.kernels.fitness).
export_casadi(model) is the serialised accel Function (casadi.Function.deserialize reads it).
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
    """{"commanded": casadi.Function, "accel": casadi.Function} of `model` (module notes)."""
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
    commanded = ca.Function("commanded", [x, hist], [f], ["x", "H"], ["f"])
    accel = ca.Function("accel", [x, hist, prev], [applied], ["x", "H", "prev"], ["a"])
    return {"commanded": commanded, "accel": accel}


def export_casadi(model) -> str:
    """The serialised casadi accel Function of `model` (casadi.Function.deserialize)."""
    return casadi_functions(model)["accel"].serialize()
