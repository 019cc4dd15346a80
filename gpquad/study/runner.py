"""Run one experiment config: load data, identify each target, write the run folder."""

from __future__ import annotations

import dataclasses
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from gpquad.data.dataset import Dataset
from gpquad.data.io import load_dataset
from gpquad.engine.evolve.coevolution import Coevolution, RunState
from gpquad.engine.threads import one_blas_thread
from gpquad.engine.variables import TARGET_STATE
from gpquad.errors import GpquadError
from gpquad.models.envelope import training_envelope
from gpquad.models.equations import DiscoveredModel, Equation
from gpquad.models.finish import finish_model
from gpquad.models.joint_fit import joint_fit_summary
from gpquad.models.refine import refined_summary
from gpquad.models.stability import stability_summary
from gpquad.models.symmetrize import symmetrized_summary
from gpquad.models.symmetry import mirror_odd_terms, parity_summary
from gpquad.study import checkpoint
from gpquad.study.config import Config, folder_config_dict
from gpquad.study.loop import evolve, final_equation
from gpquad.study.seeding import target_seed
from gpquad.study.store import (
    HistoryWriter,
    atomic_write_text,
    checked_name,
    provenance,
    read_json,
    write_json,
)


def default_run_dir(cfg: Config) -> Path:
    stamp = time.strftime("%Y%m%d-%H%M%S")
    return Path(cfg.output.dir) / f"{checked_name(cfg.name)}-seed{cfg.seed}-{stamp}"


class Progress:
    """One line per iteration: target, iteration, best error on the current test suite (the
    windows the models compete on, not the training error of model.json) and time left."""

    def __init__(self, enabled: bool, total_iterations: int, stream=sys.stdout):
        self.enabled = enabled
        self.total = total_iterations
        self.done = 0
        self.start = time.perf_counter()
        self.stream = stream

    def iteration(self, target: str, state: RunState, iterations: int) -> None:
        self.done += 1
        if not self.enabled:
            return
        elapsed = time.perf_counter() - self.start
        left = elapsed / self.done * (self.total - self.done)
        best = float(np.min(state.model_errors))
        print(f"  {target:6s} iteration {state.iteration:3d}/{iterations}  best suite error "
              f"{best:.5g}  elapsed {elapsed:6.1f} s  left ~{left:6.1f} s",
              file=self.stream, flush=True)

    def say(self, text: str) -> None:
        if self.enabled:
            print(text, file=self.stream, flush=True)


@one_blas_thread
def identify(dataset: Dataset, target: str, cfg: Config, history: HistoryWriter | None = None,
             progress: Progress | None = None, state: RunState | None = None,
             checkpoint_path: Path | None = None, history_start: int | None = None
             ) -> tuple[Equation, RunState]:
    """Run the coevolution for one target; returns its best equation and final state.

    With checkpoint_path, the state is saved atomically after every iteration together
    with the history file's size, and a run is continued from an existing checkpoint
    (the history is cut back to the size the checkpoint recorded; a run that starts
    afresh cuts it back to `history_start`, where this target's rows begin).
    On KeyboardInterrupt the exception is re-raised with the partial result attached
    as `exc.partial = (equation, state)`.
    """
    ev = cfg.evolution
    co = Coevolution(dataset, target, ev)
    if state is None and checkpoint_path is not None and checkpoint_path.exists():
        state = _resumed_state(co, checkpoint_path, history, history_start)
    if state is None:
        state = co.init_state(target_seed(cfg.seed, target))
        if history is not None and history_start is not None:
            history.truncate(history_start)
    report = None if progress is None else (
        lambda st: progress.iteration(target, st, ev.iterations))
    try:
        evolve(co, state, ev.iterations, history, checkpoint_path, on_iteration=report)
    except KeyboardInterrupt as exc:
        tree, train, val = co.best(state)
        exc.partial = (Equation(target, tree, dataset.input_names, train, val, dataset.trim), state)
        raise
    return final_equation(co, state, dataset, target), state


def _resumed_state(co: Coevolution, path: Path, history: HistoryWriter | None,
                   history_start: int | None) -> RunState | None:
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


