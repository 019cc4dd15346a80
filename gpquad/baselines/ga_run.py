"""`gpquad baseline ga-gradient|ga`: identify the 12-state model and write a run folder."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from gpquad.baselines import ga_identify as gi
from gpquad.baselines import quad12
from gpquad.baselines.flyable import Quad12Model
from gpquad.baselines.ga_config import GAConfig
from gpquad.baselines.plots import convergence_png
from gpquad.baselines.runfolder import write_flights, write_run
from gpquad.baselines.schema import to_dict
from gpquad.study.store import atomic_write_bytes, write_json


def recovery(cfg: GAConfig, params: dict[str, float]) -> dict[str, float]:
    """Relative error (%) of each fitted parameter against the truth."""
    truth = cfg.simulator.true_params
    return {p: 100.0 * (v - truth[p]) / truth[p] for p, v in params.items()}


def fit(cfg: GAConfig, noise_sd, gradient: bool):
    """Identify every loop from data with the given state noise: (params, times, costs)."""
    _, measured = gi.simulate(cfg, noise_sd)
    results, problems, times = gi.identify_loops(cfg, measured, gradient, cfg.seed)
    costs = {loop: float(r.best_cost[-1]) for loop, r in results.items()}
    return gi.assemble(cfg, results, problems), times, costs


def run_ga_baseline(
    cfg: GAConfig, method: str, run_dir: Path, study: bool = True, say=print
) -> dict:
    """Fit, measure recovery (noise-free and noisy), run the convergence study, write files."""
    started = time.time()
    gradient = method == "ga-gradient"
    say(f"gpquad baseline {method}: loops {', '.join(cfg.ga.loops)}; run folder {run_dir}")
    params, times, costs = fit(cfg, cfg.simulator.noise_sd, gradient)
    noise_free = params if not any(cfg.simulator.noise_sd) else fit(cfg, (), gradient)[0]
    noisy = fit(cfg, cfg.study.noise_sd, gradient)[0] if any(cfg.study.noise_sd) else None
    rec = {"noise_free_pct": recovery(cfg, noise_free)}
    if noisy is not None:
        rec["noisy_pct"] = recovery(cfg, noisy)
        rec["noisy_sd"] = list(cfg.study.noise_sd)
    for key in ("noise_free_pct", "noisy_pct"):
        if key in rec:
            say(f"  {key}: max |error| {max(abs(v) for v in rec[key].values()):.3f} %")
    results = {
        "method": method,
        "fit_time_s": float(sum(times.values())),
        "loop_time_s": times,
        "final_cost": costs,
        "recovery": rec,
    }
    if study and cfg.study.seeds > 0:
        conv = gi.convergence_study(cfg, progress=say)
        results["convergence"] = {k: conv[k]["summary"] for k in ("gradient", "traditional")}
        results["convergence"]["evaluations_to_threshold_median"] = {
            k: float(np.median(conv[k]["evaluations_to_threshold"]))
            for k in ("gradient", "traditional")
            if conv[k]["evaluations_to_threshold"]
        }
        for k in ("gradient", "traditional"):
            s = conv[k]["summary"]["all"]
            say(
                f"  {k} GA: generations to {cfg.study.fraction:.0%} of the initial error: median "
                f"{s['median']:g} (IQR {s['q25']:g}-{s['q75']:g}, range {s['min']:g}-"
                f"{s['max']:g}, not reached {s['not_reached']}) over {cfg.study.seeds} seeds"
            )
        write_json(run_dir / "convergence.json", conv)
        atomic_write_bytes(run_dir / "convergence.png", convergence_png(conv, cfg.study.fraction))
    truth, _ = gi.simulate(cfg)
    results["scoring_data"] = write_flights(
        run_dir, [quad12.to_flight(truth, "quad12_truth")], cfg.validation_fraction
    )
    complete = all(p in params for p in quad12.PARAMS)
    model = {
        "method": method,
        "model": "quad12",
        "parameters": params,
        "state_names": list(quad12.STATES),
        "input_names": list(quad12.VOLTAGES),
        "input_map": {
            "u_1": f"V_1 + V_2 + V_3 + V_4 - {4 * cfg.simulator.v_hover!r}",
            "u_2": "V_4 - V_2",
            "u_3": "V_1 - V_3",
            "u_4": "V_1 - V_2 + V_3 - V_4",
        },
        "v_hover": cfg.simulator.v_hover,
        "substeps": cfg.simulator.substeps,
        "dt": 1.0 / cfg.simulator.rate_hz,
        "seed": cfg.seed,
    }
    if complete:
        model["equations"] = Quad12Model(
            np.array([params[p] for p in quad12.PARAMS]),
            cfg.simulator.v_hover,
            cfg.simulator.substeps,
        ).equations()
    write_run(run_dir, model, to_dict(cfg), results, started)
    return results
