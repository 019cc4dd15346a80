"""A coevolution run's state and the pieces of the search that are not the loop: the
variation parameters of a config, the test fitness (disagreement), a deep copy."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from gpquad.engine.tree.encoding import Tree
from gpquad.engine.tree.variation import VariationParams
from gpquad.engine.variables import N_STATE
from gpquad.errors import GpquadError
from gpquad.study.config import EvolutionConfig


@dataclass
class RunState:
    """Everything needed to continue a run: climbers, tests, suite and the RNG state."""

    target: str
    iteration: int
    models: list[Tree]
    model_errors: np.ndarray
    tests: np.ndarray  # virtual positions of the test hill climbers
    suite: np.ndarray  # data start indices
    suite_age: np.ndarray  # insertion order; the smallest is the oldest
    inserted: int
    rng_state: dict
    history: list[dict] = field(default_factory=list)  # rows not yet flushed to disk
    #: The best climber's training error after each iteration (the stall rule reads it).
    best_errors: list[float] = field(default_factory=list)


#: Steps of data each short-horizon fit flies: windows are spread over the training data up
#: to this many steps in all.
SHORT_WINDOW_STEPS = 4000
#: Training windows (spread over the data) on which the linear seed is fitted.
SEED_WINDOWS = 24
#: Growing horizon (steps) of the linear seed's fit and of the gain refits.
SEED_HORIZONS = (2, 10)


def variation_params(cfg: EvolutionConfig, n_inputs: int, variables=None) -> VariationParams:
    """n_inputs: every tap of every input (gpquad.engine.taps). The constants' settings must
    be finite (a GpquadError naming the field otherwise)."""
    for name in ("const_low", "const_high", "const_variance"):
        value = getattr(cfg.gp, name)
        if not np.isfinite(value) or (name == "const_variance" and value < 0):
            raise GpquadError(
                f"{value} is not a finite number" + (" >= 0" if name == "const_variance" else ""),
                field=f"evolution.gp.{name}",
            )
    return VariationParams(
        n_variables=N_STATE + n_inputs,
        n_inputs=n_inputs,
        variables=variables,
        taps=cfg.input_taps,
        max_depth=cfg.max_depth,
        max_degree=cfg.max_degree,
        p_leaf=cfg.gp.p_leaf,
        p_constant_leaf=cfg.gp.p_constant_leaf,
        const_low=cfg.gp.const_low,
        const_high=cfg.gp.const_high,
        const_sigma=float(np.sqrt(cfg.gp.const_variance)),
        p_const_perturb=cfg.gp.p_const_perturb,
        p_delay=cfg.gp.p_delay,
        max_delay=cfg.max_delay,
    )


def disagreement(errors: np.ndarray) -> np.ndarray:
    """Fitness of each test (column): variance of the models' errors (rows).

    A diverged model (inf) counts as twice the worst finite error in the matrix, so
    that a window on which some models blow up is a strongly discriminating test.
    """
    finite = np.isfinite(errors)
    cap = 2.0 * errors[finite].max() if finite.any() else 1.0
    return np.where(finite, errors, cap).var(axis=0)


def clone_state(state: RunState) -> RunState:
    """A deep copy (trees are immutable)."""
    return dataclasses.replace(
        state,
        models=list(state.models),
        model_errors=state.model_errors.copy(),
        tests=state.tests.copy(),
        suite=state.suite.copy(),
        suite_age=state.suite_age.copy(),
        rng_state=dict(state.rng_state),
        history=list(state.history),
        best_errors=list(state.best_errors),
    )
