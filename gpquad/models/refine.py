"""Refined equations: a first-order lag and greedy product terms after the search
(the "refine" finishing step, `evolution.refine_terms`; not in the paper).

A parsimonious search with depth 7 finds the loop of a closed-loop rate equation but not
what a controller's attitude error adds to it through a motor's lag: on rotorpy's
crazyflie (angle mode, 72 ms motors) r_dot needs the yaw part of the SO(3) error, products
of the roll and pitch set-points at several delays, filtered by the motors
(docs/decisions). This step gives each found equation, flown alone through the integrator:

0. beyond FREE_TERMS terms, those that do not lower the validation error are removed
   (gpquad.models.earned); the found equation is then no longer a choice of step 3;
1. a lag, tau da/dt + a = expr (gpquad.engine.lag): the taus of LAG_GRID are tried from
   the smallest up until two in a row do no better (gpquad.models.lag_fit.choose_lag), the
   equation's own terms refitted (one-step least squares on the inverse-filtered target,
   then Levenberg-Marquardt through the integrator with a growing horizon); a lag is kept
   when it lowers the training error by more than term_min_gain (relative);
2. up to `refine_terms` new terms, one at a time: every product of two of the states (not
   psi) and input taps at delays 0..max_delay, and every tap alone, is screened by how much
   of the one-step residual it explains beyond the equation's terms; the SCREENED best are
   fitted through the integrator (all constants, from the equation's own and the term's
   one-step coefficient on its residual) by one LM fit, the FINALISTS best of them again
   with a growing horizon (RefineProblem.fit), and the best is kept while it lowers the
   training error by more than term_min_gain. With `mirror_inputs`, terms of the wrong
   left-right parity are not offered (gpquad.models.symmetry);
3. of the equations on that path (the found one first), the one with the lowest validation
   error replaces the found one: early stopping on flights the fit did not see. With the
   continuous-time engine the validation flights are flown by RK4 with FIDELITY_SUBSTEPS
   steps per sample, as a reader's simulator flies the printed ODE: a stiff loop that holds
   only by the damping of one RK4 step per sample does not win there;
4. a chosen equation with a lag has its time constant fitted as well, every constant
   refitted (gpquad.models.lag_fit.polish_lag), and is replaced by that fit when it lowers
   the training error by more than term_min_gain and flies the validation windows better;
5. with all six equations, the six are flown together on the stability repair's windows
   (and their mirror images), and refinements are undone one at a time while that makes
   the full model fly better (keep_what_flies): each equation was refined flown alone, and
   a lagged stiff loop that flies alone can diverge beside the others.

model.json `refined` reports, per equation, the lag, the added terms and the errors.
"""

from __future__ import annotations

import dataclasses
import itertools
from typing import NamedTuple

import numpy as np
import sympy as sp

from gpquad.data.mirror import mirror_dataset
from gpquad.engine.evolve.selection import RSE_RESOLUTION
from gpquad.engine.taps import base_input
from gpquad.engine.threads import thread_map
from gpquad.engine.tree.export import round_constants
from gpquad.engine.variables import STATE_NAMES, TARGET_NAMES
from gpquad.models.earned import earn_terms
from gpquad.models.equation import Equation
from gpquad.models.joint_fit import CHECK_HORIZON_S, is_whole, judged_windows
from gpquad.models.lag_fit import choose_lag, polish_lag
from gpquad.models.refine_problem import RefineProblem, monomials
from gpquad.models.stability import FullModelFlights
from gpquad.models.symmetry import wrong_parity

#: Candidates fitted through the integrator per step (the best by the one-step screen).
SCREENED = 6
#: Of those, the ones fitted with the growing horizon as well (the best by their direct
#: fit): the winner of a step was among the best two by the direct fit in every step measured
#: (docs/decisions/2026-11-27-whole-benchmark.md).
FINALISTS = 2
#: Errors below this fraction of the zero equation's count as flown exactly, the
#: selection's resolution (selection.RSE_RESOLUTION): a found equation there is kept as
#: found, and a gain is term_min_gain of max(error, NEGLIGIBLE * zero error). Below it
#: what a refinement could fit is the scheme's error in the data's other states, held
#: over a sample, not the vehicle (docs/decisions/2026-11-26-refine-stall.md).
NEGLIGIBLE = RSE_RESOLUTION


