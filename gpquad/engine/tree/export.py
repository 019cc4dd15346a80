"""Export trees to sympy, LaTeX and strings, and parse equations back into trees.

Every form is built from the one operator table. Protected division is written
as plain division (it differs only where |denominator| < DIV_EPS).
Delayed inputs keep their plain names in sympy/JSON (delays are stored beside
the expression) and are written u_{T-5} in LaTeX.
"""

import numpy as np
import sympy as sp

from gpquad.engine.taps import MAX_TAPS, base_input, tap_index, tap_name, tap_names
from gpquad.engine.tree.arithmetic import parse_arithmetic
from gpquad.engine.tree.encoding import Tree
from gpquad.engine.tree.operators import ADD, CONST, DIV, DIV_EPS, MUL, OPERATOR_BY_CODE, VAR_BASE
from gpquad.engine.variables import STATE_LATEX, STATE_NAMES, input_latex, terminal_names
from gpquad.errors import GpquadError


def symbols_for(input_names) -> dict[str, sp.Symbol]:
    """sympy Symbols of every variable leaf, by name."""
    return {name: sp.Symbol(name, real=True) for name in terminal_names(input_names)}


def to_sympy(tree: Tree, input_names) -> sp.Expr:
    """The tree as an (unsimplified) sympy expression in the variable names."""
    syms = list(symbols_for(input_names).values())
    pos = 0

    def build():
        nonlocal pos
        c = int(tree.codes[pos])
        v = float(tree.values[pos])
        pos += 1
        if c == CONST:
            return sp.Float(v)
        if c >= VAR_BASE:
            return syms[c - VAR_BASE]
        left = build()
        right = build()
        if c == DIV and right.is_Number and abs(float(right)) < DIV_EPS:
            return sp.Integer(1)  # protected division, as the kernels evaluate it
        return OPERATOR_BY_CODE[c].sympy(left, right)

    return build()


def simplify(expr: sp.Expr) -> sp.Expr:
    """Expanded, collected form used for display and for structure comparison."""
    expanded = sp.expand(expr)
    if expanded.has(sp.Pow) and any(p.exp.is_negative for p in expanded.atoms(sp.Pow)):
        expanded = sp.together(expanded)
        num, den = sp.fraction(expanded)
        return sp.expand(num) / sp.expand(den)
    return expanded


def round_constants(expr: sp.Expr, digits: int = 3) -> sp.Expr:
    """Round every Float to `digits` significant digits (display only)."""
    reps = {}
    for f in expr.atoms(sp.Float):
        val = float(f)
        reps[f] = sp.Float(float(f"{val:.{digits}g}"), digits) if val else sp.Integer(0)
    return expr.xreplace(reps)


def to_latex(expr: sp.Expr, delays: dict[str, int], input_names, digits: int = 3) -> str:
    """LaTeX of an expression, inputs written with their delays (u_{T-5})."""
    names = {sp.Symbol(n, real=True): STATE_LATEX[i] for i, n in enumerate(STATE_NAMES)}
    for name in input_names:  # taps (u_R__tap1) are written as their input
        names[sp.Symbol(name, real=True)] = input_latex(base_input(name), delays.get(name, 0))
    return sp.latex(round_constants(expr, digits), symbol_names=names)


def expr_string(expr: sp.Expr) -> str:
    """A sympy-parsable string with full-precision constants."""
    return sp.sstr(expr, full_prec=True)


def parse_equation(text: str, input_names, *, source: str = "equation") -> tuple[sp.Expr, dict]:
    """Parse '10.3*u_R(t-1) - 4.15*p' into (sympy expr, {'u_R': 1}) with the equations' own
    parser (gpquad.engine.tree.arithmetic: the text is never evaluated as Python).

    Inputs may be written name(t-k) for a delay of k samples. An input written at several
    delays (u_R(t-1) - u_R(t-3)) takes one tap per delay (gpquad.engine.taps): the first
    delay is the input's own symbol, the next ones u_R__tap1, ... Unknown names are errors.
    """
    delays: dict[str, int] = {}
    syms = symbols_for(tap_names(input_names, MAX_TAPS))

    def leaf(name: str, k: int | None) -> sp.Symbol:
        if name not in input_names:
            if k is not None:
                raise GpquadError(
                    f"'{name}(t-{k})': only inputs {list(input_names)} take a delay", source=source
                )
            if name not in syms:
                raise GpquadError(
                    f"unknown names ['{name}'] in '{text}'; variables are "
                    f"{list(terminal_names(input_names))}",
                    source=source,
                )
            return syms[name]
        k = k or 0
        for tap in range(MAX_TAPS):
            if delays.setdefault(tap_name(name, tap), k) == k:
                return syms[tap_name(name, tap)]
        raise GpquadError(f"input {name} appears with more than {MAX_TAPS} delays", source=source)

    return parse_arithmetic(text, leaf, source=source), delays


#: Largest tree from_sympy builds (a bound on what a hand-written equation may expand to).
MAX_ENCODED_NODES = 4095


class TreeTooLarge(GpquadError):
    """from_sympy's expression needs more than MAX_ENCODED_NODES tree nodes."""


def from_sympy(expr: sp.Expr, delays: dict[str, int], input_names) -> Tree:
    """Encode a sympy expression of + - * / (integer powers allowed) as a Tree; `delays`
    may hold taps (u_R__tap1, gpquad.engine.taps), which widen the tree's delay slots.
    Text is not accepted (parse it with parse_equation or gpquad.engine.tree.arithmetic)."""
    if isinstance(expr, (int, float)):
        expr = sp.Float(expr)
    if not isinstance(expr, sp.Basic):
        raise TypeError(f"from_sympy takes a sympy expression, not {type(expr).__name__}")
    leaves = tap_names(input_names, 1 + max((tap_index(n) for n in delays), default=0))
    index = {name: VAR_BASE + i for i, name in enumerate(terminal_names(leaves))}
    codes: list[int] = []
    values: list[float] = []

    def leaf(value: float):
        codes.append(CONST)
        values.append(float(value))

    def emit(e):
        if len(codes) > MAX_ENCODED_NODES:
            raise TreeTooLarge(f"the equation expands to more than {MAX_ENCODED_NODES} tree nodes")
        if e.is_Number:
            if not np.isfinite(float(e)):
                raise GpquadError(f"'{e}' is not a finite number")
            leaf(float(e))
        elif e.is_Symbol:
            if str(e) not in index:
                raise GpquadError(f"unknown name '{e}'; variables are {list(index)}")
            codes.append(index[str(e)])
            values.append(0.0)
        elif e.is_Add or e.is_Mul:
            args = list(e.args)
            op = ADD if e.is_Add else MUL
            for _ in range(len(args) - 1):
                codes.append(op)
                values.append(0.0)
            for a in args:
                emit(a)
        elif e.is_Pow and e.exp.is_Integer:
            n = int(e.exp)
            if n < 0:
                codes.append(DIV)
                values.append(0.0)
                leaf(1.0)
                emit(e.base ** (-n))
            elif n == 0:
                leaf(1.0)
            else:
                for _ in range(n - 1):
                    codes.append(MUL)
                    values.append(0.0)
                for _ in range(n):
                    emit(e.base)
        else:
            raise GpquadError(f"'{e}' uses an operation outside + - * / and integer powers")

    emit(expr)
    delay_array = np.array([int(delays.get(n, 0)) for n in leaves], dtype=np.int64)
    return Tree.from_lists(codes, values, delay_array)


__all__ = ["to_sympy", "simplify", "to_latex", "expr_string", "parse_equation", "from_sympy"]
