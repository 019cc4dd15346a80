"""Terms that earn their place on validation flights (part of the "refine" finishing step).

An equation may hold FREE_TERMS terms on the strength of its training windows alone; beyond
that, every term must lower the error on the validation flights, which the fit did not see.
Measured on rotorpy's noisy angle-mode flights (issue 32): the recommended engine returned a
20-term r_dot and a roll equation of set-point taps alone, which flew the 10 s training
windows and drifted over 30 s on flights it had not seen.

`earn_terms` removes terms one at a time while more than FREE_TERMS are left: each term's
removal is screened by the validation error of the rest (its constants as fitted), the
DROP_SCREENED best are refitted through the integrator on the training windows, and the
refit with the lowest validation error replaces the equation if it is at most `gain`
(term_min_gain of the error) worse than with the term: a term that does not lower the
validation error by more than that has not earned its place.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import sympy as sp

#: Terms an equation may hold without earning them on validation flights.
FREE_TERMS = 12
#: Removals refitted through the integrator per step (the best by the validation screen).
DROP_SCREENED = 3


def earn_terms(
    problem, expr: sp.Expr, validation, gain: Callable[[float], float], current: float
) -> tuple[sp.Expr, list[sp.Expr], float]:
    """(expr with the terms beyond FREE_TERMS that did not earn their place removed and its
    constants refitted, the removed monomials, its validation error).

    problem: a gpquad.models.refine_problem.RefineProblem (fit, error, tree); expr: the equation
    expanded with taps; validation: the dataset's validation ranges; gain(error): the least
    validation improvement a term must bring; current: expr's validation error (the caller
    has flown it).
    """
    terms = list(sp.Add.make_args(sp.expand(expr)))
    dropped: list[sp.Expr] = []
    while len(terms) > FREE_TERMS and np.isfinite(current):
        rests = [sp.Add(*(terms[:i] + terms[i + 1 :])) for i in range(len(terms))]
        screened = [problem.error(problem.tree(rest), validation) for rest in rests]
        order = np.argsort(np.where(np.isfinite(screened), screened, np.inf), kind="stable")
        best = None
        for i in order[:DROP_SCREENED]:
            fitted, _ = problem.fit(rests[i])
            error = problem.error(problem.tree(fitted), validation)
            if np.isfinite(error) and (best is None or error < best[0]):
                best = (error, int(i), fitted)
        if best is None or not best[0] < current + gain(current):
            break
        current = best[0]
        dropped.append(terms[best[1]].as_coeff_Mul()[1])
        terms = list(sp.Add.make_args(sp.expand(best[2])))
    return sp.Add(*terms), dropped, current