#: Files and folders of a run folder that gpquad writes (none may be a link).
RUN_FILES = ("config.json", "run.json", "model.json", "history.csv", "equations.tex",
             "equations.md", "equations_raw_inputs.tex", "checkpoints")
#: Run folders whose lock this process holds (released when the process ends).
_HELD_LOCKS: dict[Path, object] = {}


def claim_run_folder(run_dir: Path, cfg: Config) -> bool:
    """Make or check the run folder and lock it for this process; True when it holds a run
    of this config to resume. Refused with one line: a folder with files that are not a
    gpquad run (a user's files, a sweep folder), a run of another config, a folder another
    gpquad command is writing (lock held), a run file that is a link."""
    if run_dir.exists() and not run_dir.is_dir():
        raise GpquadError("not a folder; give a folder for the run", source=str(run_dir),
                          field="--out")
    if (run_dir / "sweep.json").exists():
        raise GpquadError("a sweep folder (`gpquad sweep` resumes it), not a run folder; give "
                          "`gpquad run` another --out", source=str(run_dir), field="--out")
    entries = {p.name for p in run_dir.iterdir()} if run_dir.is_dir() else set()
    if entries - {".lock"} and "config.json" not in entries:
        raise GpquadError("the folder holds files that are not a gpquad run (no config.json); "
                          "give an empty or new --out", source=str(run_dir), field="--out")
    links = [name for name in RUN_FILES if (run_dir / name).is_symlink()]
    if links:
        raise GpquadError(f"{links[0]} is a link; gpquad writes no file through a link: give "
                          "another --out", source=str(run_dir), field="--out")
    run_dir.mkdir(parents=True, exist_ok=True)
    _lock(run_dir)
    return _same_config(run_dir, cfg)


def _lock(run_dir: Path) -> None:
    """An exclusive lock on run_dir/.lock held until the process ends (a second command on
    the same folder is refused; this process may claim it again)."""
    import fcntl

    key = run_dir.resolve()
    if key in _HELD_LOCKS:
        return
    try:
        fd = os.open(run_dir / ".lock", os.O_WRONLY | os.O_CREAT | os.O_NOFOLLOW, 0o644)
    except OSError as exc:
        raise GpquadError(f"cannot lock the folder ({exc.strerror})", source=str(run_dir),
                          field="--out") from None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        raise GpquadError("another gpquad command is writing this run folder; wait for it to "
                          "finish or give another --out", source=str(run_dir),
                          field="--out") from None
    _HELD_LOCKS[key] = fd


def _same_config(run_dir: Path, cfg: Config) -> bool:
    """Whether run_dir already holds a run of this config (then it is resumed).

    A folder with another config is refused rather than mixed.
    """
    path = run_dir / "config.json"
    if not path.exists():
        return False
    saved = read_json(path, "run folder", "the folder's config.json is damaged: give another "
                      "--out, or delete the folder to start again")
    if saved != json.loads(json.dumps(folder_config_dict(cfg))):
        raise GpquadError("the folder holds a run of a different config; give another --out "
                          "(or the same config to resume)", source=str(run_dir), field="--out")
    return True


def _finished_record(path: Path, dataset) -> tuple[Equation, int] | None:
    """A finished target's (equation, history end) from its record; None, with a warning,
    when the record is damaged (the target is then identified again)."""
    try:
        record = json.loads(path.read_text())
        equation = Equation.from_dict(path.stem, record["equation"], dataset.input_names,
                                      dataset.trim)
        end = record["history_bytes"]
        if type(end) is not int or not 0 < end <= (path.parents[1] / "history.csv").stat().st_size:
            raise ValueError(f"history_bytes {end!r} is not within history.csv")
        return equation, end
    except (OSError, UnicodeDecodeError, ValueError, KeyError, TypeError, IndexError,
            GpquadError) as exc:
        print(f"gpquad: warning: {path}: damaged record of a finished equation "
              f"({type(exc).__name__}); identifying {path.stem} again", file=sys.stderr)
        return None


def write_model(run_dir: Path, model: DiscoveredModel) -> None:
    write_json(run_dir / "model.json", model.to_dict())
    atomic_write_text(run_dir / "equations.tex", model.latex())
    atomic_write_text(run_dir / "equations.md", model.markdown())
    if any(model.trim.values()):
        atomic_write_text(run_dir / "equations_raw_inputs.tex", model.latex(raw=True))