class Step(NamedTuple):
    """One equation on the refinement's path."""

    lag: float  # s
    expr: sp.Expr
    error: float  # training windows
    validation: float  # validation windows
    added: list  # the terms added so far
    dropped: tuple = ()  # the found equation's terms that did not earn their place


def library(problem: RefineProblem, flipped) -> list[sp.Expr]:
    """Every input tap, and every product of two of the states (not psi) and taps; without
    the wrong left-right parity when `flipped` names the mirrored inputs."""
    states = [sp.Symbol(n, real=True) for n in STATE_NAMES if n != "psi"]
    taps = [sp.Symbol(n, real=True) for n in problem.delays]
    terms = taps + [a * b for a, b in itertools.combinations_with_replacement(states + taps, 2)]
    if flipped:
        terms = [t for t in terms if not wrong_parity(problem.target, str(t), flipped)]
    return terms


def screen(
    problem: RefineProblem,
    expr: sp.Expr,
    residual: np.ndarray,
    columns: np.ndarray,
    offered: np.ndarray,
) -> list[int]:
    """Indices of the SCREENED columns among `offered` (bool, one per column) that explain
    most of `expr`'s one-step residual beyond the span of its own monomials."""
    own = np.column_stack([problem.values(m) for m in monomials(expr)])
    q, _ = np.linalg.qr(own)
    residual = residual - q @ (q.T @ residual)
    projected = columns - q @ (q.T @ columns)
    norms = (projected**2).sum(axis=0)
    score = np.where(
        offered & (norms > 1e-12 * max(norms.max(), 1e-300)),
        (projected.T @ residual) ** 2 / np.maximum(norms, 1e-300),
        0.0,
    )
    return [int(k) for k in np.argsort(-score, kind="stable")[:SCREENED] if score[k] > 0]


def finalists_of(errors) -> list[int]:
    """Indices of the FINALISTS lowest finite errors, in the order given."""
    errors = np.asarray(errors, dtype=float)
    order = np.argsort(np.where(np.isfinite(errors), errors, np.inf), kind="stable")
    return sorted(int(i) for i in order[:FINALISTS] if np.isfinite(errors[i]))


def warm_start(expr: sp.Expr, term: sp.Expr, column: np.ndarray, residual: np.ndarray) -> sp.Expr:
    """expr + c term, c the term's one-step least-squares coefficient on expr's residual:
    the equation keeps the constants it was fitted with through the integrator. (Refitting
    every constant by one-step least squares instead, the one-step fit a stiff closed loop
    does not have, stopped rotorpy-angle crazyflie seed 1's r_dot after 4 terms at
    validation error 0.022; from here it went on to 0.0092.)"""
    c = float(column @ residual / max(float(column @ column), 1e-300))
    return expr + sp.Float(c) * term


def takes_fitted_lag(chosen: Step, fitted: Step, gain: float) -> bool:
    """Whether the lag fit's step replaces the chosen one: a training error lower by more
    than `gain` (as any step of the path must earn) and a lower validation error."""
    return (
        fitted.error < chosen.error - gain
        and bool(np.isfinite(fitted.validation))
        and fitted.validation < chosen.validation
    )


