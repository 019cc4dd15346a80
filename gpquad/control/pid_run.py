"""`gpquad control pid RUN_DIR`: evolve the PID on a discovered model, then fly it on test
courses on the model and (for a simulator-identified model) on the truth plant."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from gpquad.control.config import ControlConfig
from gpquad.control.courses import course_length, random_course
from gpquad.control.evolve import evolve_gains
from gpquad.control.pid import fly, input_noise, make_controller
from gpquad.control.plant import design_point, model_plant, truth_plant
from gpquad.errors import GpquadError
from gpquad.study.store import atomic_write_text, provenance, write_json


def load_run(run_dir: Path):
    """(model, folder config, dataset) of a gpquad run folder."""
    from gpquad.data.io import load_dataset
    from gpquad.models.equations import DiscoveredModel
    from gpquad.study.config import load_folder_config

    if not (run_dir / "model.json").is_file():
        raise GpquadError(
            "not a gpquad run folder (no model.json); give the folder that `gpquad run` wrote",
            source=str(run_dir),
        )
    model = DiscoveredModel.load(run_dir)
    missing = [
        t for t in ("a_x", "a_y", "a_z", "p_dot", "q_dot", "r_dot") if t not in model.equations
    ]
    if missing:
        raise GpquadError(
            f"the model has no equation for {missing}; the PID flies all six",
            source=str(run_dir / "model.json"),
            field="targets",
        )
    cfg = load_folder_config(run_dir)
    return model, cfg, load_dataset(cfg)


def input_ranges(dataset, fraction: float, margin: float):
    """(noise SD, lo, hi) per input: SD = fraction x max |trim-subtracted input| over the
    training data (paper: 10 %); lo/hi = raw training range widened by margin x span."""
    rows = np.concatenate([np.arange(a, b) for a, b in dataset.train])
    trimmed = dataset.arrays.inputs[rows]
    trim = np.array([dataset.trim.get(n, 0.0) for n in dataset.input_names])
    raw = trimmed + trim
    lo, hi = raw.min(axis=0), raw.max(axis=0)
    span = np.maximum(hi - lo, 1e-9)
    return fraction * np.abs(trimmed).max(axis=0), lo - margin * span, hi + margin * span, span


def _summaries(flights) -> dict:
    rmse = [f.score.rmse_m for f in flights]
    comp = [f.score.completion for f in flights]
    return {
        "rmse_m_mean": float(np.mean(rmse)),
        "rmse_m": rmse,
        "completion_mean": float(np.mean(comp)),
        "completion": comp,
        "diverged": int(sum(f.score.diverged for f in flights)),
    }


def run_pid(
    run_dir,
    cfg: ControlConfig,
    out_dir,
    courses: int = 1,
    seed: int | None = None,
    say=print,
    figures: bool = True,
) -> dict:
    """Evolve, test and write the run folder; returns the summary (summary.json)."""
    run_dir, out_dir = Path(run_dir), Path(out_dir)
    if courses < 1:
        raise GpquadError("must be >= 1", field="--courses")
    seed = cfg.seed if seed is None else int(seed)
    p = cfg.pid
    started = time.time()
    model, run_cfg, dataset = load_run(run_dir)
    plant = model_plant(model, p.model_form)
    sd, lo, hi, span = input_ranges(dataset, p.input_noise, p.input_margin)
    design = design_point(plant, span, source=str(run_dir / "model.json"))
    truth = None
    if not run_cfg.data.files:
        from gpquad.data.simulator import completed

        sim = completed(run_cfg.simulator)
        truth = truth_plant(sim.equations, run_cfg.data.inputs, model.dt)
        truth.integrator, truth.substeps = sim.integrator, sim.substeps  # as the simulator flew it
    say(
        f"gpquad control pid: model {run_dir} ({len(model.input_names)} inputs, "
        f"{p.input_level}-level), channels {design.to_dict(model.input_names)['channels']}; "
        f"truth plant: {'reference simulator' if truth else 'none (real data)'}; seed {seed}"
    )
    start = make_controller(p.nominal_gains, design, lo, hi, p)
    evo = evolve_gains(plant, start, p, sd, seed, say=say)
    ctrl = evo.controller
    test_rng = np.random.default_rng(np.random.SeedSequence([seed, 34]))
    tests = []
    for _ in range(courses):
        wp = random_course(p.course, test_rng)
        noises = [input_noise(test_rng, wp, p, plant.dt, sd) for _ in range(2 * p.repetitions)]
        on_model = [fly(plant, ctrl, wp, n) for n in noises[: p.repetitions]]
        on_truth = [fly(truth, ctrl, wp, n) for n in noises[p.repetitions :]] if truth else []
        tests.append({"waypoints": wp, "model": on_model, "truth": on_truth})
    summary = {
        "model_rmse_m": float(np.mean([f.score.rmse_m for t in tests for f in t["model"]])),
        "truth_rmse_m": (
            float(np.mean([f.score.rmse_m for t in tests for f in t["truth"]])) if truth else None
        ),
        "completion": (
            float(np.mean([f.score.completion for t in tests for f in t["truth"]]))
            if truth
            else None
        ),
        "model_completion": float(np.mean([f.score.completion for t in tests for f in t["model"]])),
        "model_diverged": int(sum(f.score.diverged for t in tests for f in t["model"])),
        "courses": courses,
        "repetitions": p.repetitions,
        "seed": seed,
    }
    if truth:
        summary["rmse_ratio"] = summary["truth_rmse_m"] / max(summary["model_rmse_m"], 1e-12)
    details = {
        "run": str(run_dir),
        "gains": ctrl.gains_dict(),
        "design_point": design.to_dict(model.input_names),
        "input_noise_sd": dict(zip(model.input_names, sd.tolist(), strict=True)),
        "input_limits": {
            n: [float(a), float(b)] for n, a, b in zip(model.input_names, lo, hi, strict=True)
        },
        "fitness": "completion / (1 + rmse / d0), minus 1 if the flight diverged; "
        f"d0 = {p.deviation_scale_m} m",
        "evolution": {
            "best_fitness": evo.best_fitness,
            "evaluations": evo.evaluations,
            "wall_time_s": evo.wall_time_s,
            "cma_version": evo.cma_version,
            "history": evo.history,
        },
        "tests": [
            {
                "waypoints": t["waypoints"].tolist(),
                "length_m": course_length(t["waypoints"]),
                "model": _summaries(t["model"]),
                "truth": _summaries(t["truth"]) if t["truth"] else None,
            }
            for t in tests
        ],
    }
    out_dir.mkdir(parents=True, exist_ok=True)
    write_json(out_dir / "summary.json", {**summary, **details})
    write_json(
        out_dir / "run.json",
        {
            "command": "control pid",
            "seed": seed,
            "config": _config_dict(cfg),
            "model_run": str(run_dir),
            "wall_time_s": time.time() - started,
            **provenance_with_control(),
        },
    )
    atomic_write_text(out_dir / "paths.csv", _paths_csv(tests, plant.dt))
    if figures:
        from gpquad.control.figures import evolution_figure, paths_figure

        for i, t in enumerate(tests):
            paths_figure(
                t, out_dir / f"paths_course{i + 1}.png", title=f"course {i + 1}", dt=plant.dt
            )
        evolution_figure(evo.history, out_dir / "evolution.png")
    return summary


def _paths_csv(tests, dt: float) -> str:
    lines = ["course,plant,repetition,t,x,y,z,target"]
    for c, t in enumerate(tests):
        for plant in ("model", "truth"):
            for r, f in enumerate(t[plant]):
                for k in range(f.flown + 1):
                    x, y, z = f.pos[k]
                    lines.append(
                        f"{c + 1},{plant},{r + 1},{k * dt:.4f},{x:.5f},{y:.5f},{z:.5f},"
                        f"{int(f.target[k])}"
                    )
    return "\n".join(lines) + "\n"


def _config_dict(cfg: ControlConfig) -> dict:
    import dataclasses

    return dataclasses.asdict(cfg)


def provenance_with_control() -> dict:
    """gpquad's provenance plus the versions of cma and python-control."""
    from importlib import metadata

    info = provenance()
    for name in ("cma", "control"):
        try:
            info["versions"][name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            info["versions"][name] = "not installed"
    return info


def summary_line(summary: dict) -> str:
    return json.dumps(summary)
