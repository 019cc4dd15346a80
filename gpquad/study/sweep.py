"""Resumable sweeps: every configured equation identified `runs` times, in parallel.

The folder layout is `gpquad.study.sweep_folders`; the seeds are
`gpquad.study.seeding.run_seed`, so a run's result depends on neither the number of jobs, the
finishing order, nor the other runs of the grid. The loop of one run is `gpquad.study.loop`,
the same as `gpquad run`'s.

Kill safety: after each iteration the run appends its history rows to history.csv,
fsyncs it, then atomically replaces checkpoint.bin, which records history.csv's length.
On resume the history is truncated to that length, so rows of an iteration that was
interrupted are never duplicated. A finished run writes result.json (atomically) and is
skipped from then on.
"""

from __future__ import annotations

import fcntl
import json
import os
import time
from pathlib import Path

import numpy as np

from gpquad.data.dataset import Dataset
from gpquad.engine.evolve.coevolution import Coevolution
from gpquad.engine.variables import target_index
from gpquad.errors import GpquadError
from gpquad.study import checkpoint
from gpquad.study.config import Config, folder_config_dict
from gpquad.study.fit import measured_targets
from gpquad.study.loop import evolve, final_equation
from gpquad.study.seeding import run_seed
from gpquad.study.store import HistoryWriter, checked_name, provenance, write_json
from gpquad.study.sweep_folders import RunKey, fingerprint, grid, run_dir

BACKENDS = ("loky", "dask")
#: Seconds to wait for a Dask scheduler given by --address.
SCHEDULER_TIMEOUT_S = 10


# --------------------------------------------------------------------------- one run
def _status(path: Path, **fields) -> None:
    write_json(path, {**fields, "time": time.time()})


def _restart_files(folder: Path) -> None:
    for name in ("checkpoint.bin", "history.csv", "status.json", "result.json"):
        p = folder / name
        if p.exists():
            p.unlink()


def _resume(folder: Path, fp: str):
    """(state, history_bytes, warning) from the run's checkpoint; state None to start anew."""
    ckpt = folder / "checkpoint.bin"
    hist = folder / "history.csv"
    if not ckpt.exists():
        return None, 0, None
    try:
        state, meta = checkpoint.load(ckpt)
        if meta.get("fingerprint") != fp:
            raise checkpoint.CorruptCheckpoint("written by a different config")
        if hist.is_symlink() or not hist.is_file():
            raise checkpoint.CorruptCheckpoint("history.csv is missing or not a regular file")
        return state, checkpoint.history_bytes(meta, 0, hist.stat().st_size), None
    except (checkpoint.CorruptCheckpoint, KeyError) as exc:
        return None, 0, f"{ckpt}: corrupt checkpoint ({exc}); restarting this run from scratch"


class OrphanedWorker(RuntimeError):
    """The sweep process that started this worker has died; the run stops at a checkpoint."""


