"""Which terms of an equation matter: contributions on the data, and dominant structure.

A discovered equation often carries tiny extra terms. Each additive term of the
expanded equation is evaluated on the training samples and its RMS is compared
with the RMS of the data's acceleration for that target; terms above a share
threshold form the equation's dominant structure (used to compare runs and to
check recovery of a known model).
"""

from __future__ import annotations

import numpy as np
import sympy as sp

from gpquad.data.dataset import Dataset
from gpquad.engine.variables import STATE_NAMES, target_index
from gpquad.models.equations import Equation


def _samples(dataset: Dataset, max_delay: int) -> np.ndarray:
    return np.concatenate([np.arange(a + max_delay, b - 1) for a, b in dataset.train])


def term_series(eq: Equation, dataset: Dataset, raw: bool = True):
    """(terms, target RMS): every additive term of the expanded equation as (term, coefficient,
    values of coefficient * term on the training samples), and the RMS of the data's
    acceleration for the target on those samples. raw=True: in the log's raw inputs (trim
    added back)."""
    expr = sp.expand(eq.sympy_raw() if raw else eq.sympy())
    delays = eq.delays
    idx = _samples(dataset, max(delays.values(), default=0))
    values = {}
    for k, name in enumerate(STATE_NAMES):
        values[name] = dataset.arrays.states[idx, k]
    n_in = len(eq.input_names)
    for j, name in enumerate(eq.leaf_names):  # inputs, then their taps
        column = dataset.arrays.inputs[idx - delays[name], j % n_in]
        values[name] = column + (dataset.trim.get(eq.input_names[j % n_in], 0.0) if raw else 0.0)
    target_rms = float(np.sqrt(np.mean(dataset.arrays.acc[idx, target_index(eq.target)] ** 2)))
    terms = []
    for term in sp.Add.make_args(expr):
        coeff, rest = term.as_coeff_Mul()
        symbols = sorted(rest.free_symbols, key=str)
        func = sp.lambdify(symbols, rest, "numpy")
        series = np.broadcast_to(
            np.asarray(func(*[values[str(s)] for s in symbols]), float), idx.shape
        )
        terms.append((str(rest), float(coeff), float(coeff) * series))
    return terms, target_rms


def term_contributions(eq: Equation, dataset: Dataset, raw: bool = True) -> list[dict]:
    """Every additive term with its coefficient and RMS share of the target's RMS.

    raw=True analyses the equation in the log's raw inputs (trim added back).
    Returns dicts {term, coefficient, share}, largest share first.
    """
    terms, target_rms = term_series(eq, dataset, raw)
    rows = []
    for term, coeff, series in terms:
        rms = float(np.sqrt(np.mean(series**2)))
        rows.append(
            {
                "term": term,
                "coefficient": coeff,
                "share": rms / target_rms if target_rms > 0 else np.inf,
            }
        )
    return sorted(rows, key=lambda r: -r["share"])


def dominant_structure(
    eq: Equation, dataset: Dataset, threshold: float = 0.02, raw: bool = True
) -> dict[str, float]:
    """{term: coefficient} of the terms whose RMS share is at least `threshold`."""
    return {
        r["term"]: r["coefficient"]
        for r in term_contributions(eq, dataset, raw)
        if r["share"] >= threshold
    }


def compare_to_truth(
    eq: Equation, truth: str, dataset: Dataset, rel_tol: float = 0.05, threshold: float = 0.02
) -> dict:
    """Did `eq` recover a known equation (text like '10.3*u_R(t-1) - 4.15*p')?

    Passes when its dominant structure (raw inputs) has exactly the truth's terms, every
    input of the truth has the truth's delay, and every coefficient is within rel_tol.
    """
    from gpquad.engine.tree.export import parse_equation

    truth_expr, truth_delays = parse_equation(truth, eq.input_names)
    expected = {}
    for term in sp.Add.make_args(sp.expand(truth_expr)):
        coeff, rest = term.as_coeff_Mul()
        expected[str(rest)] = float(coeff)
    found = dominant_structure(eq, dataset, threshold, raw=True)
    truth_inputs = {str(s) for s in truth_expr.free_symbols} & set(eq.input_names)
    delays = {n: eq.delays[n] for n in truth_inputs}
    wanted = {n: truth_delays.get(n, 0) for n in truth_inputs}
    errors = {t: abs(found[t] - c) / abs(c) for t, c in expected.items() if t in found}
    same_structure = set(found) == set(expected)
    passed = same_structure and delays == wanted and max(errors.values(), default=0) <= rel_tol
    return {
        "passed": bool(passed),
        "same_structure": same_structure,
        "found": found,
        "expected": expected,
        "delays": delays,
        "expected_delays": wanted,
        "relative_errors": errors,
    }
