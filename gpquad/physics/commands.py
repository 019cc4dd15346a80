"""`gpquad physics thrust|drag|deadreckon CONFIG`: identification and dead reckoning on a
user's log (gpquad.physics.log_runs) or on simulated ground-truth flights (here), written as
run folders (JSON, Markdown table, figures, run.json)."""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np

from gpquad.physics.config import PhysicsConfig, load_physics_config
from gpquad.physics.deadreckon import MODELS, compare_models
from gpquad.physics.identify import coefficients, identify_drag, identify_thrust, load_flight
from gpquad.physics.runfolder import default_out, write_run
from gpquad.physics.tables import THESIS_ORDER, fits_table, models_ordered


def thrust_markdown(res: dict, cfg: PhysicsConfig) -> str:
    hov = res["hover_fit_on_forward_validation"]
    return "\n".join(
        [
            f"# Thrust identification ({cfg.truth.vehicle}, method {cfg.regression.method}, "
            f"seed {cfg.seed})",
            "",
            "Target m f_z (N); standard: k_t sum(w^2) (eq. 5); refined: k_t sum(w^2) - "
            "k_z w sum(w) + k_h (u^2 + v^2) (eq. 19). Truth from rotorpy's parameters (k_h = 4 "
            "rotor k_h).",
            "",
        ]
        + fits_table(res["fits"], res["truth"])
        + [
            "",
            f"Hover fit applied to the forward flight's validation part: R^2 {hov['r2']:.4f}, "
            f"RMSE {hov['rmse']:.4f} N.",
            f"Refined beats standard on forward flight (validation RMSE): "
            f"{res['refined_beats_standard']}.",
            "",
        ]
    )


def drag_markdown(res: dict, cfg: PhysicsConfig) -> str:
    return "\n".join(
        [
            f"# Drag identification ({cfg.truth.vehicle}, flights {', '.join(res['flights'])}, "
            f"method {cfg.regression.method}, seed {cfg.seed})",
            "",
            "Target f_x, f_y (m/s^2); eq. (18): k_d v w_s, optionally + c |V| v (parasitic). "
            "Truth: -4 k_d / m and -c_D / m from rotorpy's parameters.",
            "",
        ]
        + fits_table(res["fits"], res["truth"])
        + [""]
        + [f"Warning: {w}" for w in res.get("warnings", [])]
        + [""]
    )


def deadreckon_markdown(res: dict, cfg: PhysicsConfig) -> str:
    what = (
        f"{cfg.truth.vehicle}, seed {cfg.seed}"
        if cfg.source == "truth"
        else f"{', '.join(Path(f).name for f in cfg.data['files'])}, "
        + (
            f"windows of {cfg.deadreckon.window_s:g} s"
            if cfg.deadreckon.window_s
            else "whole segments"
        )
    )
    lines = [
        f"# Dead-reckoning position RMSE, m ({what})",
        "",
        "| manoeuvre | model | x | y | z | norm |",
        "|---|---|---|---|---|---|",
    ]
    for flight in res["flights"]:
        for m in MODELS:
            r = flight["models"][m]["rmse"]
            lines.append(
                f"| {flight['name']} | {m} | {r[0]:.3f} | {r[1]:.3f} | {r[2]:.3f} | "
                f"{np.linalg.norm(r):.3f} |"
            )
    lines += [
        "",
        f"Thesis order (Coriolis < refined < base < accelerometer, on the norm) holds "
        f"on {res['ordered_count']} of {len(res['flights'])} flights; "
        f"Coriolis < refined < base on {res['model_order_count']}; "
        f"accelerometer worse than base on "
        f"{res['accelerometer_worst_count']}; Coriolis best on "
        f"{res['coriolis_best_count']}.",
        "",
    ]
    lines += [f"Note: {n}" for n in res.get("notes", [])]
    return "\n".join(lines + [""] if res.get("notes") else lines)


def run_thrust(cfg: PhysicsConfig, out: Path) -> dict:
    from gpquad.physics.aero import thrust_regressors
    from gpquad.physics.identify import split
    from gpquad.physics.plots import regression_figure, series_figure
    from gpquad.physics.regression import predict

    res = identify_thrust(cfg)
    s = res["_series"]
    hover, fwd, mass = s["hover"], s["forward"], s["mass"]
    X = thrust_regressors("standard", hover["rotor"], hover["vel_body"])
    regression_figure(
        X[:, 0],
        mass * hover["force"][:, 2],
        predict(res["fits"]["standard_hover"], X),
        "sum of squared rotor speeds (rad/s)^2",
        "m f_z (N)",
        "Standard thrust on hover (eq. 5)",
        out / "thrust_standard_hover.png",
    )
    _, va = split(len(fwd["t"]), cfg.regression.validation_fraction)
    preds = {}
    for key, model in (("standard_forward", "standard"), ("refined_forward", "refined")):
        Xm = thrust_regressors(model, fwd["rotor"], fwd["vel_body"])
        preds[f"{model} (R^2 val {res['fits'][key]['r2_val']:.3f})"] = predict(
            res["fits"][key], Xm
        )[va]
    series_figure(
        fwd["t"][va],
        mass * fwd["force"][va, 2],
        preds,
        "m f_z (N)",
        "Thrust on the forward flight's validation part",
        out / "thrust_forward.png",
    )
    return res


