"""One discovered equation (model.json's per-target record): its tree, delays, lag and
errors, printed as text, LaTeX and sympy, read back with every field checked."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import sympy as sp

from gpquad.engine.taps import (
    base_input,
    canonical_taps,
    tap_names,
    taps_of,
)
from gpquad.engine.tree.encoding import Tree
from gpquad.engine.tree.export import (
    expr_string,
    round_constants,
    simplify,
    to_latex,
    to_sympy,
)
from gpquad.engine.variables import TARGET_LATEX, target_index
from gpquad.errors import GpquadError
from gpquad.models.model_checks import (
    check_expr_agrees,
    checked_number,
    checked_tree,
    parse_candidate,
)

#: A raw-input constant at most this fraction of the constants it sums (the equation's own
#: and each trimmed input's coefficient times its trim) is their float round-off, and the
#: raw forms print none (gpquad.models.precision.with_exact_raw_constant makes a negligible
#: one exactly that).
RAW_ROUNDOFF = 1e-9


@dataclass
class Equation:
    """One discovered equation: its tree and errors (integrated-state MAE or MSE)."""

    target: str
    tree: Tree
    input_names: tuple[str, ...]
    error: float
    validation_error: float
    trim: dict[str, float] = field(default_factory=dict)
    #: Simpler or other alternatives: the run's size/error Pareto front, as JSON records.
    candidates: list[dict] = field(default_factory=list)
    #: Significant digits of the printed forms (gpquad.models.precision.printed_digits).
    digits: int = 3
    #: Time constant (s) of the equation's first-order lag (gpquad.engine.lag); 0 = none.
    lag: float = 0.0

    def __post_init__(self):
        # taps in a canonical order: the read ones first, by delay (gpquad.engine.taps)
        self.tree = canonical_taps(self.tree, len(self.input_names))

    @property
    def leaf_names(self) -> tuple[str, ...]:
        """Names of the input leaves: the inputs, then their taps (gpquad.engine.taps)."""
        return tap_names(self.input_names, taps_of(len(self.tree.delays), len(self.input_names)))

    @property
    def delays(self) -> dict[str, int]:
        return {n: int(d) for n, d in zip(self.leaf_names, self.tree.delays, strict=True)}

    def used_delays(self) -> dict[str, int]:
        """Delays of the inputs (and taps) that appear in the equation."""
        used = self.tree.used_inputs()
        return {n: d for i, (n, d) in enumerate(self.delays.items()) if i in used}

    def sympy(self) -> sp.Expr:
        """Simplified sympy expression in the model's variables (taps of one input at the
        same delay are one variable: the first of them)."""
        expr = to_sympy(self.tree, self.leaf_names)
        first: dict[tuple[str, int], sp.Symbol] = {}
        reps = {}
        for name, d in self.delays.items():
            key = (base_input(name), d)
            sym = sp.Symbol(name, real=True)
            if key in first:
                reps[sym] = first[key]
            else:
                first[key] = sym
        return simplify(expr.xreplace(reps) if reps else expr)

    @property
    def n_constants(self) -> int:
        """Fitted numbers in the printed equation (each occurrence of a float in sympy())."""
        return sum(1 for a in sp.preorder_traversal(self.sympy()) if isinstance(a, sp.Float))

    def trims(self) -> dict[sp.Symbol, float]:
        """Each input leaf with a trim -> its trim."""
        return {
            sp.Symbol(n, real=True): self.trim.get(base_input(n), 0.0)
            for n in self.leaf_names
            if self.trim.get(base_input(n), 0.0)
        }

    def raw_constant_parts(self, expr: sp.Expr | None = None) -> list[float]:
        """What the raw form's constant sums: each term of the expanded equation (`expr`,
        default sympy()) that reads only trimmed inputs (or nothing), at raw inputs 0 (each
        trimmed input at -trim)."""
        trims = self.trims()
        at_zero = {s: -t for s, t in trims.items()}
        return [
            float(term.xreplace(at_zero))
            for term in sp.Add.make_args(sp.expand(self.sympy() if expr is None else expr))
            if term.free_symbols <= set(trims)
        ]

    def sympy_raw(self) -> sp.Expr:
        """The same equation in the raw (not trim-subtracted) inputs; a constant that is the
        round-off of its parts (RAW_ROUNDOFF) is left out."""
        expr = self.sympy()
        trims = self.trims()
        if not trims:
            return expr
        raw = simplify(expr.xreplace({s: s - t for s, t in trims.items()}))
        constant, rest = raw.as_coeff_Add()
        if constant and abs(float(constant)) <= RAW_ROUNDOFF * sum(
            abs(c) for c in self.raw_constant_parts(expr)
        ):
            return rest
        return raw

    def latex_lhs(self) -> str:
        """The left-hand side in LaTeX: the target, with its lag operator when lag > 0."""
        lhs = TARGET_LATEX[target_index(self.target)]
        if self.lag > 0:
            lhs = rf"\left(1 + {self.lag:.3g}\,\frac{{d}}{{dt}}\right) {lhs}"
        return lhs

    def latex(self, digits: int | None = None, raw: bool = False) -> str:
        """LaTeX with constants at `digits` significant digits (default: self.digits)."""
        lhs = self.latex_lhs()
        expr = self.sympy_raw() if raw else self.sympy()
        return f"{lhs} = {to_latex(expr, self.delays, self.leaf_names, digits or self.digits)}"

    def shown_inputs(self) -> dict[sp.Symbol, sp.Symbol]:
        """Input symbols -> their display symbols: u_T (t-5), u_R__tap1 at delay 0 -> u_R."""
        out = {}
        for n, d in self.delays.items():
            base = base_input(n)
            if d or base != n:
                out[sp.Symbol(n, real=True)] = sp.Symbol(f"{base}(t-{d})" if d else base, real=True)
        return out

    def text(self, digits: int | None = None, raw: bool = False) -> str:
        """One line, delayed inputs written u_T(t-5), constants rounded to `digits`
        significant digits (default: self.digits, which keeps the line faithful)."""
        expr = round_constants(self.sympy_raw() if raw else self.sympy(), digits or self.digits)
        lhs = (
            self.target if self.lag <= 0 else f"{self.target} + {self.lag:.3g} d({self.target})/dt"
        )
        return f"{lhs} = {expr.xreplace(self.shown_inputs())}"

    def summary(self) -> dict:
        """A short JSON record: expression, delays used, training error, size."""
        out = {
            "expr": expr_string(self.sympy()),
            "delays": self.used_delays(),
            "error": _json_number(self.error),
            "size": self.tree.size,
        }
        if self.lag > 0:
            out["lag"] = self.lag
        return out

    def alternatives(self) -> list[Equation]:
        """The front's candidates (`candidates`) as equations of the same inputs and trim,
        in the front's order (smallest first), each with its lag (gpquad.models.refine
        puts the found equation and its refinement path first); their validation error is
        unknown (NaN)."""
        out = []
        for i, c in enumerate(self.candidates):
            tree, _ = parse_candidate(self.target, i, c, self.input_names)
            out.append(
                Equation(
                    self.target,
                    tree,
                    self.input_names,
                    _number(c.get("error")),
                    np.nan,
                    dict(self.trim),
                    [],
                    self.digits,
                    float(c.get("lag", 0.0)),
                )
            )
        return out

    def to_dict(self) -> dict:
        out = {
            "expr": expr_string(self.sympy()),
            "delays": self.delays,
            "error": _json_number(self.error),
            "validation_error": _json_number(self.validation_error),
            "latex": self.latex(),
            "digits": self.digits,
            "size": self.tree.size,
            "prefix": {"codes": self.tree.codes.tolist(), "values": self.tree.values.tolist()},
        }
        if self.lag > 0:
            out["lag"] = self.lag
        if any(self.trim.values()):
            out["expr_raw"] = expr_string(self.sympy_raw())
        if self.candidates:
            out["candidates"] = self.candidates
        return out

    @classmethod
    def from_dict(cls, target: str, d: dict, input_names, trim) -> Equation:
        """The equation of a record read from a file, every field checked
        (gpquad.models.model_checks; a bad one is a GpquadError naming it)."""
        if not isinstance(d, dict):
            raise GpquadError("an equation is an object", field=f"targets.{target}")
        tree = checked_tree(target, d, input_names)
        candidates = d.get("candidates", [])
        if not isinstance(candidates, list):
            raise GpquadError("candidates is a list", field=f"targets.{target}.candidates")
        for i, c in enumerate(candidates):
            parse_candidate(target, i, c, input_names)
        lag = checked_number(d.get("lag", 0.0), f"targets.{target}.lag")
        digits = d.get("digits", 3)
        if isinstance(digits, bool) or not isinstance(digits, int) or not 1 <= digits <= 17:
            raise GpquadError(
                f"digits is a whole number from 1 to 17, not {digits!r}",
                field=f"targets.{target}.digits",
            )
        equation = cls(
            target,
            tree,
            tuple(input_names),
            _number(d.get("error")),
            _number(d.get("validation_error")),
            dict(trim),
            list(candidates),
            digits,
            max(lag, 0.0),
        )
        if "expr" in d:
            check_expr_agrees(
                target, d["expr"], equation.tree, equation.leaf_names, equation.delays
            )
        return equation


def _shown(x: float) -> str:
    """An error for a table: '-' where there is none (no validation data, diverged)."""
    return f"{x:.4g}" if np.isfinite(x) else "-"


def _json_number(x: float):
    """A float for JSON; NaN or inf (no validation data, a diverged model) becomes null."""
    return float(x) if np.isfinite(x) else None


def _number(x) -> float:
    """A JSON number back to a float; null (NaN or inf when written) becomes NaN."""
    return np.nan if x is None else float(x)