def refine_equation(equation, dataset, evolution, flipped=(), workers: int = 1):
    """(equation, report): the found equation's lag and added terms (module notes), or the
    found equation itself when no refinement flies the validation windows better. workers:
    threads for the candidates of a step (the same result for any number)."""
    n_terms = evolution.refine_for(equation.target)
    min_gain = evolution.term_min_gain
    problem = RefineProblem(equation, dataset, evolution)
    found = problem.canonical(equation)
    found_error = problem.error(problem.tree(found))
    path = [
        Step(0.0, found, found_error, problem.error(problem.tree(found), dataset.validation), [])
    ]
    if not np.isfinite(path[0].validation):  # nothing to judge a refinement on: not worth fitting
        return equation, {
            "lag": 0.0,
            "added": [],
            "error_before": found_error,
            "error_after": found_error,
            "validation_before": None,
            "validation_after": None,
            "tried": 0,
            "no_validation": True,
        }
    zero_error = problem.error(problem.tree(sp.Float(0.0)))

    def gain(err: float) -> float:  # the least improvement that counts
        return min_gain * max(err, NEGLIGIBLE * zero_error)

    if found_error <= NEGLIGIBLE * zero_error:  # flown within the resolution: nothing to try
        return equation, {
            "lag": 0.0,
            "added": [],
            "error_before": found_error,
            "error_after": found_error,
            "validation_before": path[0].validation,
            "validation_after": path[0].validation,
            "tried": 0,
        }
    expr, dropped, validation = earn_terms(
        problem, found, dataset.validation, gain, path[0].validation
    )
    error = problem.error(problem.tree(expr)) if dropped else found_error
    if dropped:  # the found equation is no longer a choice: its extra terms did not earn
        path.append(Step(0.0, expr, error, validation, [], tuple(dropped)))
    if problem.fitting(expr).substeps != problem.ev.substeps:
        # a stiff loop: its constants refitted with the steps per sample that fly it as the
        # ODE it prints (gpquad.models.stiffness)
        refit, refit_error = problem.fit(expr)
        if np.isfinite(refit_error):
            val = problem.error(problem.tree(refit), dataset.validation)
            path.append(Step(0.0, refit, refit_error, val, [], tuple(dropped)))
            expr, error = refit, refit_error
    tau, expr, error, grid_fits = choose_lag(problem, expr, error, gain(error), workers)
    lag_choice = expr
    if tau > 0:
        val = problem.error(problem.tree(expr), dataset.validation)
        path.append(Step(tau, expr, error, val, [], tuple(dropped)))
    added: list[sp.Expr] = []
    candidates = library(problem, frozenset(flipped))
    columns = np.column_stack([problem.values(c) for c in candidates])
    for _ in range(n_terms):
        own = set(monomials(expr))
        offered = np.array([c not in own for c in candidates])
        residual = problem.residual(expr)
        best = None
        screened = screen(problem, expr, residual, columns, offered)
        starts = [warm_start(expr, candidates[k], columns[:, k], residual) for k in screened]
        ranked = thread_map(problem.direct_fit, starts, workers)
        finalists = finalists_of([r.error for r in ranked])
        pairs = [(starts[i], ranked[i]) for i in finalists]
        fits = thread_map(lambda pair: problem.fit(*pair), pairs, workers)
        for i, (fitted, fitted_error) in zip(finalists, fits, strict=True):
            if best is None or fitted_error < best[1]:
                best = (fitted, fitted_error, candidates[screened[i]])
        if best is None or not best[1] < error - gain(error):
            break
        expr, error = best[0], best[1]
        added.append(best[2])
        val = problem.error(problem.tree(expr), dataset.validation)
        path.append(Step(tau, expr, error, val, list(added), tuple(dropped)))
    # path[0] (path[1] after earn_terms) has a finite validation error; a later step may not
    eligible = [p for p in path[1 if dropped else 0 :] if np.isfinite(p.validation)]
    chosen = min(eligible, key=lambda p: p.validation)
    chosen_problem = problem
    if chosen.lag > 0:  # the lag fitted as one more constant of the chosen equation
        # the grid's fits of the same terms are the polish's first trials
        known = grid_fits if chosen.expr is lag_choice else None
        polished = polish_lag(problem, chosen.expr, chosen.lag, chosen.error, workers, known)
        if polished[0] != chosen.lag:
            tau, expr, error, lagged = polished
            val = lagged.error(lagged.tree(expr), dataset.validation)
            path.append(Step(tau, expr, error, val, chosen.added, chosen.dropped))
            if takes_fitted_lag(chosen, path[-1], gain(chosen.error)):
                chosen, chosen_problem = path[-1], lagged
    report = {
        "lag": chosen.lag,
        "added": [text(equation, t) for t in chosen.added],
        "dropped": [text(equation, t) for t in chosen.dropped],
        "error_before": found_error,
        "error_after": chosen.error,
        "validation_before": path[0].validation,
        "validation_after": chosen.validation,
        "tried": len(path) - 1,
        "substeps": chosen_problem.fitting(chosen.expr).substeps,
    }
    if chosen is path[0]:
        return equation, report

    def as_equation(step: Step) -> Equation:
        return dataclasses.replace(
            equation,
            tree=problem.tree(step.expr),
            lag=float(step.lag),
            error=float(step.error),
            validation_error=float(step.validation),
            candidates=[],
        )

    # the found equation and the rest of the path become the first alternatives of the
    # stability repair: a refined equation that flies alone may diverge with the others
    others = [equation.summary()] + [as_equation(p).summary() for p in path[1:] if p is not chosen]
    refined = dataclasses.replace(as_equation(chosen), candidates=others + equation.candidates)
    return refined, report


