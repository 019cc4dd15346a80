"""Equations of a left-right symmetric vehicle (the "symmetrize" finishing step).

Each equation's terms of the wrong left-right parity (gpquad.models.symmetry) are removed,
constants excepted (a constant in p_dot may be a real offset: a centre of gravity off the
axis, a trim that is not the vehicle's neutral), and the remaining constants refitted by
Levenberg-Marquardt through the integrator on the training windows, the equation flown
alone with the other accelerations from the data, as the search fits them. Runs before the
stability repair; the report (model.json `symmetrized`) lists what each equation lost.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import sympy as sp

from gpquad.engine.evolve.evaluator import Evaluator
from gpquad.engine.evolve.gradient_fit import gauss_newton_constants
from gpquad.engine.evolve.lm import FTOL
from gpquad.engine.evolve.windows import tile
from gpquad.engine.taps import taps_of, with_taps
from gpquad.engine.tree.export import from_sympy, round_constants
from gpquad.models.symmetry import wrong_parity

#: Levenberg-Marquardt evaluations of the refit (each flies every training window once).
REFIT_STEPS = 40


def without_wrong_parity(equation, flipped) -> tuple[sp.Expr, list[str]] | None:
    """(the equation without its wrong-parity terms, those terms) or None if it has none."""
    keep, dropped = [], []
    for term in sp.Add.make_args(sp.expand(equation.sympy())):
        rest = term.as_coeff_Mul()[1]
        if rest == 1 or not wrong_parity(equation.target, str(rest), flipped):
            keep.append(term)
        else:
            dropped.append(
                str(round_constants(term, equation.digits).xreplace(equation.shown_inputs()))
            )
    if not dropped:
        return None
    return sp.Add(*keep) if keep else sp.Float(0.0), dropped


def refit(equation, tree, dataset, evolution):
    """The tree with its constants fitted through the integrator on the training windows,
    and its training error (the search's metric)."""
    taps = taps_of(len(tree.delays), len(equation.input_names))
    cfg = evolution.for_target(equation.target)  # the search's evaluator for this target
    window_steps = cfg.window_steps(dataset.dt)
    ev = Evaluator(
        with_taps(dataset, taps),
        equation.target,
        window_steps,
        cfg.metric,
        cfg.max_depth,
        integrator=cfg.integrator,
        substeps=cfg.substeps,
    )
    starts, steps = tile(dataset.train, window_steps, evolution.max_delay)

    def error_of(t) -> float:
        return float(ev.window_errors([t], starts, n_steps=steps).mean())

    start_error = error_of(tree)
    return gauss_newton_constants(ev, tree, start_error, starts, steps, error_of, REFIT_STEPS, FTOL)


def symmetrize_equation(equation, dataset, evolution, flipped):
    """(the equation without its wrong-parity terms, constants refitted, its report entry
    {"dropped": [term texts], "error_after": training error after the refit}), or None
    when it has no such term."""
    found = without_wrong_parity(equation, frozenset(flipped))
    if found is None:
        return None
    expr, dropped = found
    tree = from_sympy(expr, equation.used_delays(), equation.input_names)
    tree, error = refit(equation, tree, dataset, evolution)
    return (
        dataclasses.replace(equation, tree=tree, error=float(error), validation_error=np.nan),
        {"dropped": dropped, "error_after": float(error)},
    )


def symmetrize(model, dataset, evolution, flipped, each=None):
    """(model, report): every equation without its wrong-parity terms, constants refitted
    (symmetrize_equation); report {target: entry} for the equations that lost a term.
    each(kind, equation, compute), if given: how an equation's result is had
    (gpquad.models.early_finish.EarlyFinish: taken from the work begun during the searches
    where its input is the same); else it is computed."""
    equations, report = dict(model.equations), {}
    for target, equation in model.equations.items():

        def compute(e):
            return symmetrize_equation(e, dataset, evolution, flipped)

        done = compute(equation) if each is None else each("symmetrize", equation, compute)
        if done is not None:
            equations[target], report[target] = done
    return dataclasses.replace(model, equations=equations), report


def symmetrized_summary(report: dict) -> str:
    """One line for the user: which equations lost which terms."""
    if not report:
        return "symmetric equations: no equation had a term of the wrong left-right parity"
    parts = [f"{target} without {', '.join(entry['dropped'])}" for target, entry in report.items()]
    return f"symmetric equations (terms of the wrong left-right parity removed): {'; '.join(parts)}"
