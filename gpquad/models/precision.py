"""How many significant digits a printed equation needs to stay the model.

Equations are printed (text, LaTeX, the report, benchmark cells) with rounded constants.
Three significant digits suffice for p_dot = -4.15 p + 10.3 u_R, not for a lag filter
whose taps nearly cancel, such as 1310 u_R - 2760 u_R(t-1) + 3420 u_R(t-2) - 3060 u_R(t-3)
+ 1510 u_R(t-4) - 417 u_R(t-5): its gain at low frequency is the sum of the coefficients,
3, and rounding each to 3 digits moves that sum by up to 25. On the benchmark's
rotorpy-angle models the 3-digit texts flew 1.5 to 3 times worse than the models at 7 s.

An equation's printed form is faithful when, on training samples of the data it was found
on, it differs from the model's own expression by at most TOLERANCE of the expression's
RMS value, and on average by at most BIAS_TOLERANCE of it: a bias is what a weakly damped
state integrates over a long flight (a rounded hover constant in a_z moves w for 30 s).
`printed_digits` is the least number of digits from MIN_DIGITS to MAX_DIGITS for which both
printed forms (trimmed and raw inputs) are; model.json keeps it and every printed form
uses it. The kernels and model.json's "prefix" always hold the full constants.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import sympy as sp

from gpquad.engine.taps import base_input
from gpquad.engine.tree.export import TreeTooLarge, from_sympy, round_constants
from gpquad.engine.variables import STATE_NAMES

TOLERANCE = 1e-3
BIAS_TOLERANCE = 1e-4
MIN_DIGITS, MAX_DIGITS = 3, 8
#: Training samples the printed and the exact expression are compared on.
SAMPLES = 2000


def sample_rows(ranges, max_delay: int, count: int = SAMPLES) -> np.ndarray:
    """Up to `count` sample indices spread evenly over `ranges`, each with max_delay samples
    of input history inside its range."""
    rows = np.concatenate(
        [np.arange(a + max_delay, b) for a, b in ranges if b > a + max_delay]
        or [np.zeros(0, dtype=np.int64)]
    )
    if len(rows) > count:
        rows = rows[np.linspace(0, len(rows) - 1, count).round().astype(np.int64)]
    return rows.astype(np.int64)


def sample_columns(equation, arrays, rows, raw: bool) -> dict[str, np.ndarray]:
    """Each variable of the equation at `rows`: states, and inputs at their delays (raw:
    with the trim added back)."""
    out = {n: arrays.states[rows, k] for k, n in enumerate(STATE_NAMES)}
    for name, delay in equation.delays.items():
        base = base_input(name)
        j = equation.input_names.index(base)
        out[name] = arrays.inputs[rows - delay, j] + (equation.trim.get(base, 0.0) if raw else 0.0)
    return out


def expression_values(expr: sp.Expr, columns: dict[str, np.ndarray], n: int) -> np.ndarray:
    symbols = sorted(expr.free_symbols, key=lambda s: s.name)
    func = sp.lambdify(symbols, expr, "numpy")
    with np.errstate(all="ignore"):
        return np.broadcast_to(np.asarray(func(*[columns[s.name] for s in symbols]), float), (n,))


def faithful(expr: sp.Expr, exact: np.ndarray, columns: dict[str, np.ndarray], digits: int) -> bool:
    """Whether `expr` rounded to `digits` stays within TOLERANCE x RMS of its own values
    `exact` (= expression_values(expr, columns)), and within BIAS_TOLERANCE x RMS of them
    on average."""
    finite = np.isfinite(exact)
    if not finite.any():
        return True
    rounded = expression_values(round_constants(expr, digits), columns, len(exact))
    scale = max(float(np.sqrt(np.mean(exact[finite] ** 2))), 1e-12)
    moved = rounded[finite] - exact[finite]
    return bool(
        np.max(np.abs(moved)) <= TOLERANCE * scale
        and abs(float(np.mean(moved))) <= BIAS_TOLERANCE * scale
    )


def printed_digits(equation, arrays, rows) -> int:
    """Least significant digits (MIN_DIGITS..MAX_DIGITS) that keep both printed forms of
    `equation` faithful on `rows` of `arrays` (a Dataset's arrays, trimmed inputs)."""
    forms = [(equation.sympy(), False)]
    if any(equation.trim.get(base_input(n), 0.0) for n in equation.delays):
        forms.append((equation.sympy_raw(), True))
    checks = []
    for expr, raw in forms:
        columns = sample_columns(equation, arrays, rows, raw)
        checks.append((expr, expression_values(expr, columns, len(rows)), columns))
    for digits in range(MIN_DIGITS, MAX_DIGITS + 1):
        if all(faithful(expr, exact, columns, digits) for expr, exact, columns in checks):
            return digits
    return MAX_DIGITS


def without_negligible_terms(equation, arrays, rows):
    """`equation` without the additive terms (of its expanded form) that together move its
    value by at most half of TOLERANCE x RMS on `rows`, smallest first: terms a fit drove
    to round-off (a coupling the search needed under eq. 2 and a continuous-time refit set
    to 1e-6) would otherwise be printed and exported. The same equation when none is, or
    when its expanded form is too large to encode (from_sympy's MAX_ENCODED_NODES)."""
    expr = sp.expand(equation.sympy())
    terms = sp.Add.make_args(expr)
    if len(terms) < 2:
        return equation
    columns = sample_columns(equation, arrays, rows, raw=False)
    values = [expression_values(term, columns, len(rows)) for term in terms]
    total = np.sum(values, axis=0)
    finite = np.isfinite(total)
    if not finite.any():
        return equation
    budget = 0.5 * TOLERANCE * float(np.sqrt(np.mean(total[finite] ** 2)))
    sizes = [float(np.max(np.abs(v[finite]))) for v in values]
    dropped: set[int] = set()
    moved = 0.0
    for k in sorted(range(len(terms)), key=lambda k: sizes[k]):
        if moved + sizes[k] > budget or len(dropped) == len(terms) - 1:
            break
        dropped.add(k)
        moved += sizes[k]
    if not dropped:
        return equation
    kept = sp.Add(*[t for k, t in enumerate(terms) if k not in dropped])
    try:
        tree = from_sympy(kept, equation.delays, equation.input_names)
    except TreeTooLarge:  # the expanded form of a product of sums: kept as found
        return equation
    return dataclasses.replace(equation, tree=tree)


def with_exact_raw_constant(equation, arrays, rows):
    """`equation` with its constant moved so that its raw form's constant is zero when that
    constant moves the equation by at most half of BIAS_TOLERANCE x RMS on `rows`: a fit
    leaves the trimmed constant of p_dot = 10.3 (u_R - trim) - 4.15 p at 1e-6 of its value,
    and the raw form would print the difference (+ 2.6e-8) as a constant the data do not
    have. The same equation otherwise, or when that form is too large to encode."""
    if not equation.trims():
        return equation
    expr = equation.sympy()
    constant = sum(equation.raw_constant_parts(expr))
    if constant == 0.0:
        return equation
    values = expression_values(expr, sample_columns(equation, arrays, rows, raw=False), len(rows))
    values = values[np.isfinite(values)]
    if not values.size:
        return equation
    if abs(constant) > 0.5 * BIAS_TOLERANCE * float(np.sqrt(np.mean(values**2))):
        return equation
    try:
        tree = from_sympy(expr - constant, equation.delays, equation.input_names)
    except TreeTooLarge:  # as without_negligible_terms
        return equation
    return dataclasses.replace(equation, tree=tree)


def model_rows(model, dataset) -> np.ndarray:
    """The training samples (else validation) on which a model's equations are compared."""
    max_delay = max((d for e in model.equations.values() for d in e.delays.values()), default=0)
    return sample_rows(dataset.train or dataset.validation, max_delay)


def without_negligible(model, dataset):
    """The model with each equation without its negligible terms (without_negligible_terms);
    the finishing steps start from it, so that they fit the terms that will be printed."""
    rows = model_rows(model, dataset)
    if len(rows) == 0:
        return model
    equations = {
        t: without_negligible_terms(e, dataset.arrays, rows) for t, e in model.equations.items()
    }
    return dataclasses.replace(model, equations=equations)


def with_printed_digits(model, dataset):
    """The model without negligible terms (without_negligible_terms), with raw constants
    that are negligible made zero (with_exact_raw_constant) and with each equation's
    `digits` set from the dataset's training samples."""
    rows = model_rows(model, dataset)
    if len(rows) == 0:
        return model
    model = without_negligible(model, dataset)
    exact = {
        t: with_exact_raw_constant(e, dataset.arrays, rows) for t, e in model.equations.items()
    }
    equations = {
        t: dataclasses.replace(e, digits=printed_digits(e, dataset.arrays, rows))
        for t, e in exact.items()
    }
    return dataclasses.replace(model, equations=equations)
