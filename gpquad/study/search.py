"""One target's search: the coevolution run to its last iteration (gpquad.study.loop), with
optional history and checkpoints, and the progress line it prints."""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from gpquad.data.dataset import Dataset
from gpquad.engine.evolve.coevolution import Coevolution
from gpquad.engine.evolve.state import RunState
from gpquad.engine.threads import one_blas_thread
from gpquad.models.equations import Equation
from gpquad.study import checkpoint
from gpquad.study.config import Config
from gpquad.study.loop import evolve, final_equation, stop_reason
from gpquad.study.seeding import target_seed
from gpquad.study.store import HistoryWriter


class Progress:
    """One line per iteration: target, iteration, best error on the current test suite (the
    windows the models compete on, not the training error of model.json) and time left. The
    time left is estimated from the iterations after the run's first, which also compiles
    the kernels (tens of seconds, once per machine with numba's cache)."""

    def __init__(self, enabled: bool, total_iterations: int, stream=sys.stdout):
        self.enabled = enabled
        self.total = total_iterations
        self.done = 0
        self.start = time.perf_counter()
        self.first: float | None = None  # elapsed time at the end of the first iteration
        self.stream = stream

    def time_left(self, elapsed: float) -> str:
        """'~12.3 s' from the iterations after the first, or 'estimating'."""
        if self.first is None or self.done < 2:
            return "estimating"
        rate = (elapsed - self.first) / (self.done - 1)
        return f"~{rate * (self.total - self.done):.1f} s"

    def iteration(self, target: str, state: RunState, iterations: int) -> None:
        self.done += 1
        elapsed = time.perf_counter() - self.start
        if self.first is None:
            self.first = elapsed
        if not self.enabled:
            return
        best = float(np.min(state.model_errors))
        print(
            f"  {target:6s} iteration {state.iteration:3d}/{iterations}  best suite error "
            f"{best:.5g}  elapsed {elapsed:6.1f} s  left {self.time_left(elapsed)}",
            file=self.stream,
            flush=True,
        )

    def stopped(self, target: str, state: RunState, cfg) -> None:
        """A search that stopped before its last iteration: its iterations left are not
        counted in the time left, and one line says why (stop_reason)."""
        self.total -= cfg.iterations - state.iteration
        why = stop_reason(cfg, state)
        self.say(f"  {target:6s} stopped after iteration {state.iteration}: {why}")

    def say(self, text: str) -> None:
        if self.enabled:
            print(text, file=self.stream, flush=True)


@one_blas_thread
def identify(
    dataset: Dataset,
    target: str,
    cfg: Config,
    history: HistoryWriter | None = None,
    progress: Progress | None = None,
    state: RunState | None = None,
    checkpoint_path: Path | None = None,
    history_start: int | None = None,
    threads=None,
    seconds: dict | None = None,
) -> tuple[Equation, RunState]:
    """Run the coevolution for one target; returns its best equation and final state.
    `threads`: a callable giving the threads its final choice may use now (default 1; the
    equation is the same for any number). `seconds`, if given, receives the wall seconds of
    the search's phases (gpquad.engine.evolve.coevolution.PHASES).

    With checkpoint_path, the state is saved atomically after every iteration together
    with the history file's size, and a run is continued from an existing checkpoint
    (the history is cut back to the size the checkpoint recorded; a run that starts
    afresh cuts it back to `history_start`, where this target's rows begin).
    On KeyboardInterrupt the exception is re-raised with the partial result attached
    as `exc.partial = (equation, state)`.
    """
    ev = cfg.evolution
    co = Coevolution(dataset, target, ev)
    if threads is not None:
        co.threads = threads
    if state is None and checkpoint_path is not None and checkpoint_path.exists():
        state = _resumed_state(co, checkpoint_path, history, history_start)
    if state is None:
        state = co.init_state(target_seed(cfg.seed, target))
        if history is not None and history_start is not None:
            history.truncate(history_start)
    report = (
        None if progress is None else (lambda st: progress.iteration(target, st, ev.iterations))
    )
    try:
        evolve(co, state, ev.iterations, history, checkpoint_path, on_iteration=report)
        if progress is not None and state.iteration < ev.iterations:
            progress.stopped(target, state, ev)
    except KeyboardInterrupt as exc:
        tree, train, val = co.best(state)
        exc.partial = (  # type: ignore[attr-defined]
            Equation(target, tree, dataset.input_names, train, val, dataset.trim),
            state,
        )
        raise
    equation = final_equation(co, state, dataset, target)
    if seconds is not None:
        seconds.update(co.seconds)
    return equation, state


def _resumed_state(
    co: Coevolution, path: Path, history: HistoryWriter | None, history_start: int | None
) -> RunState | None:
    """The state of a checkpoint that fits this run, with the history cut back to the length
    it recorded (checked first); None, with one warning line, when the checkpoint is
    damaged, foreign or an older pickled one (never unpickled)."""
    try:
        state, meta = checkpoint.load(path)
        checkpoint.check_fits(state, co)
        if history is not None:
            history.truncate(checkpoint.history_bytes(meta, history_start or 0, history.size()))
        return state
    except checkpoint.CorruptCheckpoint as exc:
        print(f"gpquad: warning: {path}: {exc}; restarting {co.target}", file=sys.stderr)
        return None