def text(equation, term: sp.Expr) -> str:
    """A term as the equations print it: u_R__tap3 -> u_R(t-3)."""
    reps = {
        s: sp.Symbol(f"{base_input(str(s))}(t-{d})" if d else base_input(str(s)), real=True)
        for s in term.free_symbols
        for d in [int(str(s).rsplit("__tap", 1)[1]) if "__tap" in str(s) else 0]
    }
    return str(round_constants(term, equation.digits).xreplace(reps))


def refine(
    model, dataset, evolution, flipped=(), workers: int = 1, each=None
) -> tuple[object, dict]:
    """(model, report): every equation with `refine_terms` > 0 refined (module notes),
    then refinements the full model flies worse with reverted (keep_what_flies);
    report {target: refine_equation's report, with "reverted": true for those}.
    workers: threads that refine equations side by side (their fits release the GIL); each
    equation's refinement is its own, so the result is the same for any number.
    each(kind, equation, compute), if given: how an equation's refinement is had
    (gpquad.models.early_finish.EarlyFinish: taken from the work begun during the searches
    where its input is the same); else it is computed."""
    targets = [t for t in model.equations if evolution.refine_for(t) > 0]

    def one(target):
        def compute(e):
            return refine_equation(e, dataset, evolution, flipped, workers)

        found = model.equations[target]
        return compute(found) if each is None else each("refine", found, compute)

    results = thread_map(one, targets, workers)
    equations, report = dict(model.equations), {}
    for target, (equation, entry) in zip(targets, results, strict=True):
        equations[target], report[target] = equation, entry
    refined, reverted = keep_what_flies(
        dataclasses.replace(model, equations=equations), model, dataset, flipped
    )
    for target in reverted:
        report[target]["reverted"] = True
    return refined, report


def keep_what_flies(refined, found, dataset, mirror=()) -> tuple[object, list[str]]:
    """(model, reverted targets): each equation is refined flown alone, with the other
    accelerations from the data; flown together a lagged stiff loop can diverge. While
    putting one refined equation's found form back makes the six fly the stability repair's
    windows better (fewer diverged windows, then fewer diverged mirrored ones, then a lower
    full-model error), the best such reversion is made."""
    changed = [
        t
        for t in TARGET_NAMES
        if t in refined.equations and refined.equations[t] is not found.equations[t]
    ]
    if not changed or not is_whole(refined, dataset):
        return refined, []
    starts, steps, _ = judged_windows(dataset, refined, CHECK_HORIZON_S)
    if len(starts) == 0:
        return refined, []
    flights = FullModelFlights(dataset, starts, steps)
    mirrored = FullModelFlights(mirror_dataset(dataset, mirror), starts, steps) if mirror else None

    def score(model) -> tuple[int, int, float]:
        n_div, windows = flights.windows(model)
        n_mirror = mirrored.windows(model)[0] if mirrored is not None else 0
        error = float(windows.sum())
        return n_div, n_mirror, error if np.isfinite(error) else np.inf

    def reverted(model, target):
        return dataclasses.replace(
            model, equations={**model.equations, target: found.equations[target]}
        )

    current, out = score(refined), []
    while changed:
        best_score, target = min((score(reverted(refined, t)), t) for t in changed)
        if not best_score < current:
            break
        refined, current = reverted(refined, target), best_score
        changed.remove(target)
        out.append(target)
    return refined, out


def refined_summary(report: dict) -> str:
    """One line for the user: what each refined equation gained."""
    if not report:
        return "refined equations: none asked for"
    parts = []
    for target, entry in report.items():
        if entry.get("reverted"):
            parts.append(f"{target}: kept as found (refined, it made the full model fly worse)")
        elif entry.get("no_validation"):
            parts.append(
                f"{target}: kept as found (no validation window of window_s "
                "to judge a refinement on: raise data.validation_fraction or name "
                "validation files in data.validation)"
            )
        elif entry.get("dropped") or entry["validation_after"] < entry["validation_before"]:
            lag = f"lag {1000 * entry['lag']:.0f} ms, " if entry["lag"] > 0 else ""
            cut = f"-{len(entry['dropped'])} unearned " if entry.get("dropped") else ""
            fine = entry.get("substeps", 1)
            parts.append(
                f"{target}: {lag}{cut}+{len(entry['added'])} terms"
                + (f" (fitted at {fine} RK4 steps per sample)" if fine > 1 else "")
                + f", validation error {entry['validation_before']:.4g} -> "
                f"{entry['validation_after']:.4g}"
            )
        else:
            parts.append(f"{target}: kept as found")
    return "refined equations: " + "; ".join(parts)
