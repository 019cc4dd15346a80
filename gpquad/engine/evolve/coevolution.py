"""The coevolution loop of the paper (section 2.2), with explicit, checkpointable state.

One iteration = `model_generations` generations of the model hill climbers on
the test suite, `test_generations` generations of the test hill climbers
(fitness: variance of the models' errors), insertion of the best test into the
suite, and one bloat simplification of every model.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from gpquad.data.dataset import Dataset
from gpquad.engine.evolve.choice import SEARCH_SCHEME, FinalChoice
from gpquad.engine.evolve.evaluator import Evaluator
from gpquad.engine.evolve.gradient_fit import continued_constants
from gpquad.engine.evolve.leaves import measured_variables
from gpquad.engine.evolve.linear_seed import linear_seed, variable_scales
from gpquad.engine.evolve.local_search import (
    improve_constants,
    improve_delays,
)
from gpquad.engine.evolve.state import (
    SEED_HORIZONS,
    SEED_WINDOWS,
    SHORT_WINDOW_STEPS,
    RunState,
    disagreement,
    variation_params,
)
from gpquad.engine.evolve.term_search import best_index, improve_terms
from gpquad.engine.evolve.windows import WindowSpace, spread, tile
from gpquad.engine.kernels.tree_eval import eval_on_samples
from gpquad.engine.taps import initial_delays, with_taps
from gpquad.engine.tree.encoding import Tree
from gpquad.engine.tree.random_stream import RandomStream
from gpquad.engine.tree.variation import (
    constant_mutation,
    fold_constants,
    kernel_params,
    mutate_population,
    random_tree,
    replace_with_constant,
)
from gpquad.engine.variables import N_STATE
from gpquad.study.config import EvolutionConfig

#: The parts of a search that `Coevolution.seconds` times: an iteration's phases in their
#: order, then the final choice of the reported equation (gpquad.study.loop.final_equation).
PHASES = (
    "generations",
    "constants and delays",
    "term insertion",
    "tests",
    "simplification",
    "final choice",
)


def summed_phases(phases: dict[str, dict[str, float]]) -> dict[str, float]:
    """{phase: seconds} of PHASES summed over several searches' {target: {phase: s}}."""
    return {p: sum(one.get(p, 0.0) for one in phases.values()) for p in PHASES}


def keep_rows(parents, mutants, rows):
    """The packed parents with `rows` replaced by the mutants', in place (the model phase
    owns them; widened when a mutant is longer than their rows)."""
    codes, values, sizes, delays = parents
    longest = int(mutants[2][rows].max())
    if longest > codes.shape[1]:
        grow = longest - codes.shape[1]
        codes = np.pad(codes, ((0, 0), (0, grow)))
        values = np.pad(values, ((0, 0), (0, grow)))
    for i in rows:
        n = int(mutants[2][i])
        codes[i] = 0
        values[i] = 0.0
        codes[i, :n] = mutants[0][i, :n]
        values[i, :n] = mutants[1][i, :n]
        sizes[i] = n
        delays[i] = mutants[3][i]
    return codes, values, sizes, delays


def median(values: np.ndarray) -> float:
    """np.median of a short 1-D array, the same bits (the mean of the two middle values of
    an even count), without numpy's per-call cost (about 19 us against 1 us for the 14
    climbers' errors, once per generation); NaN when any value is NaN, as numpy's."""
    items = values.tolist()
    if not items or any(v != v for v in items):
        return float("nan")
    ordered = sorted(items)
    m = len(ordered) // 2
    return ordered[m] if len(ordered) % 2 else (ordered[m - 1] + ordered[m]) / 2


