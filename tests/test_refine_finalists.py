"""The refinement's term steps fit every screened candidate once (its direct LM fit) and
only the best FINALISTS of them with the growing horizon as well (gpquad.models.refine)."""

import numpy as np
import pytest
import sympy as sp
from conftest import truth_dataset
from test_refine import FLIP, R_DOT, TRUTH, evolution
from test_stability import model_of

from gpquad.models import refine as refine_module
from gpquad.models import refine_problem
from gpquad.models.refine import finalists_of, refine_equation, warm_start
from gpquad.models.refine_problem import Fitted, RefineProblem

TERM = sp.Symbol("u_P__tap2", real=True) * sp.Symbol("u_R__tap1", real=True)


@pytest.fixture(scope="module")
def dataset():
    return truth_dataset({"r_dot": R_DOT}, duration_s=120.0, seed=11)


@pytest.fixture(scope="module")
def found(dataset):
    return model_of({"r_dot": TRUTH["r_dot"]}, dataset).equations["r_dot"]


def start(problem, found, scale: float) -> sp.Expr:
    """The found equation with its constants scaled, the missing term warm-started."""
    expr = problem.canonical(found)
    expr = expr.xreplace({c: c * scale for c in expr.atoms(sp.Float)})
    return warm_start(expr, TERM, problem.values(TERM), problem.residual(expr))


def test_a_fit_continued_from_its_direct_fit_is_the_fit_made_whole(dataset, found, monkeypatch):
    """fit(expr, direct_fit(expr)) repeats no work and gives fit(expr) to the bit; given
    another direct fit that the growing horizon does not beat (the bad case), that one is
    the result: nothing is fitted from expr again."""
    problem = RefineProblem(found, dataset, evolution())
    expr = start(problem, found, 0.7)
    whole = problem.fit(expr)
    direct = problem.direct_fit(expr)
    calls = []
    original = refine_problem.gauss_newton_constants

    def counted(*args, **kwargs):
        calls.append(1)
        return original(*args, **kwargs)

    monkeypatch.setattr(refine_problem, "gauss_newton_constants", counted)
    continued = problem.fit(expr, direct)
    assert continued[1] == whole[1]
    assert sp.srepr(continued[0]) == sp.srepr(whole[0])
    assert not calls  # the direct fit was not made again
    assert direct.error >= whole[1]  # the growing horizon can only add a better fit
    # the bad case: another first fit, better than the growing horizon's, is what it returns
    other = problem.tree(start(problem, found, 1.3))
    fake = Fitted(problem.expr(other), 0.0, (other, 0.0))
    assert sp.srepr(problem.fit(expr, fake)[0]) == sp.srepr(problem.expr(other))


def test_the_finalists_are_the_lowest_finite_errors_in_their_order():
    assert finalists_of([3.0, 1.0, np.inf, 2.0, np.nan, 0.5]) == [1, 5]
    assert finalists_of([1.0, 1.0, 1.0]) == [0, 1]
    assert finalists_of([np.inf, 4.0]) == [1]
    assert finalists_of([np.nan, np.inf]) == []


def test_a_step_fits_only_its_finalists_whole_and_finds_the_same_term(dataset, found, monkeypatch):
    """With every screened candidate fitted whole (FINALISTS = SCREENED) the refinement
    finds the same term and constants; with the default, no step fits more than FINALISTS
    candidates with the growing horizon."""
    whole_fits = []
    original = RefineProblem.fit

    def counted(self, expr, direct=None):
        if direct is not None:
            whole_fits.append(1)
        return original(self, expr, direct)

    monkeypatch.setattr(RefineProblem, "fit", counted)
    refined, report = refine_equation(found, dataset, evolution(1), FLIP)
    assert report["added"] == ["u_P(t-2)*u_R(t-1)"]
    assert 1 <= len(whole_fits) <= refine_module.FINALISTS  # one step: 6 screened
    whole_fits.clear()
    default = refine_module.FINALISTS
    monkeypatch.setattr(refine_module, "FINALISTS", refine_module.SCREENED)
    everyone, everyone_report = refine_equation(found, dataset, evolution(1), FLIP)
    assert len(whole_fits) > default  # the bad case: all six fitted whole
    assert everyone_report["added"] == report["added"]
    assert np.array_equal(everyone.tree.values, refined.tree.values)


