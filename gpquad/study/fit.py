"""The one fit path: every configured target searched (gpquad.study.runner.identify), then
the model finished (gpquad.models.finish). `gpquad run` calls it with a run folder (history,
checkpoints, resume), `gpquad benchmark` and `gpquad.fit` without one; `gpquad sweep` runs
the same `identify` per repetition and the same finish on its assembled models."""

from __future__ import annotations

import dataclasses
import json
import sys
import time
from pathlib import Path

from gpquad.data.dataset import Dataset
from gpquad.engine.variables import TARGET_NAMES, TARGET_STATE
from gpquad.errors import GpquadError
from gpquad.models.early_finish import EarlyFinish
from gpquad.models.envelope import training_envelope
from gpquad.models.equations import DiscoveredModel, Equation
from gpquad.study import workers
from gpquad.study.config import Config
from gpquad.study.finishing import finish
from gpquad.study.search import Progress, identify
from gpquad.study.store import HistoryWriter, write_json

#: The order the searches go to the worker processes: by their mean seconds over the
#: benchmark's fits, longest first (docs/decisions/2026-11-27-search-order.md). A worker
#: takes the next search when its last ends, so the longest going last would leave the
#: other core idle at the end; the equations are the same in any order.
SEARCH_ORDER = ("r_dot", "p_dot", "q_dot", "a_z", "a_x", "a_y")


def measured_targets(cfg: Config, dataset: Dataset) -> Config:
    """`cfg` with evolution.targets left to those whose integrated state the data measures,
    one line on stderr for each target left out.

    A state that a log does not measure (u and v of a PX4 flight without GPS, every velocity
    of a Betaflight log) holds placeholder values, and an equation fitted to them describes
    the placeholder, not the vehicle: such a target is not identified. No other equation
    reads that state (gpquad.engine.evolve.leaves), and the model flies the log's own
    acceleration for it where it flies data, zero from inputs alone. Raises GpquadError
    (before any long work) when no target is left."""
    notes = unmeasured_notes(dataset, cfg.evolution.targets) or {}
    kept = tuple(t for t in cfg.evolution.targets if t not in notes)
    if not kept:
        missing = ", ".join(f"{t}: {TARGET_STATE[t]}" for t in notes)
        raise GpquadError(
            f"the log measures none of the targets' states ({missing}); "
            "choose targets whose states it measures",
            field="evolution.targets",
        )
    for target, note in notes.items():
        print(f"gpquad: warning: {target}: {note}", file=sys.stderr)
    if not notes:
        return cfg
    return dataclasses.replace(cfg, evolution=dataclasses.replace(cfg.evolution, targets=kept))


def _finished_record(path: Path, dataset) -> tuple[Equation, int] | None:
    """A finished target's (equation, history end) from its record; None, with a warning,
    when the record is damaged (the target is then identified again)."""
    try:
        record = json.loads(path.read_text())
        equation = Equation.from_dict(
            path.stem, record["equation"], dataset.input_names, dataset.trim
        )
        end = record["history_bytes"]
        if type(end) is not int or not 0 < end <= (path.parents[1] / "history.csv").stat().st_size:
            raise ValueError(f"history_bytes {end!r} is not within history.csv")
        return equation, end
    except (
        OSError,
        UnicodeDecodeError,
        ValueError,
        KeyError,
        TypeError,
        IndexError,
        GpquadError,
    ) as exc:
        print(
            f"gpquad: warning: {path}: damaged record of a finished equation "
            f"({type(exc).__name__}); identifying {path.stem} again",
            file=sys.stderr,
        )
        return None


class RowCollector:
    """A history writer that keeps the rows in memory (a search in a worker process)."""

    def __init__(self):
        self.rows: list[dict] = []

    def write(self, rows) -> None:
        self.rows.extend(dict(r) for r in rows)

    def size(self) -> int:
        return 0

    def truncate(self, size: int) -> None:
        self.rows.clear()


def _identify_in_worker(
    dataset: Dataset, target: str, cfg: Config, keep_rows: bool, share: str, jobs: int
):
    """(target, equation, history rows or [], seconds, its phases' seconds) of one search in
    a worker process, with the threads its pool's CoreShare file `share` allows
    (workers.threads_of)."""
    t0 = time.perf_counter()
    rows = RowCollector() if keep_rows else None
    phases: dict[str, float] = {}
    equation, _ = identify(
        dataset, target, cfg, rows, threads=workers.threads_of(share, jobs), seconds=phases
    )
    return target, equation, rows.rows if rows else [], time.perf_counter() - t0, phases


def _history_start(run_dir: Path) -> int:
    """Where the history of the first target begins: after the header line."""
    return len((run_dir / "history.csv").read_bytes().split(b"\n", 1)[0]) + 1