class Coevolution(FinalChoice):
    """Coevolutionary identification of one target's equation. `seconds`: the wall seconds
    of each of PHASES so far, summed over the iterations (a profile; no result reads it)."""

    def __init__(self, dataset: Dataset, target: str, cfg: EvolutionConfig):
        # this target's taps, depth and degree (each may be a per-target table); with taps,
        # the kernels see every input once per tap (gpquad.engine.taps)
        cfg = cfg.for_target(target)
        self.seconds: dict[str, float] = {}
        self.dataset = dataset = with_taps(dataset, cfg.input_taps)
        self.target = target
        self.cfg = cfg
        self.params = variation_params(
            cfg,
            len(dataset.input_names),
            measured_variables(dataset, cfg.exclude_leaves, cfg.keep_tracked),
        )
        #: samples in a test window, and how far a test mutation moves it (half a window)
        self.window_steps = cfg.window_steps(dataset.dt)
        self.test_offset_max = self.window_steps // 2
        # The generations fly eq. 2, the cheap surrogate; the reported equation's constants
        # are fitted and chosen through the configured scheme (model_evaluator, `best`).
        self.evaluator = Evaluator(dataset, target, self.window_steps, cfg.metric, cfg.max_depth)
        self.model_evaluator = self.evaluator
        if cfg.integrator != SEARCH_SCHEME:
            self.model_evaluator = Evaluator(
                dataset,
                target,
                self.window_steps,
                cfg.metric,
                cfg.max_depth,
                integrator=cfg.integrator,
                substeps=cfg.substeps,
            )
        self.space = WindowSpace(dataset.train, self.window_steps, cfg.max_delay)
        # the growing horizon of the linear seed and of the gain refits
        self.regain_windows = self.windows_for(SEED_HORIZONS)
        #: Threads the final choice may use now (gpquad.engine.evolve.choice; asked again
        #: before each batch of fits): a search alone on the machine may take its cores.
        self.threads: Callable[[], int] = lambda: 1

    # ----------------------------------------------------------------- state
    def init_state(self, seed) -> RunState:
        rng = np.random.default_rng(seed)
        cfg = self.cfg
        models = [random_tree(rng, self.params) for _ in range(cfg.n_models)]
        if cfg.linear_seed:
            seeded = self.linear_seed()
            if seeded is not None:
                models[0] = seeded
        tests = self.space.random(rng, cfg.n_tests)
        suite = self.space.starts(self.space.random(rng, cfg.suite_size))
        errors = self.evaluator.mean_errors(models, suite)
        return RunState(
            target=self.target,
            iteration=0,
            models=models,
            model_errors=errors,
            tests=tests,
            suite=suite,
            suite_age=np.arange(cfg.suite_size),
            inserted=cfg.suite_size,
            rng_state=rng.bit_generator.state,
        )

    def windows_for(self, horizons) -> list[tuple[np.ndarray, int]]:
        """Short windows spread over the training data for each horizon (steps)."""
        return [
            (spread(tile(self.dataset.train, h, self.cfg.max_delay)[0], SHORT_WINDOW_STEPS // h), h)
            for h in horizons
        ]

    def linear_seed(self) -> Tree | None:
        """The linear output-error climber (gpquad.engine.evolve.linear_seed), fitted with a
        growing horizon (SEED_HORIZONS)."""
        cfg = self.cfg
        fit = self.regain_fitter(cfg.gradient_steps)
        starts, steps = tile(self.dataset.train, self.window_steps, cfg.max_delay)
        if fit is None or len(starts) == 0:
            return None
        variables = (
            self.params.variables
            if self.params.variables is not None
            else range(self.params.n_variables)
        )
        variables = list(variables)
        scales = variable_scales(self.dataset.arrays, variables, self.dataset.train)
        delays = initial_delays(
            len(self.dataset.input_names) // cfg.input_taps, cfg.input_taps, cfg.max_delay
        )
        return linear_seed(
            variables, delays, scales, fit, spread(starts, SEED_WINDOWS), steps, cfg.max_depth
        )

    # ---------------------------------------------------------------- phases
    def model_phase(self, state: RunState, rng: RandomStream) -> None:
        """Hill climbers: each parent makes one mutant, kept if strictly better. The
        climbers are mutated and flown as packed rows (variation.mutate_population:
        variation.mutate's mutants, drawn in the same order)."""
        ev = self.evaluator
        parents = ev.pack(state.models)
        state.model_errors = ev.packed_mean_errors(parents, state.suite)
        kernel_args = kernel_params(self.params)
        for gen in range(self.cfg.model_generations):
            mutants = mutate_population(rng, parents, self.params, kernel_args)
            errors = ev.packed_mean_errors(mutants, state.suite, bounds=state.model_errors)
            better = np.flatnonzero(errors < state.model_errors)
            if better.size:
                parents = keep_rows(parents, mutants, better)
            for i in better:
                n = int(mutants[2][i])
                state.models[i] = Tree(
                    mutants[0][i, :n].copy(), mutants[1][i, :n].copy(), mutants[3][i].copy()
                )
                state.model_errors[i] = errors[i]
            best = int(np.argmin(state.model_errors))
            state.history.append(
                {
                    "target": self.target,
                    "iteration": state.iteration,
                    "generation": gen,
                    "best_suite_error": float(state.model_errors[best]),
                    "median_suite_error": median(state.model_errors),
                    "best_size": state.models[best].size,
                }
            )

    def test_phase(self, state: RunState, rng: np.random.Generator) -> None:
        """Test hill climbers maximise disagreement; the best joins the suite."""
        ev = self.evaluator
        fitness = disagreement(ev.window_errors(state.models, self.space.starts(state.tests)))
        for _ in range(self.cfg.test_generations):
            mutants = self.space.mutate(rng, state.tests, self.test_offset_max)
            f = disagreement(ev.window_errors(state.models, self.space.starts(mutants)))
            better = f > fitness
            state.tests[better] = mutants[better]
            fitness[better] = f[better]
        best_start = int(self.space.starts(state.tests[int(np.argmax(fitness))]))
        self.insert_test(state, best_start)

    def insert_test(self, state: RunState, start: int) -> None:
        """Replace the suite test the new one overlaps, else the oldest."""
        overlap = np.abs(state.suite - start) < self.window_steps
        slot = int(np.argmax(overlap)) if overlap.any() else int(np.argmin(state.suite_age))
        state.suite[slot] = start
        state.suite_age[slot] = state.inserted
        state.inserted += 1

    def subtree_mean(self, tree: Tree, start: int, end: int, samples) -> float:
        """Mean one-step value of tree.codes[start:end] on data samples (finite values only)."""
        arrays = self.dataset.arrays
        sub = np.ascontiguousarray(tree.codes[start:end])
        vals = np.ascontiguousarray(tree.values[start:end])
        out = eval_on_samples(
            sub, vals, len(sub), tree.delays, arrays.states, arrays.inputs, samples
        )
        out = out[np.isfinite(out)]
        return float(out.mean()) if out.size else 0.0

    def simplify_phase(self, state: RunState, rng: RandomStream) -> None:
        """Replace a random subtree of each model by a constant, re-converge constants only,
        and keep the result when it is no worse."""
        ev = self.evaluator
        state.model_errors = ev.mean_errors(state.models, state.suite)
        samples = (state.suite[:, None] + np.arange(self.window_steps)[None, :]).ravel()

        def constant_for(tree: Tree):
            return lambda start, end: self.subtree_mean(tree, start, end, samples)

        candidates = [replace_with_constant(rng, m, constant_for(m)) for m in state.models]
        errors = ev.mean_errors(candidates, state.suite)
        for _ in range(self.cfg.simplify_generations):
            mutants = [constant_mutation(rng, c, self.params) for c in candidates]
            mutant_errors = ev.mean_errors(mutants, state.suite, bounds=errors)
            for i in np.flatnonzero(mutant_errors < errors):
                candidates[i] = mutants[i]
                errors[i] = mutant_errors[i]
        # The paper (2.2) discards a simplification that "performs no better": with
        # simplify_tolerance 0 only a strictly better one is kept; a tolerance > 0 (not in the
        # paper) keeps one within that relative error.
        tol = self.cfg.simplify_tolerance
        keep = (
            errors < state.model_errors if tol == 0 else errors <= state.model_errors * (1.0 + tol)
        )
        for i in np.flatnonzero(keep):
            state.models[i] = fold_constants(candidates[i])
            state.model_errors[i] = errors[i]

    def gradient_fitter(
        self, steps: int, ev: Evaluator | None = None, short_windows=None, stall=None
    ):
        """fit(tree, error, starts, n_steps) by Levenberg-Marquardt, or None (Nelder-Mead).
        Errors are those of `ev` (default: the run's evaluator); short_windows (default none)
        start each fit on a growing horizon; `stall`: the LM's stall rule (default none)."""
        if self.cfg.constant_fit != "lm":
            return None
        ev = self.evaluator if ev is None else ev
        short_windows = [] if short_windows is None else short_windows

        def fit(tree: Tree, error: float, starts, n_steps: int) -> tuple[Tree, float]:
            def error_of(t: Tree) -> float:
                return float(ev.window_errors([t], starts, n_steps=n_steps).mean())

            return continued_constants(
                ev, tree, error, starts, n_steps, error_of, steps, short_windows, stall=stall
            )

        return fit

    def timed(self, phase: str, step: Callable, *args):
        """step(*args), its wall time added to seconds[phase]."""
        t0 = time.perf_counter()
        try:
            return step(*args)
        finally:
            self.seconds[phase] = self.seconds.get(phase, 0.0) + time.perf_counter() - t0

    def local_search_phase(self, state: RunState) -> None:
        """Optional local search of delays and constants (not in the paper; see config),
        then term insertion on the best climber."""
        if self.cfg.constant_fit == "none":
            return
        self.timed("constants and delays", self.climber_fits, state)
        if self.cfg.term_search:
            self.timed("term insertion", self.term_phase, state)

    def climber_fits(self, state: RunState) -> None:
        """Every climber's constants, then its delays, refitted on the suite."""
        refit = self.cfg.nelder_mead_evals // 5
        fit = self.gradient_fitter(self.cfg.gradient_steps)
        refit_fit = self.gradient_fitter(max(self.cfg.gradient_steps // 4, 1))
        for i, model in enumerate(state.models):
            err = state.model_errors[i]
            model, err = improve_constants(
                self.evaluator, model, err, state.suite, self.cfg.nelder_mead_evals, fit
            )
            model, err = improve_delays(
                self.evaluator, model, err, state.suite, self.cfg.max_delay, refit, refit_fit
            )
            state.models[i], state.model_errors[i] = model, err

    def term_phase(self, state: RunState) -> None:
        """Greedy term insertion on the best climber (gpquad.engine.evolve.term_search)."""
        cfg = self.cfg
        fit = self.gradient_fitter(max(cfg.gradient_steps // 4, 1))
        if fit is None:

            def fit(tree, err, starts, n_steps):
                return improve_constants(
                    self.evaluator, tree, err, starts, cfg.nelder_mead_evals // 5
                )

        i = best_index(state.model_errors)
        state.models[i], state.model_errors[i] = improve_terms(
            self.evaluator,
            state.models[i],
            float(state.model_errors[i]),
            state.suite,
            fit,
            self.params.variables if self.params.variables is not None else self.params.n_variables,
            cfg.max_depth,
            cfg.term_min_gain,
            self.regain_fitter(max(cfg.gradient_steps // 4, 1)),
            self.extra_taps(),
            self.params.allows,
        )

    def extra_taps(self) -> dict[int, int]:
        """Variable index of every input tap k >= 1 -> the variable of its input (tap 0)."""
        n_in = self.params.n_inputs // self.params.taps
        return {
            N_STATE + k * n_in + j: N_STATE + j
            for k in range(1, self.params.taps)
            for j in range(n_in)
        }

    def regain_fitter(self, steps: int, ev: Evaluator | None = None, stall=None):
        """The LM fit with a growing horizon (SEED_HORIZONS),
        for the few candidates whose gains start far from their values; None without LM."""
        return self.gradient_fitter(steps, ev, short_windows=self.regain_windows, stall=stall)

    def iterate(self, state: RunState) -> RunState:
        """One full iteration; returns the same state object, advanced."""
        rng = np.random.default_rng()
        rng.bit_generator.state = state.rng_state
        stream = RandomStream(rng)  # scalar draws for the variation operators
        self.timed("generations", self.model_phase, state, stream)
        self.local_search_phase(state)
        self.timed("tests", self.test_phase, state, rng)
        self.timed("simplification", self.simplify_phase, state, stream)
        state.iteration += 1
        state.rng_state = rng.bit_generator.state
        return state