def execute_run(cfg: Config, dataset: Dataset, key: RunKey, out) -> dict:
    """Run (or resume, or skip) one cell of the grid; returns its summary.

    Summary keys: target, repetition, train_error, validation_error, skipped (bool),
    warnings (list of str). The run folder is locked (flock) while the run works, so a
    worker left over from a killed sweep and the resumed sweep never write it together.
    """
    folder = run_dir(Path(out), key)
    folder.mkdir(parents=True, exist_ok=True)
    with open(folder / ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released by the kernel if this process dies
        return _execute_locked(cfg, dataset, key, folder)


def _execute_locked(cfg: Config, dataset: Dataset, key: RunKey, folder: Path) -> dict:
    parent = os.getppid()
    result_path = folder / "result.json"
    warnings: list[str] = []
    if result_path.exists():
        try:
            done = json.loads(result_path.read_text())
            return {**_summary(done), "skipped": True, "warnings": []}
        except (ValueError, KeyError, TypeError) as exc:
            warnings.append(f"{result_path}: unreadable ({exc}); running it again")
            result_path.unlink()
    fp = fingerprint(cfg)
    ev = cfg.evolution
    co = Coevolution(dataset, key.target, ev)
    hist = folder / "history.csv"
    ckpt = folder / "checkpoint.bin"
    status = folder / "status.json"
    state, history_bytes, warning = _resume(folder, fp)
    if state is not None:
        try:
            checkpoint.check_fits(state, co)
        except checkpoint.CorruptCheckpoint as exc:
            state, warning = None, f"{ckpt}: corrupt checkpoint ({exc}); restarting this run"
    if warning:
        warnings.append(warning)
    if state is None:
        _restart_files(folder)
        state = co.init_state(run_seed(cfg.seed, key.target, key.repetition))
    else:
        with open(hist, "r+b") as fh:  # drop rows written after the checkpoint
            fh.truncate(history_bytes)
    started = time.time()
    _status(
        status,
        target=key.target,
        repetition=key.repetition,
        iteration=state.iteration,
        iterations=ev.iterations,
        best_suite_error=float(np.min(state.model_errors)),
        started=started,
        state="running",
    )

    def after_iteration(st):
        _status(
            status,
            target=key.target,
            repetition=key.repetition,
            iteration=st.iteration,
            iterations=ev.iterations,
            best_suite_error=float(np.min(st.model_errors)),
            started=started,
            state="running",
        )
        if os.getppid() != parent:  # loky worker whose sweep was killed: stop here
            raise OrphanedWorker(
                f"{key.name}: sweep process gone; stopped at iteration "
                f"{st.iteration} (checkpointed)"
            )

    writer = HistoryWriter(hist)
    try:
        evolve(
            co,
            state,
            ev.iterations,
            writer,
            ckpt,
            {"fingerprint": fp, "target": key.target, "repetition": key.repetition},
            after_iteration,
        )
    finally:
        writer.close()
    eq = final_equation(co, state, dataset, key.target)
    train, val = eq.error, eq.validation_error
    result = {
        "target": key.target,
        "repetition": key.repetition,
        "seed": {
            "master": cfg.seed,
            "spawn_key": list(run_seed(cfg.seed, key.target, key.repetition).spawn_key),
        },
        "iterations": state.iteration,
        "train_error": train,
        "validation_error": val,
        "equation": eq.to_dict(),
    }
    write_json(result_path, result)
    _status(
        status,
        target=key.target,
        repetition=key.repetition,
        iteration=state.iteration,
        iterations=ev.iterations,
        best_suite_error=float(np.min(state.model_errors)),
        started=started,
        state="done",
        wall_s=time.time() - started,
    )
    return {**_summary(result), "skipped": False, "warnings": warnings}


def _summary(result: dict) -> dict:
    return {
        "target": result["target"],
        "repetition": int(result["repetition"]),
        "train_error": float(result["train_error"]),
        "validation_error": float(result["validation_error"]),
    }


# ------------------------------------------------------------------------ the sweep
def prepare(cfg: Config, out: Path, runs: int) -> dict:
    """Create or check the sweep folder; refuses a folder written by another config."""
    out = Path(out)
    fp = fingerprint(cfg)
    info_path = out / "sweep.json"
    if info_path.exists():
        try:
            old = json.loads(info_path.read_text())
        except ValueError:
            old = {}
        if old.get("fingerprint") not in (None, fp):
            raise GpquadError(
                "this folder holds a sweep of a different config (seed, data, "
                "simulator or evolution settings differ); give another --out",
                source=str(out),
                field="--out",
            )
    elif out.exists() and any(out.iterdir()):
        raise GpquadError(
            "folder exists and is not a sweep folder; give another --out",
            source=str(out),
            field="--out",
        )
    out.mkdir(parents=True, exist_ok=True)
    info = {
        "fingerprint": fp,
        "seed": cfg.seed,
        "name": cfg.name,
        "runs": runs,
        "targets": list(cfg.evolution.targets),
        "iterations": cfg.evolution.iterations,
        "base_dir": cfg.base_dir,
        "seeding": "run (target, k): SeedSequence(seed).spawn(7)[target_index]"
        ".spawn(k + 1)[k]; full model k: child 6, spawn(k + 1)[k]",
        **provenance(),
    }
    write_json(info_path, info)
    write_json(out / "config.json", folder_config_dict(cfg))
    return info


def precheck(out: Path, keys: list[RunKey], fp: str) -> list[str]:
    """Warnings for checkpoints that cannot be resumed (found before any work starts)."""
    found = []
    for key in keys:
        folder = run_dir(out, key)
        if (folder / "result.json").exists():
            continue
        _, _, warning = _resume(folder, fp)
        if warning:
            found.append(warning)
    return found


def _parallel(jobs: int, backend: str, address: str | None):
    """A context manager yielding a configured joblib.Parallel."""
    import contextlib

    from joblib import Parallel, parallel_config

    @contextlib.contextmanager
    def ctx():
        if backend == "loky":
            yield Parallel(n_jobs=jobs, backend="loky", return_as="generator_unordered")
            return
        from gpquad.extras import require

        distributed = require("dask.distributed", "gpquad sweep --backend dask")
        Client, LocalCluster = distributed.Client, distributed.LocalCluster

        cluster = None
        if address:
            try:
                client = Client(address, timeout=f"{SCHEDULER_TIMEOUT_S}s")
            except (OSError, TimeoutError, ValueError, TypeError) as exc:
                raise GpquadError(
                    f"no Dask scheduler answers at {address} within "
                    f"{SCHEDULER_TIMEOUT_S} s ({type(exc).__name__}); start one "
                    "(`dask scheduler`) or give its address",
                    field="--address",
                ) from None
        else:
            cluster = LocalCluster(
                n_workers=jobs,
                threads_per_worker=1,
                processes=True,
                host="127.0.0.1",
                dashboard_address=None,
                silence_logs=40,
            )
            client = Client(cluster)
        try:
            with parallel_config(backend="dask"):
                yield Parallel(n_jobs=-1 if address else jobs, return_as="generator_unordered")
        finally:
            client.close()
            if cluster is not None:
                cluster.close()

    return ctx()


def run_sweep(
    cfg: Config,
    out,
    *,
    runs: int | None = None,
    jobs: int = 1,
    backend: str = "loky",
    address: str | None = None,
    progress=None,
    assemble: bool = True,
) -> dict:
    """Run every missing cell of the grid, then assemble the full models.

    Returns {"runs": [summaries], "warnings": [...], "model": path or None}.
    """
    from gpquad.data.io import load_dataset

    if backend not in BACKENDS:
        raise GpquadError(f"choose one of {list(BACKENDS)}", field="--backend")
    if jobs < 1:
        raise GpquadError("must be >= 1", field="--jobs")
    out = Path(out)
    n_runs = cfg.sweep.runs if runs is None else int(runs)
    if n_runs < 1:
        raise GpquadError("must be >= 1", field="--runs")
    dataset = load_dataset(cfg)  # bad data fails here, before any long work
    cfg = measured_targets(cfg, dataset)
    for t in cfg.evolution.targets:  # window too long for the data fails here too
        Coevolution(dataset, t, cfg.evolution)
    prepare(cfg, out, n_runs)
    keys = grid(cfg, n_runs)
    warnings = precheck(out, keys, fingerprint(cfg))
    if progress is not None:
        progress.start(out, keys, cfg.evolution.iterations)
        for w in warnings:
            progress.warn(w)
    summaries = []
    t0 = time.time()
    try:
        from joblib import delayed

        with _parallel(jobs, backend, address) as parallel:
            for summary in parallel(delayed(execute_run)(cfg, dataset, k, str(out)) for k in keys):
                summaries.append(summary)
                for w in summary["warnings"]:
                    if w not in warnings:
                        warnings.append(w)
                        if progress is not None:
                            progress.warn(w)
                if progress is not None:
                    progress.run_done(summary)
    finally:
        if progress is not None:
            progress.stop()
    summaries.sort(key=lambda s: (target_index(s["target"]), s["repetition"]))
    model_path = None
    if assemble:
        from gpquad.study.assemble import assemble_sweep

        model_path = assemble_sweep(out, cfg, dataset, n_runs)
    info_path = out / "sweep.json"
    info = json.loads(info_path.read_text())
    info.update(
        last_wall_time_s=time.time() - t0,
        jobs=jobs,
        backend=backend,
        finished=time.strftime("%Y-%m-%dT%H:%M:%S%z"),
    )
    write_json(info_path, info)
    if progress is not None:
        progress.finished(summaries, model_path)
    return {"runs": summaries, "warnings": warnings, "model": model_path}


def default_out(cfg: Config) -> Path:
    """A stable folder name, so that the same command resumes the same sweep."""
    return Path(cfg.output.dir) / f"{checked_name(cfg.name)}-sweep-seed{cfg.seed}"
