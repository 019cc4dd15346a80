"""The reported equation of a coevolution run: the best climber over the whole training
data, pruned and chosen by BIC (gpquad.engine.evolve.selection) among the size/error front,
or pruned within a tolerance (`selection = "prune"`). A mixin of
gpquad.engine.evolve.coevolution.Coevolution, whose state it reads."""

from __future__ import annotations

import functools

import numpy as np

from gpquad.engine.evolve.evaluator import Evaluator
from gpquad.engine.evolve.lm import STALL
from gpquad.engine.evolve.local_search import fit_constants, prune
from gpquad.engine.evolve.poles import without_poles
from gpquad.engine.evolve.selection import fitted_rivals, mse_of, prune_by_bic, select_by_bic
from gpquad.engine.evolve.stall import NEAR_EXACT_RSE, best_error, exact
from gpquad.engine.evolve.state import RunState
from gpquad.engine.evolve.windows import tile
from gpquad.engine.tree.encoding import Tree
from gpquad.engine.tree.operators import CONST

#: The scheme the generations fly (gpquad.engine.kernels.step): eq. 2, the cheapest; a
#: configured continuous-time `integrator` fits and chooses the reported equation.
SEARCH_SCHEME = "euler"


class FinalChoice:
    """Coevolution's choice of its reported equation (module notes)."""

    def tiled_errors(self, trees: list[Tree], ranges, ev: Evaluator | None = None) -> np.ndarray:
        """Mean error of each tree over non-overlapping windows tiling `ranges` (inf if none),
        flown by `ev` (default: the search's evaluator)."""
        starts, steps = tile(ranges, self.window_steps, self.cfg.max_delay)
        if len(starts) == 0:
            return np.full(len(trees), np.nan)
        ev = self.evaluator if ev is None else ev
        return ev.window_errors(trees, starts, n_steps=steps).mean(axis=1)

    def training_errors(self, state: RunState) -> np.ndarray:
        """Each climber's error over the whole training data (NaN: no window fits)."""
        return self.tiled_errors(state.models, self.dataset.train)

    @functools.cached_property
    def target_spread(self) -> float:
        """Standard deviation of the target state over the training samples."""
        rows = [np.arange(a, b) for a, b in self.dataset.train]
        if not rows:
            return 0.0
        states = self.dataset.arrays.states[np.concatenate(rows), 3 + self.evaluator.target]
        return float(np.std(states))

    def exact_in_model_scheme(self, state: RunState, train=None) -> bool:
        """Whether the best climber over the training data, its constants fitted through the
        configured integrator (when it is not the surrogate the generations fly), flies the
        whole training data within EXACT_RSE of the target's spread
        (gpquad.engine.evolve.stall). Checked only when its surrogate error is below
        NEAR_EXACT_RSE; it is fitted on the suite's few windows first, and on the whole data
        only when it is exact there; each fit stops when it stops gaining (lm.STALL).
        `train`: training_errors(state), if computed already."""
        ev = self.model_evaluator
        if ev is self.evaluator:
            return False
        train = self.training_errors(state) if train is None else train
        error = best_error(train)
        if not exact(error, self.target_spread, self.evaluator.squared, NEAR_EXACT_RSE):
            return False
        fit = self.gradient_fitter(self.cfg.gradient_steps, ev, stall=STALL)
        starts, steps = tile(self.dataset.train, self.window_steps, self.cfg.max_delay)
        if fit is None or len(starts) == 0:
            return False
        model = state.models[int(np.argmin(np.where(np.isnan(train), np.inf, train)))]
        for windows, n_steps in ((state.suite, self.window_steps), (starts, steps)):
            error = float(ev.window_errors([model], windows, n_steps=n_steps).mean())
            model, error = fit(model, error, windows, n_steps)
            if not exact(error, self.target_spread, ev.squared):
                return False
        return True

    def best(self, state: RunState, train=None) -> tuple[Tree, float, float]:
        """The climber with the lowest error over the whole training data, with its training
        and validation errors. With prune_tolerance > 0 it is pruned first: subtrees become
        constants while the error grows by less than prune_tolerance times the error of the
        best constant model. `train` may pass training_errors(state) computed already."""
        train = self.training_errors(state) if train is None else train
        i = int(np.argmin(np.where(np.isnan(train), np.inf, train)))
        model, error = state.models[i], float(train[i])
        if self.cfg.selection == "bic":
            model = self.select_by_bic(state, model, train)
        elif self.cfg.prune_tolerance > 0:
            starts, steps = tile(self.dataset.train, self.window_steps, self.cfg.max_delay)
            samples = (starts[:, None] + np.arange(steps)[None, :]).ravel()
            # The allowance is a fraction of the error of the best constant model.
            mean_acc = float(self.dataset.arrays.acc[samples, self.evaluator.target].mean())
            trivial = Tree.from_lists([CONST], [mean_acc], np.zeros_like(model.delays))
            scale = float(self.evaluator.window_errors([trivial], starts, n_steps=steps).mean())
            model, error = prune(
                self.evaluator,
                model,
                starts,
                steps,
                self.cfg.prune_tolerance * scale,
                self.cfg.nelder_mead_evals,
                lambda t, a, b: self.subtree_mean(t, a, b, samples),
                self.gradient_fitter(self.cfg.gradient_steps),
            )
        ev = self.model_evaluator
        if self.cfg.selection != "bic" and ev is not self.evaluator:
            fit = self.gradient_fitter(self.cfg.gradient_steps, ev)
            starts, steps = tile(self.dataset.train, self.window_steps, self.cfg.max_delay)
            if fit is not None and len(starts):
                model = fit(
                    model,
                    float(self.tiled_errors([model], self.dataset.train, ev)[0]),
                    starts,
                    steps,
                )[0]
        error = float(self.tiled_errors([model], self.dataset.train, ev)[0])
        validation = self.tiled_errors([model], self.dataset.validation, ev)[0]
        return model, error, float(validation)

    def select_by_bic(self, state: RunState, model: Tree, train) -> Tree:
        """Prune `model` while its training BIC does not grow, then pick the lowest BIC over
        the training and validation windows among it and the front's climbers
        (gpquad.engine.evolve.selection). The pruning flies the search's scheme; with another
        configured `integrator` the pruned equation is pruned again in it, the front's
        constants are fitted through it, and the choice is made in it. Every fit here stops
        when it stops gaining (lm.STALL); the pruning's and the front's fits run in up to
        `self.threads()` threads (the same equation for any number)."""
        cfg = self.cfg
        starts, steps = tile(self.dataset.train, self.window_steps, cfg.max_delay)
        samples = (starts[:, None] + np.arange(steps)[None, :]).ravel()

        def pruned_in(scheme: str, substeps: int, tree: Tree):
            ev, fit = self._mse_fitter(scheme, substeps)
            constant_of = lambda t, a, b: self.subtree_mean(t, a, b, samples)  # noqa: E731
            regain = self.regain_fitter(cfg.gradient_steps, ev, stall=STALL)
            return (
                ev,
                fit,
                prune_by_bic(ev, tree, starts, steps, constant_of, fit, regain, self.threads),
            )

        # BIC over every window, training and validation: a criterion made for the data the
        # constants were fitted on, and the validation windows alone are often one or two
        # (px4-s250: its 10 s of validation favoured r_dot = u_Y - r over 16.8 (u_Y - r),
        # which predicts the held-out flight 50 times better).
        chosen_from = starts
        val_starts, val_steps = tile(self.dataset.validation, self.window_steps, cfg.max_delay)
        if len(val_starts) and val_steps == steps:
            chosen_from = np.concatenate([starts, val_starts])
        other_scheme = cfg.integrator != SEARCH_SCHEME
        surrogate_exact = exact(best_error(train), self.target_spread, self.evaluator.squared)
        if other_scheme and not surrogate_exact and self.exact_in_model_scheme(state, train):
            # exact in the integrator only: pruned there only, where every true term shows,
            # not in the surrogate, whose discretisation error can hide a small one
            pruned = model
        else:
            ev_mse, fit, pruned = pruned_in(SEARCH_SCHEME, 1, model)
        arrays = self.dataset.arrays
        # a quotient singular where the data went is no choice (gpquad.engine.evolve.poles)
        pruned, *front = without_poles(
            [pruned] + [t for t, _ in self.front(state, train)],
            arrays.states,
            arrays.inputs,
            samples,
        )
        if other_scheme:
            # pruned again: terms the surrogate needed only for its own discretisation go
            ev_mse, fit, pruned = pruned_in(cfg.integrator, cfg.substeps, pruned)
            front = fitted_rivals(
                ev_mse, fit, pruned, front, starts, chosen_from, steps, self.threads()
            )
        return select_by_bic(ev_mse, [pruned] + front, chosen_from, steps)[0]

    def _mse_fitter(self, integrator: str, substeps: int):
        """(mean-squared-error evaluator flying `integrator`, its constant fit)."""
        cfg = self.cfg
        ev_mse = Evaluator(
            self.dataset,
            self.target,
            self.window_steps,
            "mse",
            cfg.max_depth,
            integrator=integrator,
            substeps=substeps,
        )
        fit = self.gradient_fitter(cfg.gradient_steps, ev_mse, stall=STALL)
        if fit is None:

            def fit(tree, err, starts, n_steps):
                return fit_constants(
                    tree, err, lambda t: mse_of(ev_mse, t, starts, n_steps), cfg.nelder_mead_evals
                )

        return ev_mse, fit

    def front(self, state: RunState, train=None) -> list[tuple[Tree, float]]:
        """The climbers on the size/error Pareto front (training data), smallest first:
        each is more accurate than every smaller one (alternatives to the best equation)."""
        train = self.training_errors(state) if train is None else train
        order = sorted(
            range(len(state.models)),
            key=lambda i: (state.models[i].size, np.nan_to_num(train[i], nan=np.inf)),
        )
        front, best = [], np.inf
        for i in order:
            if train[i] < best:
                front.append((state.models[i], float(train[i])))
                best = train[i]
        return front
