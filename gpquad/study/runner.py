"""`gpquad run`: load the data, fit it (gpquad.study.fit) and write the run folder."""

from __future__ import annotations

import dataclasses
import json
import os
import sys
import time
from pathlib import Path

from gpquad.data.io import load_dataset
from gpquad.engine.evolve.coevolution import summed_phases
from gpquad.errors import GpquadError
from gpquad.models.equations import DiscoveredModel
from gpquad.study import workers as search_workers
from gpquad.study.config import Config, folder_config_dict
from gpquad.study.finishing import finish
from gpquad.study.fit import early_finish, measured_targets, new_model, search_equations
from gpquad.study.search import Progress
from gpquad.study.store import (
    atomic_write_text,
    checked_name,
    provenance,
    read_json,
    write_json,
)

#: run.json's layout: 1 = gpquad 0.1 (no "schema" key), 2 = 0.2 (time profile).
RUN_SCHEMA = 2


def default_run_dir(cfg: Config) -> Path:
    stamp = time.strftime("%Y%m%d-%H%M%S")
    return Path(cfg.output.dir) / f"{checked_name(cfg.name)}-seed{cfg.seed}-{stamp}"


#: Files and folders of a run folder that gpquad writes (none may be a link).
RUN_FILES = (
    "config.json",
    "run.json",
    "model.json",
    "history.csv",
    "equations.tex",
    "equations.md",
    "equations_raw_inputs.tex",
    "checkpoints",
)
#: Run folders whose lock this process holds (released when the process ends).
_HELD_LOCKS: dict[Path, object] = {}


def claim_run_folder(run_dir: Path, cfg: Config) -> bool:
    """Make or check the run folder and lock it for this process; True when it holds a run
    of this config to resume. Refused with one line: a folder with files that are not a
    gpquad run (a user's files, a sweep folder), a run of another config, a folder another
    gpquad command is writing (lock held), a run file that is a link."""
    if run_dir.exists() and not run_dir.is_dir():
        raise GpquadError(
            "not a folder; give a folder for the run", source=str(run_dir), field="--out"
        )
    if (run_dir / "sweep.json").exists():
        raise GpquadError(
            "a sweep folder (`gpquad sweep` resumes it), not a run folder; give "
            "`gpquad run` another --out",
            source=str(run_dir),
            field="--out",
        )
    entries = {p.name for p in run_dir.iterdir()} if run_dir.is_dir() else set()
    if entries - {".lock"} and "config.json" not in entries:
        raise GpquadError(
            "the folder holds files that are not a gpquad run (no config.json); "
            "give an empty or new --out",
            source=str(run_dir),
            field="--out",
        )
    links = [name for name in RUN_FILES if (run_dir / name).is_symlink()]
    if links:
        raise GpquadError(
            f"{links[0]} is a link; gpquad writes no file through a link: give another --out",
            source=str(run_dir),
            field="--out",
        )
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
        raise GpquadError(
            f"cannot lock the folder ({exc.strerror})", source=str(run_dir), field="--out"
        ) from None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        raise GpquadError(
            "another gpquad command is writing this run folder; wait for it to "
            "finish or give another --out",
            source=str(run_dir),
            field="--out",
        ) from None
    _HELD_LOCKS[key] = fd


def _same_config(run_dir: Path, cfg: Config) -> bool:
    """Whether run_dir already holds a run of this config (then it is resumed).

    A folder with another config is refused rather than mixed.
    """
    path = run_dir / "config.json"
    if not path.exists():
        return False
    saved = read_json(
        path,
        "run folder",
        "the folder's config.json is damaged: give another "
        "--out, or delete the folder to start again",
    )
    if saved != json.loads(json.dumps(folder_config_dict(cfg))):
        raise GpquadError(
            "the folder holds a run of a different config; give another --out "
            "(or the same config to resume)",
            source=str(run_dir),
            field="--out",
        )
    return True


def write_model(run_dir: Path, model: DiscoveredModel) -> None:
    write_json(run_dir / "model.json", model.to_dict())
    atomic_write_text(run_dir / "equations.tex", model.latex())
    atomic_write_text(run_dir / "equations.md", model.markdown())
    if any(model.trim.values()):
        atomic_write_text(run_dir / "equations_raw_inputs.tex", model.latex(raw=True))


