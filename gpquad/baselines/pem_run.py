"""`gpquad baseline pem`: closed-loop PEM on the body-centric model; writes a run folder."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from gpquad.baselines import pem
from gpquad.baselines import pem_sim as ps
from gpquad.baselines.flyable import BodyModel
from gpquad.baselines.geometry import initial_guess
from gpquad.baselines.pem_config import PARAMS, PemConfig
from gpquad.baselines.runfolder import write_flights, write_run
from gpquad.baselines.schema import to_dict


def initial_theta(cfg: PemConfig) -> np.ndarray:
    v = cfg.vehicle
    return ps.theta_array(initial_guess(cfg.geometry, v.arm_length, v.mass, v.gravity))


def error_table(cfg: PemConfig, fit: pem.PemFit, train, unseen, noise_sd, rng) -> list[dict]:
    """E (eq. 17) with the initial and refined parameters on training and unseen flights."""
    rows = []
    for name, rec in [("training", train)] + [(f"unseen {i + 1}", r) for i, r in enumerate(unseen)]:
        y = ps.add_noise(rec.outputs(), noise_sd, rng)
        lam = pem.weights(y)
        e0 = pem.error(fit.theta0, cfg, rec, y, lam)
        e1 = pem.error(fit.theta, cfg, rec, y, lam)
        rows.append(
            {
                "data": name,
                "E_initial": e0,
                "E_refined": e1,
                "improvement_pct": 100.0 * (e0 - e1) / e0,
            }
        )
    return rows


def pct(theta, truth) -> dict[str, float]:
    return {p: float(100.0 * (a - b) / b) for p, a, b in zip(PARAMS, theta, truth, strict=True)}


def run_pem_baseline(cfg: PemConfig, run_dir: Path, say=print) -> dict:
    """Fit noise-free and noisy data, tabulate E, show the open-loop failure, write files."""
    started = time.time()
    s = cfg.simulator
    say(
        f"gpquad baseline pem: {s.train_s:g} s training flight, {len(s.unseen_s)} unseen; "
        f"run folder {run_dir}"
    )
    truth = ps.theta_array(s.true_params)
    theta0 = initial_theta(cfg)
    full = ps.simulate(cfg, s.train_s, 0)
    n_train = len(full.t) - int(round(cfg.validation_fraction * len(full.t)))
    train = full.head(n_train)
    unseen = [ps.simulate(cfg, d, i + 1) for i, d in enumerate(s.unseen_s)]
    out = {
        "initial_guess": dict(zip(PARAMS, theta0.tolist(), strict=True)),
        "initial_error_pct": pct(theta0, truth),
    }
    fits = {}

    def run(label, sd):
        rng = np.random.default_rng(np.random.SeedSequence([s.seed, 100]))
        f = pem.fit(cfg, train, ps.add_noise(train.outputs(), sd, rng), theta0)
        say(
            f"  {label:10s}: E {f.e_initial:.4g} -> {f.e_refined:.4g} in {f.iterations} "
            f"iterations ({f.fit_time_s:.1f} s); max |param error| "
            f"{max(abs(v) for v in pct(f.theta, truth).values()):.2f} %"
        )
        table = error_table(
            cfg, f, train, unseen, sd, np.random.default_rng(np.random.SeedSequence([s.seed, 200]))
        )
        out[label] = {
            "parameters": dict(zip(PARAMS, f.theta.tolist(), strict=True)),
            "error_pct": pct(f.theta, truth),
            "noise_sd": list(sd),
            "E_initial": f.e_initial,
            "E_refined": f.e_refined,
            "iterations": f.iterations,
            "evaluations": f.evaluations,
            "fit_time_s": f.fit_time_s,
            "message": f.message,
            "E_table": table,
        }
        return f

    fits["configured"] = run("configured", s.noise_sd)
    fits["noise_free"] = run("noise_free", ()) if any(s.noise_sd) else fits["configured"]
    fits["noisy"] = run("noisy", cfg.noisy_sd)
    main = fits["configured"]
    # Open loop: prediction horizon, and identification with recorded motor speeds.
    horizon = {}
    for label, theta in (("refined_noisy", fits["noisy"].theta), ("truth", truth)):
        d = pem.divergence_times(
            theta, cfg, unseen[0], cfg.pem.open_loop_windows_s, cfg.pem.divergence_rad
        )
        horizon[label] = {
            m: {
                "median_s": float(np.median(v)),
                "min_s": float(v.min()),
                "max_s": float(v.max()),
                "windows": int(len(v)),
            }
            for m, v in d.items()
        }
    open_fit = pem.fit(cfg, train, train.outputs(), theta0, closed=False)
    out["open_loop"] = {
        "divergence_rad": cfg.pem.divergence_rad,
        "window_s": cfg.pem.open_loop_windows_s,
        "horizon": horizon,
        "open_loop_identification": {
            "E_initial": open_fit.e_initial,
            "E_refined": open_fit.e_refined,
            "error_pct": pct(open_fit.theta, truth),
            "message": open_fit.message,
        },
    }
    h = horizon["refined_noisy"]
    worst = max(abs(v) for v in out["open_loop"]["open_loop_identification"]["error_pct"].values())
    say(
        f"  open loop: attitude off by > {cfg.pem.divergence_rad} rad after "
        f"{h['open']['median_s']:.2f} s (median; closed loop {h['closed']['median_s']:.2f} s "
        f"of {cfg.pem.open_loop_windows_s:g}); open-loop PEM max |param error| {worst:.1f} %"
    )
    flights = [ps.to_flight(full, "body_train")] + [
        ps.to_flight(r, f"body_unseen{i + 1}") for i, r in enumerate(unseen)
    ]
    out["scoring_data"] = write_flights(run_dir, flights, cfg.validation_fraction)
    out["fit_time_s"] = main.fit_time_s
    v = cfg.vehicle
    body = BodyModel(main.theta, ps.vehicle_array(cfg), np.array(cfg.controller.gain), s.substeps)
    model = {
        "method": "pem",
        "model": "body-centric",
        "parameters": dict(zip(PARAMS, main.theta.tolist(), strict=True)),
        "parameters_initial": dict(zip(PARAMS, theta0.tolist(), strict=True)),
        "equations": body.equations(),
        "input_names": list(ps.REF_NAMES),
        "vehicle": body.vehicle.tolist(),
        "vehicle_names": ["l", "m", "g", "omega_min", "omega_max"],
        "controller_gain": body.gain.tolist(),
        "controller": "Omega_i = Omega_T - sum_j K_ij e_j, e = [phi - phi_r, "
        "theta - theta_r, psi - psi_r, p, q, r]",
        "substeps": s.substeps,
        "dt": 1.0 / s.rate_hz,
        "seed": cfg.seed,
        "mass": v.mass,
    }
    write_run(run_dir, model, to_dict(cfg), out, started)
    return out