def search_equations(
    dataset: Dataset,
    cfg: Config,
    report: Progress,
    run_dir: Path | None = None,
    resuming: bool = False,
    jobs: int = 1,
    in_process: bool = False,
    idle=None,
    phases: dict | None = None,
    early=None,
) -> tuple[dict[str, Equation], dict[str, float]]:
    """Every target's equation ({target: Equation}) and search time (s); `phases`, if given,
    receives each search's phases ({target: {phase: s}}, coevolution.PHASES). With run_dir, the
    history and checkpoints are written there and finished targets are resumed from it. On
    KeyboardInterrupt the exception carries `equations` = the equations found so far.

    With jobs > 1 the targets left to search run in worker processes, at most one per
    target (the same equations for any jobs: each search is seeded by its target and runs
    BLAS on one thread), and a search with cores left idle takes them as threads
    (workers.CoreShare); a search in this process (one target, `in_process`, or jobs = 1)
    takes `jobs` threads. In a run folder each finished target is recorded (its history
    rows appended in target order, its record written) once every target before it is, so
    history.csv is the same bytes as with jobs = 1; a target interrupted in a worker
    restarts on resume (no per-iteration checkpoint there). `idle()`, if given, is called
    once when the worker processes leave a core idle (fewer searches left than processes):
    the command line loads its plotting there. `early` (gpquad.models.early_finish.
    EarlyFinish), if given, is told each equation found in a worker and started there."""
    ev = cfg.evolution
    equations: dict[str, Equation] = {}
    timings: dict[str, float] = {}
    phases = {} if phases is None else phases
    workers.warm_up_wait()  # forget an earlier fit's: workers.warm_up_wait() tells this one's
    history = HistoryWriter(run_dir / "history.csv") if run_dir is not None else None
    inside = workers.inside_worker()
    parallel = jobs > 1 and len(ev.targets) > 1 and not inside and not in_process
    # a search in this process may use the fit's cores, unless it shares them with others
    threads = 1 if inside else jobs
    try:
        history_end = _history_start(run_dir) if run_dir is not None else 0
        pending: list[str] = []
        for target in ev.targets:
            done = run_dir / "checkpoints" / f"{target}.json" if run_dir is not None else None
            # in parallel, only a prefix of finished targets is resumed (history in order)
            record = (
                _finished_record(done, dataset)
                if done is not None and resuming and done.exists() and not (parallel and pending)
                else None
            )
            if record is not None:  # finished before the interruption
                equations[target], history_end = record
                report.done += ev.iterations
                report.say(f"  {target}: finished earlier (resumed from {done})")
            elif parallel:
                pending.append(target)
            else:
                t0 = time.perf_counter()
                equations[target], _ = identify(
                    dataset,
                    target,
                    cfg,
                    history,
                    report,
                    checkpoint_path=None if done is None else done.with_suffix(".ckpt"),
                    history_start=history_end,
                    threads=lambda: threads,
                    seconds=phases.setdefault(target, {}),
                )
                timings[target] = time.perf_counter() - t0
                history_end = _record(equations[target], done, history, [])
                _say_found(report, equations[target])
        if pending:
            if history is not None:
                history.truncate(history_end)
            phases.update(
                _search_in_workers(
                    dataset,
                    cfg,
                    report,
                    run_dir,
                    history,
                    pending,
                    jobs,
                    equations,
                    timings,
                    idle,
                    early,
                )
            )
    except KeyboardInterrupt as exc:
        partial = getattr(exc, "partial", None)
        if partial is not None:
            equations[partial[0].target] = partial[0]
        found = {t: equations[t] for t in ev.targets if t in equations}  # not arrival order
        exc.equations = found  # type: ignore[attr-defined]
        raise
    finally:
        if history is not None:
            history.close()
    return {t: equations[t] for t in ev.targets if t in equations}, timings


def _record(
    equation: Equation,
    done: Path | None,
    history,
    rows: list,
) -> int:
    """A finished target: its rows appended to the history and its record written (in a
    run folder); returns where the history now ends."""
    end = 0
    if done is not None and history is not None:
        history.write(rows)
        end = history.size()
        write_json(done, {"equation": equation.to_dict(), "history_bytes": end})
    return end


def _say_found(report: Progress, equation: Equation, seconds: float | None = None) -> None:
    """The line of a found equation (with its search's seconds, when searched in a worker)."""
    took = "" if seconds is None else f"; {seconds:.1f} s"
    report.say(f"  -> {equation.text()}  (validation error {equation.validation_error:.4g}{took})")


