"""One equation's refinement problem (gpquad.models.refine): the data with one tap per
delay, the evaluators that fit it and judge it, its training windows and samples."""

from __future__ import annotations

import copy
from typing import NamedTuple

import numpy as np
import sympy as sp

from gpquad.data.score import readers_scheme
from gpquad.engine.evolve.evaluator import Evaluator
from gpquad.engine.evolve.gradient_fit import continued_constants, gauss_newton_constants
from gpquad.engine.evolve.lm import FTOL
from gpquad.engine.evolve.state import SEED_HORIZONS, SHORT_WINDOW_STEPS
from gpquad.engine.evolve.windows import spread, tile
from gpquad.engine.kernels.tree_eval import eval_on_samples
from gpquad.engine.taps import base_input, tap_name, with_taps
from gpquad.engine.tree.encoding import Tree, shallow_sum
from gpquad.engine.tree.export import from_sympy, to_sympy
from gpquad.engine.variables import target_index
from gpquad.models.stiffness import equation_substeps

#: Levenberg-Marquardt evaluations per fit (each flies every training window once).
FIT_STEPS = 40
#: The fits' stall rule (gpquad.engine.evolve.lm.levenberg_marquardt): a fit stops once
#: two steps taken together lowered the sum by at most 0.3 % of it, the tail of a stiff
#: loop's polish in its finer scheme, which creeps on for tens of steps; a term must earn
#: term_min_gain (1 % by default) (docs/decisions/2026-11-27-stiff-polish.md).
STALL = (2, 3e-3)
#: LM evaluations of a direct fit in the search's scheme when the loop it starts from needs
#: a finer one: there it only finds the basin that the polish in the finer scheme fits
#: (a fine fit from the start does not find it, docs/decisions/2026-11-27-refine-ranking.md),
#: while half its windows may diverge (docs/decisions/2026-11-27-stiff-polish.md).
BASIN_STEPS = 20
#: Training samples of the one-step screen and the least-squares starts (evenly spread):
#: the library's columns then take at most 560 x 20000 numbers whatever the log's length.
SCREEN_SAMPLES = 20000


class Fitted(NamedTuple):
    """RefineProblem.direct_fit's result: the fitted expression and its training error, and
    its first fit (tree, error), which `RefineProblem.fit` continues from."""

    expr: sp.Expr
    error: float
    first: tuple[Tree, float]


def monomials(expr: sp.Expr) -> list[sp.Expr]:
    """The expanded expression's monomials without their coefficients (1 for a constant)."""
    return [term.as_coeff_Mul()[1] for term in sp.Add.make_args(sp.expand(expr))]


