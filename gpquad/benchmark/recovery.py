"""Exact-structure recovery of a peer's equations (gpquad's own use gpquad.models.analysis).

The rule is `gpquad.models.analysis.compare_to_truth`'s: the equation, written in the log's raw
inputs and expanded, keeps its terms whose RMS on the training samples is at least 2 % of
the target's RMS (its dominant structure); it recovers the truth when those terms are
exactly the truth's terms, with the truth's input delays (u_R(t-1) is the lag-1 feature
u_R_l1), and every coefficient is within 5 %.
"""

from __future__ import annotations

import numpy as np
import sympy as sp

from gpquad.benchmark.rollout import MAX_LAG, lagged_inputs, lagged_names
from gpquad.engine.taps import base_input
from gpquad.engine.tree.arithmetic import parse_in_symbols
from gpquad.engine.tree.export import parse_equation
from gpquad.engine.variables import STATE_NAMES, target_index
from gpquad.errors import GpquadError

SHARE = 0.02
REL_TOL = 0.05


def _symbols(input_names) -> dict[str, sp.Symbol]:
    names = list(STATE_NAMES) + lagged_names(input_names)
    return {n: sp.Symbol(n, real=True) for n in names}


def truth_terms(truth: str, input_names) -> dict[str, float]:
    """{term: coefficient} of a truth equation in lagged-feature names (raw inputs)."""
    expr, delays = parse_equation(truth, tuple(input_names))
    reps = {
        sp.Symbol(n, real=True): sp.Symbol(f"{base_input(n)}_l{delays.get(n, 0)}", real=True)
        for n in set(input_names) | set(delays)
    }
    return _terms(sp.expand(expr.xreplace(reps)))


def _terms(expr) -> dict[str, float]:
    out = {}
    for term in sp.Add.make_args(expr):
        coeff, rest = term.as_coeff_Mul()
        out[str(rest)] = out.get(str(rest), 0.0) + float(coeff)
    return out


def dominant_terms(text: str, target: str, dataset) -> dict[str, float]:
    """{term: coefficient} of the terms of an equation (features, trim-subtracted inputs)
    whose RMS share on the training samples is >= SHARE, in raw inputs."""
    syms = _symbols(dataset.input_names)
    expr = parse_in_symbols(text, syms, caret_power=True)
    raw = {
        syms[f"{n}_l{lag}"]: syms[f"{n}_l{lag}"] - dataset.trim.get(n, 0.0)
        for n in dataset.input_names
        for lag in range(MAX_LAG + 1)
        if dataset.trim.get(n, 0.0)
    }
    expr = sp.expand(expr.xreplace(raw))
    rows = np.concatenate(
        [np.arange(a + MAX_LAG, b - 1) for a, b in dataset.train if b - 1 > a + MAX_LAG]
    )
    trim = np.array([[dataset.trim.get(n, 0.0)] * (MAX_LAG + 1) for n in dataset.input_names])
    values = np.hstack(
        [dataset.arrays.states[rows], lagged_inputs(dataset.arrays.inputs, rows) + trim.reshape(-1)]
    )
    columns = dict(zip(syms, values.T))
    target_rms = float(np.sqrt(np.mean(dataset.arrays.acc[rows, target_index(target)] ** 2)))
    found = {}
    for term in sp.Add.make_args(expr):
        coeff, rest = term.as_coeff_Mul()
        symbols = sorted(rest.free_symbols, key=str)
        func = sp.lambdify(symbols, rest, "numpy")
        with np.errstate(all="ignore"):
            series = np.broadcast_to(
                np.asarray(func(*[columns[str(s)] for s in symbols]), float), rows.shape
            )
        rms = float(np.sqrt(np.mean((float(coeff) * series) ** 2)))
        if target_rms > 0 and rms / target_rms >= SHARE:
            found[str(rest)] = found.get(str(rest), 0.0) + float(coeff)
    return found


def recovered(text: str, truth: str, target: str, dataset) -> bool:
    """Whether an equation's dominant structure is exactly the truth's (see module doc)."""
    expected = truth_terms(truth, dataset.input_names)
    try:
        found = dominant_terms(text, target, dataset)
    except (GpquadError, TypeError, KeyError, ZeroDivisionError):
        return False
    if set(found) != set(expected):
        return False
    return all(abs(found[t] - c) <= REL_TOL * abs(c) for t, c in expected.items())
