"""`gpquad run`: load the data, fit it (gpquad.study.fit) and write the run folder."""

from __future__ import annotations

import dataclasses
import json
import sys
import time
from pathlib import Path

from gpquad.data.io import load_dataset
from gpquad.errors import GpquadError
from gpquad.models.equations import DiscoveredModel
from gpquad.study.config import Config, folder_config_dict
from gpquad.study.fit import finish, new_model, search_equations, warn_unmeasured
from gpquad.study.search import Progress
from gpquad.study.store import atomic_write_text, provenance, read_json, write_json

#: run.json's layout: 1 = gpquad 0.1 (no "schema" key), 2 = 0.2 (time profile).
RUN_SCHEMA = 2


def default_run_dir(cfg: Config) -> Path:
    stamp = time.strftime("%Y%m%d-%H%M%S")
    return Path(cfg.output.dir) / f"{cfg.name}-seed{cfg.seed}-{stamp}"


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


def write_model(run_dir: Path, model: DiscoveredModel) -> None:
    write_json(run_dir / "model.json", model.to_dict())
    atomic_write_text(run_dir / "equations.tex", model.latex())
    atomic_write_text(run_dir / "equations.md", model.markdown())
    if any(model.trim.values()):
        atomic_write_text(run_dir / "equations_raw_inputs.tex", model.latex(raw=True))


def run_experiment(cfg: Config, run_dir=None, progress: bool | None = None,
                   dataset=None) -> DiscoveredModel:
    """Identify every configured target and write the run folder.

    Bad data or config fails here, before any long work. Ctrl-C writes the equations
    found so far (model.json has "interrupted": true) and re-raises. `dataset`: the data
    already loaded (gpquad.fit), else the config's.
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
    resuming = _same_config(run_dir, cfg)
    run_dir.mkdir(parents=True, exist_ok=True)
    info = {"schema": RUN_SCHEMA, "seed": cfg.seed, "config": cfg.to_dict(),
            "dataset": dataset.summary(),
            "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"), **provenance()}
    if not resuming:
        write_json(run_dir / "config.json", folder_config_dict(cfg))
    write_json(run_dir / "run.json", info)
    ev = cfg.evolution
    warn_unmeasured(dataset, ev.targets)
    report.say(f"gpquad: {dataset.summary()['train_samples']} training samples at "
               f"{1 / dataset.dt:.4g} Hz; targets {', '.join(ev.targets)}; run folder {run_dir}")
    try:
        equations, timings = search_equations(dataset, cfg, report, run_dir, resuming)
    except KeyboardInterrupt as exc:
        model = new_model(getattr(exc, "equations", {}), dataset, cfg)
        write_model(run_dir, dataclasses.replace(model, interrupted=True))
        print(f"\ngpquad: interrupted; the equations found so far are in {run_dir}; the same "
              "command with the same --out resumes", file=sys.stderr)
        raise
    finish_seconds: dict[str, float] = {}
    model = finish(new_model(equations, dataset, cfg), dataset, cfg, report, finish_seconds)
    write_model(run_dir, model)
    wall = time.time() - started
    info.update(finished=time.strftime("%Y-%m-%dT%H:%M:%S%z"), wall_time_s=wall,
                load_time_s=load_seconds, target_time_s=timings, finish_time_s=finish_seconds)
    write_json(run_dir / "run.json", info)
    report.say(time_profile(wall, load_seconds, timings, finish_seconds))
    return model


def time_profile(wall: float, load: float, searches: dict[str, float],
                 finishing: dict[str, float]) -> str:
    """One line: where a run's wall time went (run.json keeps the numbers)."""
    parts = [f"loading {load:.1f}"] + [f"{t} {s:.1f}" for t, s in searches.items()] + \
        [f"{name} {s:.1f}" for name, s in finishing.items()]
    return f"time: {wall:.1f} s in all; " + ", ".join(parts) + " (s)"