class RefineProblem:
    """One equation's data for the refinement: the dataset with one tap per delay
    0..max_delay, the search's evaluator on it (`ev`, which fits), the evaluator that
    judges validation flights (`judge`: the scheme a reader flies the printed equations
    with, gpquad.data.score.readers_scheme), the training windows and samples."""

    def __init__(self, equation, dataset, evolution):
        cfg = evolution.for_target(equation.target)
        self.target = equation.target
        self.input_names = equation.input_names
        n_taps = cfg.max_delay + 1
        self.delays = {tap_name(n, d): d for d in range(n_taps) for n in self.input_names}
        tapped = with_taps(dataset, n_taps)
        self.arrays = tapped.arrays
        window_steps = cfg.window_steps(dataset.dt)

        def evaluator(integrator: str, substeps: int) -> Evaluator:
            return Evaluator(
                tapped,
                equation.target,
                window_steps,
                cfg.metric,
                cfg.max_depth,
                integrator=integrator,
                substeps=substeps,
            )

        self._evaluator = evaluator
        self.ev = evaluator(cfg.integrator, cfg.substeps)
        self._fitting = {cfg.substeps: self.ev}
        # validation flies the printed ODE as a reader's simulator does (fine RK4): a loop
        # that holds only by one RK4 step's damping does not win on validation
        judged = readers_scheme(cfg.integrator, cfg.substeps)
        self.judge = self.ev
        if judged != (cfg.integrator, cfg.substeps):
            self.judge = evaluator(*judged)
        self.dt = dataset.dt
        self.starts, self.steps = tile(dataset.train, window_steps, cfg.max_delay)
        self.short = [
            (spread(tile(dataset.train, h, cfg.max_delay)[0], SHORT_WINDOW_STEPS // h), h)
            for h in SEED_HORIZONS
        ]
        samples = np.unique((self.starts[:, None] + np.arange(self.steps)[None, :]).ravel())
        self.samples = spread(samples[samples >= 1], SCREEN_SAMPLES)
        self.acc = self.arrays.acc[:, target_index(equation.target)]
        self.window_steps, self.max_delay = window_steps, cfg.max_delay

    def with_lag(self, tau: float) -> RefineProblem:
        """The same problem with evaluators of its own, lag tau set (for fits side by side:
        an evaluator's lag is its state)."""
        other = copy.copy(self)
        other.ev = self._evaluator(self.ev.integrator, self.ev.substeps)
        other.ev.set_lag(tau)
        other._fitting = {other.ev.substeps: other.ev}
        other.judge = other.ev
        if self.judge is not self.ev:
            other.judge = self._evaluator(self.judge.integrator, self.judge.substeps)
        return other

    def canonical(self, equation) -> sp.Expr:
        """The equation's expression with each delayed input written as the tap at its
        delay (u_R at delay 3 -> u_R__tap3)."""
        reps = {
            sp.Symbol(n, real=True): sp.Symbol(tap_name(base_input(n), d), real=True)
            for n, d in equation.delays.items()
        }
        return sp.expand(equation.sympy().xreplace(reps))

    def tree(self, expr: sp.Expr) -> Tree:
        """The tree of an expanded expression: its terms as a shallow sum."""
        prefixes = []
        for term in sp.Add.make_args(expr):
            t = from_sympy(term, self.delays, self.input_names)
            prefixes.append(list(zip(t.codes.tolist(), t.values.tolist(), strict=True)))
        prefix = shallow_sum(prefixes)
        return Tree.from_lists(
            [c for c, _ in prefix],
            [v for _, v in prefix],
            from_sympy(sp.Float(0.0), self.delays, self.input_names).delays,
        )

    def expr(self, tree: Tree) -> sp.Expr:
        """The expanded expression of a tree of this problem."""
        return sp.expand(to_sympy(tree, tuple(self.delays)))

    def values(self, expr: sp.Expr) -> np.ndarray:
        """One-step values of an expression on the training samples."""
        t = self.tree(expr)
        return eval_on_samples(
            t.codes,
            t.values,
            t.size,
            t.delays,
            self.arrays.states,
            self.arrays.inputs,
            self.samples,
        )

    def commanded(self) -> np.ndarray:
        """The one-step target of the expression under the evaluator's lag: the data's
        acceleration inverse-filtered, (a_k - (1 - alpha) a_{k-1}) / alpha."""
        alpha = self.ev.alpha
        return (self.acc[self.samples] - (1.0 - alpha) * self.acc[self.samples - 1]) / alpha

    def residual(self, expr: sp.Expr) -> np.ndarray:
        """What the expression leaves of the one-step target on the training samples."""
        return self.commanded() - self.values(expr)

    def fitting(self, expr: sp.Expr) -> Evaluator:
        """The evaluator that fits `expr`: the search's scheme, with an RK4 engine at as many
        steps per sample as its loop needs to fly as its ODE (gpquad.models.stiffness), the
        current lag set."""
        if self.ev.integrator != "rk4":
            return self.ev
        substeps = equation_substeps(
            self.target, expr, self.ev.lag, self.values, self.dt, self.ev.substeps
        )
        if substeps not in self._fitting:
            self._fitting[substeps] = self._evaluator("rk4", substeps)
        ev = self._fitting[substeps]
        ev.set_lag(self.ev.lag)
        return ev

    def _window_error(self, ev: Evaluator, tree: Tree, starts, steps) -> float:
        if len(starts) == 0:
            return float("nan")
        with np.errstate(all="ignore"):
            return float(ev.window_errors([tree], starts, n_steps=steps).mean())

    def error(self, tree: Tree, ranges=None) -> float:
        """Mean window error flown alone (the search's metric) over the training windows, in
        the scheme that fits it (`fitting`), or over `ranges` tiled (validation: flown by the
        judge, fine RK4 for an RK4 engine), both with the current lag."""
        if ranges is None:
            return self._window_error(self.fitting(self.expr(tree)), tree, self.starts, self.steps)
        starts, steps = tile(ranges, self.window_steps, self.max_delay)
        self.judge.set_lag(self.ev.lag)  # the equation's lag, whichever evaluator judges
        return self._window_error(self.judge, tree, starts, steps)

    def fit(self, expr: sp.Expr, direct: Fitted | None = None) -> tuple[sp.Expr, float]:
        """(expr with its constants fitted through the integrator, training error): fitted in
        the search's scheme (the better of a direct LM fit and one with a growing horizon),
        then, while the fitted loop needs more steps per sample (`fitting`), polished in the
        finer scheme from there. direct: this problem's `direct_fit(expr)` at its current
        lag, when made already: nothing it did is done again (where its first fit stays the
        better one, it is the result)."""
        tree = self.tree(expr)
        first = self._first_fit(expr, tree) if direct is None else direct.first
        fitted, error = continued_constants(
            self.ev,
            tree,
            np.inf,  # not read: the direct fit is given
            self.starts,
            self.steps,
            self._error_of(self.ev),
            FIT_STEPS,
            self.short,
            FTOL,
            STALL,
            direct=first,
        )
        if direct is not None and fitted is first[0]:  # polished already
            return direct.expr, direct.error
        return self._polished(fitted, error)

    def direct_fit(self, expr: sp.Expr) -> Fitted:
        """`fit` without the growing horizon (its direct LM fit in the search's scheme,
        polished as `fit` polishes), with that first fit kept for `fit(expr, direct=...)`."""
        first = self._first_fit(expr, self.tree(expr))
        return Fitted(*self._polished(*first), first)

    def _first_fit(self, expr: sp.Expr, tree: Tree) -> tuple[Tree, float]:
        """The direct LM fit in the search's scheme: of at most BASIN_STEPS evaluations when
        `expr`'s loop needs a finer scheme (the fit there only finds the basin that the
        polish fits), else FIT_STEPS."""
        stiff = self.fitting(expr).substeps > self.ev.substeps
        return self._direct(self.ev, tree, BASIN_STEPS if stiff else FIT_STEPS)

    def _polished(self, fitted: Tree, error: float) -> tuple[sp.Expr, float]:
        """(expr, training error) of a fit in the search's scheme, polished in the finer
        scheme while the fitted loop needs more steps per sample (`fitting`)."""
        expr, ev = self.expr(fitted), self.ev
        while (finer := self.fitting(expr)).substeps > ev.substeps:
            # polished in the finer scheme from the coarse fit: already in the loop's basin,
            # it needs no growing horizon
            ev = finer
            fitted, error = self._direct(ev, self.tree(expr))
            expr = self.expr(fitted)
        return expr, float(error)

    def _error_of(self, ev: Evaluator):
        """The training windows' error of a tree flown by `ev`."""
        return lambda t: self._window_error(ev, t, self.starts, self.steps)

    def _direct(self, ev: Evaluator, tree: Tree, steps: int = FIT_STEPS) -> tuple[Tree, float]:
        """The LM fit of the tree's constants on the training windows, flown by `ev`, from
        its constants (kept when no better), in at most `steps` evaluations."""
        error_of = self._error_of(ev)
        start = error_of(tree)
        return gauss_newton_constants(
            ev,
            tree,
            start if np.isfinite(start) else np.inf,
            self.starts,
            self.steps,
            error_of,
            steps,
            FTOL,
            STALL,
        )