def run_drag(cfg: PhysicsConfig, out: Path) -> dict:
    from gpquad.physics.plots import regression_figure

    res = identify_drag(cfg)
    flights = res["_series"]["flights"]
    for axis in (0, 1):
        x = np.concatenate([f["vel_body"][:, axis] * f["rotor"].mean(axis=1) for f in flights])
        y = np.concatenate([f["force"][:, axis] for f in flights])
        coef = res["fits"]["xy"[axis]]["coef"][0]
        regression_figure(
            x,
            y,
            coef * x,
            f"v_b{'xy'[axis]} w_s (m rad/s^2)",
            f"f_{'xy'[axis]} (m/s^2)",
            f"Drag, eq. (18): k_d{'xy'[axis]} = {coef:.4g}",
            out / f"drag_{'xy'[axis]}.png",
        )
    return res


def run_deadreckon(cfg: PhysicsConfig, out: Path) -> dict:
    from gpquad.physics.plots import tracks_figure

    thrust, drag = identify_thrust(cfg), identify_drag(cfg)
    coef = coefficients(thrust, drag, cfg.regression.parasitic_drag)
    mass = thrust["_series"]["mass"]
    flights = []
    for manoeuvre in cfg.deadreckon.manoeuvres:
        for yaw in cfg.deadreckon.yaw:
            meas = load_flight(cfg, manoeuvre, yaw)
            cmp = compare_models(meas, coef, mass)
            rmse = {m: cmp[m]["rmse"] for m in MODELS}
            norms = {m: float(np.linalg.norm(rmse[m])) for m in MODELS}
            flights.append(
                {
                    "name": meas["name"],
                    "duration_s": float(meas["t"][-1]),
                    "models": {m: {"rmse": rmse[m]} for m in MODELS},
                    "thesis_order": models_ordered(rmse),
                    "model_order": models_ordered(rmse, THESIS_ORDER[:3]),
                    "accelerometer_worse_than_base": norms["accelerometer"] > norms["base"],
                    "best": min(norms, key=norms.get),
                }
            )
            tracks_figure(
                meas["t"],
                meas["pos"],
                {m: cmp[m]["_track"] for m in MODELS},
                f"Dead reckoning, {meas['name']}",
                out / f"tracks_{meas['name']}.png",
            )
    return {
        "coefficients": coef,
        "flights": flights,
        "ordered_count": sum(f["thesis_order"] for f in flights),
        "model_order_count": sum(f["model_order"] for f in flights),
        "accelerometer_worst_count": sum(f["accelerometer_worse_than_base"] for f in flights),
        "coriolis_best_count": sum(f["best"] == "coriolis" for f in flights),
    }


def _runner(kind: str, source: str):
    """(run, markdown) of a command for a source of flights."""
    if source == "log":
        from gpquad.physics import log_runs as lr

        return {
            "thrust": (lr.run_thrust_log, lr.thrust_markdown_log),
            "drag": (lr.run_drag_log, lr.drag_markdown_log),
            "deadreckon": (lr.run_deadreckon_log, deadreckon_markdown),
        }[kind]
    return {
        "thrust": (run_thrust, thrust_markdown),
        "drag": (run_drag, drag_markdown),
        "deadreckon": (run_deadreckon, deadreckon_markdown),
    }[kind]


def json_summary(kind: str, result: dict, cfg: PhysicsConfig) -> dict:
    """The --json line (gpquad.physics.summary), in SI units."""
    from gpquad.physics.summary import deadreckon_json, drag_json, thrust_json
    from gpquad.physics.truth import vehicle_params

    mass = cfg.vehicle.mass if cfg.source == "log" else vehicle_params(cfg.truth.vehicle)["mass"]
    if kind == "thrust":
        return thrust_json(result, mass)
    if kind == "drag":
        return drag_json(result, mass, cfg.regression.parasitic_drag)
    return deadreckon_json(result)


def run_command(
    kind: str,
    config_path,
    out=None,
    seed: int | None = None,
    progress: bool = False,
    summary: bool = False,
):
    """Load the config (errors before any work), run, write the run folder. Returns the
    folder, or (folder, JSON summary) with summary=True."""
    started = time.time()
    cfg = load_physics_config(config_path)
    if seed is not None:
        cfg = dataclasses.replace(cfg, seed=seed)
    out = Path(out) if out else default_out(kind, cfg.name)
    out.mkdir(parents=True, exist_ok=True)
    runner = _runner(kind, cfg.source)
    result = runner[0](cfg, out)
    md = runner[1](result, cfg)
    write_run(out, kind, result, md, config=cfg.to_dict(), seed=cfg.seed, started=started)
    if progress:
        print(md)
    return (out, json_summary(kind, result, cfg)) if summary else out