def run_experiment(
    cfg: Config,
    run_dir=None,
    progress: bool | None = None,
    dataset=None,
    jobs: int = 1,
    after=None,
    searched=None,
    seconds: dict | None = None,
    in_process: bool = False,
    idle=None,
) -> DiscoveredModel:
    """Identify every configured target and write the run folder.

    Bad data or config fails here, before any long work. Ctrl-C writes the equations
    found so far (model.json has "interrupted": true) and re-raises. `dataset`: the data
    already loaded (gpquad.fit), else the config's. `after(model, dataset)` runs once the
    model is written (the command line draws its figures there, on the loaded data).
    `seconds`, if given, receives the fit's profile as gpquad.study.fit.fit_dataset's (the
    same numbers run.json keeps). `jobs`: the cores to use; `in_process`: search every
    target in this process, on `jobs` threads, checkpointing every iteration; `idle()`
    runs once when the searches' worker processes leave a core idle
    (gpquad.study.fit.search_equations).
    """
    run_dir = Path(run_dir) if run_dir is not None else default_run_dir(cfg)
    show = cfg.output.progress if progress is None else progress
    started = time.time()
    report = Progress(show, cfg.evolution.iterations * len(cfg.evolution.targets))
    t_load = time.perf_counter()
    if dataset is None:
        report.say("gpquad: loading the flight data ...")
        dataset = load_dataset(cfg)
    load_seconds = time.perf_counter() - t_load
    cfg = measured_targets(cfg, dataset)
    report.total = cfg.evolution.iterations * len(cfg.evolution.targets)
    resuming = claim_run_folder(run_dir, cfg)
    info = {
        "schema": RUN_SCHEMA,
        "seed": cfg.seed,
        "config": cfg.to_dict(),
        "dataset": dataset.summary(),
        "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        **provenance(),
    }
    if not resuming:
        write_json(run_dir / "config.json", folder_config_dict(cfg))
    write_json(run_dir / "run.json", info)
    ev = cfg.evolution
    phases: dict[str, dict[str, float]] = {}
    report.say(
        f"gpquad: {dataset.summary()['train_samples']} training samples at "
        f"{1 / dataset.dt:.4g} Hz; targets {', '.join(ev.targets)}; run folder {run_dir}"
    )
    with early_finish(dataset, cfg, jobs) as early:
        try:
            equations, timings = search_equations(
                dataset, cfg, report, run_dir, resuming, jobs, in_process, idle, phases, early
            )
        except KeyboardInterrupt as exc:
            model = new_model(getattr(exc, "equations", {}), dataset, cfg)
            write_model(run_dir, dataclasses.replace(model, interrupted=True))
            print(
                f"\ngpquad: interrupted; the equations found so far are in {run_dir}; the "
                "same command with the same --out resumes",
                file=sys.stderr,
            )
            raise
        compile_wait = search_workers.warm_up_wait()
        if searched is not None:
            searched(run_dir)
        finish_seconds: dict[str, float] = {}
        model = finish(
            new_model(equations, dataset, cfg), dataset, cfg, report, finish_seconds, jobs, early
        )
    write_model(run_dir, model)
    wall = time.time() - started
    info.update(
        finished=time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        wall_time_s=wall,
        load_time_s=load_seconds,
        compile_wait_s=compile_wait,
        target_time_s=timings,
        search_phase_time_s=phases,
        finish_time_s=finish_seconds,
        early_finish_s=early.busy_s,
    )
    write_json(run_dir / "run.json", info)
    if seconds is not None:
        seconds.update(
            search=timings,
            phases=phases,
            finish=finish_seconds,
            early_finish=early.busy_s,
            compile_wait=compile_wait,
        )
    report.say(time_profile(wall, load_seconds, timings, finish_seconds, compile_wait))
    if phases:
        report.say(phase_profile(phases))
    if after is not None:
        after(model, dataset)
    return model


def phase_profile(phases: dict[str, dict[str, float]]) -> str:
    """One line: the searches' phases (gpquad.engine.evolve.coevolution.PHASES), each summed
    over the searches (searches run side by side: these are process seconds, not wall)."""
    total = summed_phases(phases)
    parts = [f"{p} {s:.1f}" for p, s in total.items() if s > 0]
    return f"searches, summed: {sum(total.values()):.1f} s; " + ", ".join(parts) + " (s)"


def time_profile(
    wall: float,
    load: float,
    searches: dict[str, float],
    finishing: dict[str, float],
    compile_wait: float = 0.0,
) -> str:
    """One line: where a run's wall time went (run.json keeps the numbers); the wait for
    the kernels' compilation (a cold cache) where it took 0.1 s or more."""
    waited = [f"compiling the kernels {compile_wait:.1f}"] if compile_wait >= 0.1 else []
    parts = (
        [f"loading {load:.1f}"]
        + waited
        + [f"{t} {s:.1f}" for t, s in searches.items()]
        + [f"{name} {s:.1f}" for name, s in finishing.items()]
    )
    return f"time: {wall:.1f} s in all; " + ", ".join(parts) + " (s)"