def run_experiment(cfg: Config, run_dir=None, progress: bool | None = None) -> DiscoveredModel:
    """Identify every configured target and write the run folder.

    Bad data or config fails here, before any long work. Ctrl-C writes the equations
    found so far (model.json has "interrupted": true) and re-raises.
    """
    run_dir = Path(run_dir) if run_dir is not None else default_run_dir(cfg)
    show = cfg.output.progress if progress is None else progress
    started = time.time()
    dataset = load_dataset(cfg)
    resuming = claim_run_folder(run_dir, cfg)
    info = {"seed": cfg.seed, "config": cfg.to_dict(), "dataset": dataset.summary(),
            "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"), **provenance()}
    if not resuming:
        write_json(run_dir / "config.json", folder_config_dict(cfg))
    write_json(run_dir / "run.json", info)
    ev = cfg.evolution
    for target in ev.targets:
        missing = dataset.unmeasured(TARGET_STATE[target])
        if missing:
            print(f"gpquad: warning: {target} integrates {TARGET_STATE[target]}, which "
                  f"{', '.join(missing)} does not measure; its equation fits the log's "
                  "placeholder values", file=sys.stderr)
    report = Progress(show, ev.iterations * len(ev.targets))
    report.say(f"gpquad: {dataset.summary()['train_samples']} training samples at "
               f"{1 / dataset.dt:.4g} Hz; targets {', '.join(ev.targets)}; run folder {run_dir}")
    history = HistoryWriter(run_dir / "history.csv")
    equations: dict[str, Equation] = {}
    model = DiscoveredModel(equations, dataset.input_names, dataset.trim, dataset.dt, cfg.seed,
                            cfg.to_dict(), envelope=training_envelope(dataset))
    timings = {}
    done_dir = run_dir / "checkpoints"
    try:
        # Where the history of finished targets ends (the header, before any target).
        history_end = len((run_dir / "history.csv").read_bytes().split(b"\n", 1)[0]) + 1
        for target in ev.targets:
            done = done_dir / f"{target}.json"
            record = _finished_record(done, dataset) if resuming and done.exists() else None
            if record is not None:  # finished before the interruption
                equations[target] = record[0]
                history_end = record[1]
                report.done += ev.iterations
                report.say(f"  {target}: finished earlier (resumed from {done})")
                continue
            t0 = time.perf_counter()
            equations[target], _ = identify(dataset, target, cfg, history, report,
                                            checkpoint_path=done_dir / f"{target}.ckpt",
                                            history_start=history_end)
            timings[target] = time.perf_counter() - t0
            history_end = history.size()
            write_json(done, {"equation": equations[target].to_dict(),
                              "history_bytes": history_end})
            report.say(f"  -> {equations[target].text()}  (validation error "
                       f"{equations[target].validation_error:.4g})")
    except KeyboardInterrupt as exc:
        partial = getattr(exc, "partial", None)
        if partial is not None:
            equations[partial[0].target] = partial[0]
        model = dataclasses.replace(model, interrupted=True)
        write_model(run_dir, model)
        print(f"\ngpquad: interrupted; the equations found so far are in {run_dir}; the same "
              "command with the same --out resumes", file=sys.stderr)
        raise
    finally:
        history.close()
    model = finish_model(model, dataset, ev)
    if model.symmetrized is not None:
        report.say(symmetrized_summary(model.symmetrized))
    if model.refined is not None:
        report.say(refined_summary(model.refined))
    if model.stability is not None:
        report.say(stability_summary(model.stability))
    if model.joint_fit is not None:
        report.say(joint_fit_summary(model.joint_fit))
    if ev.mirror_inputs:
        found = mirror_odd_terms(model, dataset, ev.mirror_inputs)
        model = dataclasses.replace(model, mirror_parity=found)
        report.say(parity_summary(found, ev.mirror_inputs))
    write_model(run_dir, model)
    info.update(finished=time.strftime("%Y-%m-%dT%H:%M:%S%z"), wall_time_s=time.time() - started,
                target_time_s=timings)
    write_json(run_dir / "run.json", info)
    return model