def _search_in_workers(
    dataset, cfg, report, run_dir, history, pending, jobs, equations, timings, idle=None, early=None
) -> dict[str, dict[str, float]]:
    """The `pending` targets searched in worker processes on `jobs` cores, each recorded in
    target order as soon as every target before it is (search_equations' notes); returns
    each search's phases ({target: {phase: s}})."""
    phases: dict[str, dict[str, float]] = {}
    pool = workers.processes(jobs, len(cfg.evolution.targets))
    searches = f"{len(pending)} equation{'s' if len(pending) > 1 else ''}"
    report.say(f"gpquad: searching {searches} in {pool} processes ...")
    ready: dict[str, tuple] = {}
    order = list(pending)
    with workers.CoreShare(len(pending)) as share:  # the searches left, read by the workers
        arguments = [
            (dataset, t, cfg, run_dir is not None, share.path, jobs) for t in longest_first(pending)
        ]
        futures = workers.submit_all(pool, _identify_in_worker, arguments)
        # idle() once a process has no search left: after this many results, or at once
        # (a resumed run with fewer searches than processes)
        idle_after = max(0, len(pending) - pool + 1)
        starts = [f for f in (idle, None if early is None else early.start) if f is not None]
        for start in starts if idle_after == 0 else ():
            start()
        for left, (target, equation, rows, seconds, phase_seconds) in enumerate(
            workers.completed(futures), start=1
        ):
            phases[target] = phase_seconds
            share.set(len(pending) - left)
            if early is not None:
                early.found(equation)
            for start in starts if left == idle_after else ():
                start()
            ready[target] = (equation, rows)
            equations[target], timings[target] = equation, seconds
            _say_found(report, equation, seconds)
            report.done += cfg.evolution.iterations
            while order and order[0] in ready:
                name = order.pop(0)
                equation, rows = ready.pop(name)
                done = run_dir / "checkpoints" / f"{name}.json" if run_dir is not None else None
                _record(equation, done, history, rows)
    return phases


def longest_first(targets) -> list[str]:
    """`targets` in the order their searches are handed to the workers: the longest
    first (SEARCH_ORDER), so that the workers finish together."""
    rank = {t: i for i, t in enumerate(SEARCH_ORDER)}
    return sorted(targets, key=lambda t: rank.get(t, len(rank)))


def unmeasured_notes(dataset: Dataset, targets) -> dict[str, str] | None:
    """{target: note} for the targets whose integrated state the data does not measure."""
    notes = {
        t: f"not identified: the log does not measure {TARGET_STATE[t]}"
        for t in targets
        if dataset.unmeasured(TARGET_STATE[t])
    }
    return notes or None


def new_model(equations: dict[str, Equation], dataset: Dataset, cfg: Config) -> DiscoveredModel:
    """The unfinished model of `equations` with what is needed to reproduce and fly it."""
    return DiscoveredModel(
        equations,
        dataset.input_names,
        dataset.trim,
        dataset.dt,
        cfg.seed,
        cfg.to_dict(),
        envelope=training_envelope(dataset),
        unmeasured=unmeasured_notes(dataset, TARGET_NAMES),
    )


def early_finish(dataset: Dataset, cfg: Config, jobs: int) -> EarlyFinish:
    """The EarlyFinish of a fit of `cfg` on `dataset` on `jobs` cores (a context: closed on
    leaving)."""
    flipped = cfg.vehicle.flipped(dataset.input_names)
    return EarlyFinish(dataset, cfg.evolution, flipped, workers=jobs)


def fit_dataset(
    dataset: Dataset,
    cfg: Config,
    report: Progress | None = None,
    run_dir: Path | None = None,
    resuming: bool = False,
    jobs: int = 1,
    seconds: dict | None = None,
) -> DiscoveredModel:
    """Search every configured target and finish the model (module notes). Without a run
    folder the searches may run in `jobs` processes (the same equations for any value).
    `seconds`, if given, receives the fit's profile: {"search": {target: s}, "phases":
    {target: {phase: s}}, "finish": {step: s}, "early_finish": s, "compile_wait": s} (each
    search's own time and its phases', each finishing step's wall time, the seconds of
    per-equation finishing work begun on a core the searches left idle (gpquad.models.
    early_finish), the wait for the kernels' compilation before the searches:
    workers.warm_up_wait)."""
    cfg = measured_targets(cfg, dataset)
    report = report or Progress(False, cfg.evolution.iterations * len(cfg.evolution.targets))
    report.total = cfg.evolution.iterations * len(cfg.evolution.targets)
    phases: dict[str, dict[str, float]] = {}
    with early_finish(dataset, cfg, jobs) as early:
        equations, timings = search_equations(
            dataset, cfg, report, run_dir, resuming, jobs, phases=phases, early=early
        )
        steps: dict[str, float] = {}
        model = finish(new_model(equations, dataset, cfg), dataset, cfg, report, steps, jobs, early)
    if seconds is not None:
        seconds.update(
            search=timings,
            phases=phases,
            finish=steps,
            early_finish=early.busy_s,
            compile_wait=workers.warm_up_wait(),
        )
    return model
