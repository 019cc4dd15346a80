"""The one run loop, shared by `gpquad run` (gpquad.study.runner) and `gpquad sweep`.

`evolve` iterates a coevolution state to its last iteration, or until it stops gaining
(gpquad.engine.evolve.stall). After every iteration it
appends the iteration's history rows (written and fsynced by HistoryWriter), then replaces
the checkpoint atomically, recording the history's length, so that a run killed at any
moment resumes from its last iteration with no duplicated history rows. `final_equation`
picks the reported equation and its Pareto front the same way for both commands.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from gpquad.data.dataset import Dataset
from gpquad.engine.evolve.coevolution import Coevolution
from gpquad.engine.evolve.stall import best_error, exact, stalled
from gpquad.engine.evolve.state import RunState
from gpquad.models.equations import Equation
from gpquad.study import checkpoint
from gpquad.study.config import EvolutionConfig
from gpquad.study.store import HistoryWriter


def evolve(
    co: Coevolution,
    state: RunState,
    iterations: int,
    history: HistoryWriter | None = None,
    checkpoint_path: Path | None = None,
    meta: dict | None = None,
    on_iteration: Callable[[RunState], None] | None = None,
) -> RunState:
    """Iterate `state` until `iterations`, or until the search stalls (`search_stalled`);
    after each iteration: its best training error, history, checkpoint, then
    `on_iteration(state)`."""
    train = None  # the climbers' training errors of the last iteration, when computed
    while state.iteration < iterations and not search_stalled(co, state, train):
        co.iterate(state)
        if co.cfg.stall_iterations > 0:
            train = co.training_errors(state)
            state.best_errors.append(best_error(train))
        if history is not None:
            history.write(state.history)
        state.history.clear()
        if checkpoint_path is not None:
            checkpoint.save(
                checkpoint_path,
                state,
                {**(meta or {}), "history_bytes": history.size() if history else 0},
            )
        if on_iteration is not None:
            on_iteration(state)
    return state


def search_stalled(co: Coevolution, state: RunState, train=None) -> bool:
    """Whether the search stopped gaining (gpquad.engine.evolve.stall, the config's
    stall_iterations and stall_gain) or its best climber is exact: in the surrogate the
    generations fly, or in the configured integrator (FinalChoice.exact_in_model_scheme).
    `train`: the climbers' training errors, if computed already."""
    if not state.best_errors:
        return False
    if stalled(state.best_errors, co.cfg.stall_iterations, co.cfg.stall_gain):
        return True
    if exact(state.best_errors[-1], co.target_spread, co.evaluator.squared):
        return True
    return co.exact_in_model_scheme(state, train)


def stop_reason(cfg: EvolutionConfig, state: RunState) -> str:
    """Why a search stopped before its last iteration (search_stalled), in words: its
    training record stalled, or else its best climber was exact (search_stalled's other
    reasons)."""
    if stalled(state.best_errors, cfg.stall_iterations, cfg.stall_gain):
        return (
            f"the last {cfg.stall_iterations} lowered its training error by less than "
            f"{100 * cfg.stall_gain:g} %"
        )
    return "its best equation is exact"


def final_equation(co: Coevolution, state: RunState, dataset: Dataset, target: str) -> Equation:
    """The reported equation and its front (chosen_equation), timed as the search's
    "final choice" (Coevolution.seconds)."""
    return co.timed("final choice", chosen_equation, co, state, dataset, target)


def chosen_equation(co: Coevolution, state: RunState, dataset: Dataset, target: str) -> Equation:
    """The reported equation and the run's size/error Pareto front (training errors).

    The equation is the final climbers' best, pruned or chosen by the configured
    `selection`. With "prune", a front candidate that is no larger and has a lower
    training error than the pruned equation replaces it: the reported equation is never
    beaten by one the run already holds. With "bic" the choice is by BIC on the validation
    windows, which can prefer a smaller equation over a more accurate one by design.
    """
    train_errors = co.training_errors(state)
    tree, train, val = co.best(state, train_errors)
    front = co.front(state, train_errors)
    if co.cfg.selection != "bic":
        if co.model_evaluator is not co.evaluator:  # the front's errors are the surrogate's
            errors = co.tiled_errors([t for t, _ in front], dataset.train, co.model_evaluator)
            front = [(t, float(e)) for (t, _), e in zip(front, errors)]
        better = [(t, e) for t, e in front if t.size <= tree.size and e < train]
        if better:
            tree, train = min(better, key=lambda te: (te[1], te[0].size))
            val = float(co.tiled_errors([tree], dataset.validation, co.model_evaluator)[0])
    summaries = [
        Equation(target, t, dataset.input_names, err, float("nan"), dataset.trim).summary()
        for t, err in front
    ]
    return Equation(target, tree, dataset.input_names, train, val, dataset.trim, summaries)