def test_a_finalist_whose_direct_fit_stays_best_is_not_polished_again(dataset, found, monkeypatch):
    """Where the growing horizon does not beat the direct fit, the finalist's result is its
    direct fit as `direct_fit` polished it, and no fit in the finer scheme is made again;
    where it does (the bad case for reuse), that fit is polished."""
    problem = RefineProblem(found, dataset, evolution())
    expr = start(problem, found, 0.7)
    finer = problem._evaluator("rk4", 2)
    monkeypatch.setattr(problem, "fitting", lambda e: finer)
    direct = problem.direct_fit(expr)
    polishes = []
    original = problem._direct

    def recorded(ev, tree):
        polishes.append(ev.substeps)
        return original(ev, tree)

    monkeypatch.setattr(problem, "_direct", recorded)
    monkeypatch.setattr(refine_problem, "continued_constants", lambda *a, direct, **k: direct)
    assert problem.fit(expr, direct) == (direct.expr, direct.error)
    assert not polishes
    grown = problem.tree(start(problem, found, 0.9))
    monkeypatch.setattr(refine_problem, "continued_constants", lambda *a, direct, **k: (grown, 1.0))
    problem.fit(expr, direct)
    assert polishes == [2]


def test_every_refinement_fit_stops_by_the_refinements_stall_rule(dataset, found, monkeypatch):
    """The direct fits and the growing horizon's (continued_constants) both get
    refine_problem.STALL, not the selection's tighter lm.STALL: a stiff loop's polish
    creeps on by a fraction of a percent a step (docs/decisions/2026-11-27-stiff-polish.md).
    Bad cases: a direct fit, or a growing horizon, wired to lm.STALL is seen."""
    from gpquad.engine.evolve import gradient_fit, lm

    def rules_of_a_fit() -> set:
        rules = []
        original = gradient_fit.levenberg_marquardt

        def recorded(*args, stall=None, **kwargs):
            rules.append(stall)
            return original(*args, stall=stall, **kwargs)

        with monkeypatch.context() as patch:
            patch.setattr(gradient_fit, "levenberg_marquardt", recorded)
            problem = RefineProblem(found, dataset, evolution())
            problem.fit(start(problem, found, 0.7))
        assert len(rules) >= 2  # the direct fit and the growing horizon's
        return set(rules)

    assert refine_problem.STALL != lm.STALL
    assert rules_of_a_fit() == {refine_problem.STALL}
    grown = refine_problem.continued_constants
    with monkeypatch.context() as patch:  # the growing horizon's fits wired to lm.STALL
        patch.setattr(
            refine_problem,
            "continued_constants",
            lambda *args, direct: grown(*args[:-1], lm.STALL, direct=direct),
        )
        assert rules_of_a_fit() != {refine_problem.STALL}
    direct = refine_problem.gauss_newton_constants
    monkeypatch.setattr(  # the direct fits wired to lm.STALL
        refine_problem,
        "gauss_newton_constants",
        lambda *args: direct(*args[:-1], lm.STALL),  # the stall rule is the last argument
    )
    assert rules_of_a_fit() != {refine_problem.STALL}


def test_a_stiff_starts_first_fit_only_finds_its_basin(dataset, found, monkeypatch):
    """Where the start's loop needs a finer scheme than the search's, its direct fit in the
    search's scheme gets BASIN_STEPS evaluations and the polish in the finer scheme
    FIT_STEPS; a start that needs no finer scheme gets FIT_STEPS (the bad case for the cut:
    nothing polishes it after)."""
    problem = RefineProblem(found, dataset, evolution())
    expr = start(problem, found, 0.7)
    budgets = []
    original = refine_problem.gauss_newton_constants

    def recorded(ev, *args):
        budgets.append((ev.substeps, args[5]))  # (steps per sample, the fit's evaluations)
        return original(ev, *args)

    monkeypatch.setattr(refine_problem, "gauss_newton_constants", recorded)
    problem.direct_fit(expr)
    assert problem.fitting(expr) is problem.ev
    assert budgets == [(1, refine_problem.FIT_STEPS)]
    finer = problem._evaluator("rk4", 2)
    monkeypatch.setattr(problem, "fitting", lambda e: finer)
    budgets.clear()
    problem.direct_fit(expr)
    assert budgets == [(1, refine_problem.BASIN_STEPS), (2, refine_problem.FIT_STEPS)]
    assert refine_problem.BASIN_STEPS < refine_problem.FIT_STEPS
