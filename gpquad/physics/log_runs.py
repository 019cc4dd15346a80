"""`gpquad physics thrust|drag|deadreckon` on a user's log: results, Markdown and figures
(the simulated-truth mode is in gpquad.physics.commands)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gpquad.physics.deadreckon import MODELS, compare_models
from gpquad.physics.identify import coefficients
from gpquad.physics.identify_log import identify_drag_log, identify_thrust_log, windows
from gpquad.physics.logdata import load_log_segments
from gpquad.physics.mixer import runs_of
from gpquad.physics.tables import THESIS_ORDER, fits_table, models_ordered

MAX_TRACK_FIGURES = 12


def _title(cfg) -> str:
    files = cfg.data.get("files", [])
    return f"{', '.join(Path(f).name for f in files)}, mass {cfg.vehicle.mass:g} kg"


def _log_lines(res: dict) -> list[str]:
    log = res["log"]
    lines = [
        f"Log: {', '.join(log['files'])} (format {log['format']}, frame {log['frame']}); "
        f"{len(log['segments'])} segment(s), "
        f"{sum(s['duration_s'] for s in log['segments']):.1f} s; {log['notes'][0]}.",
        "",
    ]
    return (
        lines
        + [f"Note: {n}" for n in res.get("notes", [])]
        + [f"Warning: {w}" for w in res.get("warnings", [])]
    )


def thrust_markdown_log(res: dict, cfg) -> str:
    hov = res["hover_fit_on_forward_validation"]
    beats = res["refined_beats_standard"]
    return "\n".join(
        [
            f"# Thrust identification ({_title(cfg)}, method {cfg.regression.method})",
            "",
            "Target m f_z (N); standard: k_t sum(w^2) (eq. 5) on near-hover samples and on all; "
            "refined: k_t sum(w^2) - k_z w sum(w) + k_h (u^2 + v^2) (eq. 19) on all.",
            "",
        ]
        + _log_lines(res)
        + [""]
        + fits_table(res["fits"], {})
        + [
            "",
            f"Hover fit applied to the flight's validation part: R^2 {hov['r2']:.4f}, "
            f"RMSE {hov['rmse']:.4f} N.",
            f"Refined beats standard on the validation parts (RMSE): "
            f"{'-' if beats is None else beats}.",
            "",
        ]
    )


def drag_markdown_log(res: dict, cfg) -> str:
    return "\n".join(
        [
            f"# Drag identification ({_title(cfg)}, method {cfg.regression.method})",
            "",
            "Target f_x, f_y (m/s^2); eq. (18): k_d v w_s, optionally + c |V| v (parasitic) and "
            "a constant (accelerometer bias). In N: multiply by the mass.",
            "",
        ]
        + _log_lines(res)
        + [""]
        + fits_table(res["fits"], {})
        + [""]
    )


def run_thrust_log(cfg, out: Path) -> dict:
    from gpquad.physics.plots import regression_figure, series_figure

    segs, summary = load_log_segments(cfg, ("rotor", "acc"), "thrust")
    res = identify_thrust_log(cfg, segs)
    res["log"] = summary
    s = res["_series"]
    hov = s["hover"]
    X = np.vstack([hov["Xtr"], hov["Xva"]])
    y = np.concatenate([hov["ytr"], hov["yva"]])
    coef = res["fits"]["standard_hover"]["coef"][0]
    regression_figure(
        X[:, 0],
        y,
        coef * X[:, 0],
        "sum of squared rotor speeds (rad/s)^2",
        "m f_z (N)",
        f"Standard thrust on near-hover samples (eq. 5): k_t = {coef:.4g}",
        out / "thrust_standard_hover.png",
    )
    fwd = s["forward"]
    if len(fwd["yva"]):
        preds = {
            f"{m} (RMSE val {res['fits'][m + '_forward']['rmse_val']:.3g} N)": p
            for m, p in s["preds"].items()
        }
        cut = np.flatnonzero(np.diff(fwd["tva"]) > 0.5) + 1  # no line between segments
        t_plot = np.insert(fwd["tva"], cut, np.nan)
        preds = {k: np.insert(v, cut, np.nan) for k, v in preds.items()}
        series_figure(
            t_plot,
            np.insert(fwd["yva"], cut, np.nan),
            preds,
            "m f_z (N)",
            "Thrust on the validation parts (segments joined)",
            out / "thrust_forward.png",
        )
    return res


def run_drag_log(cfg, out: Path) -> dict:
    from gpquad.physics.plots import regression_figure

    segs, summary = load_log_segments(cfg, ("rotor", "acc", "vel"), "drag")
    res = identify_drag_log(cfg, segs)
    res["log"] = summary
    for axis in (0, 1):
        key = "xy"[axis]
        p = res["_series"][key]
        X = np.vstack([p["Xtr"], p["Xva"]])
        y = np.concatenate([p["ytr"], p["yva"]])
        fitted = X @ np.asarray(res["fits"][key]["coef"])
        regression_figure(
            X[:, 0],
            y,
            fitted,
            f"v_b{key} w_s (m rad/s^2)",
            f"f_{key} (m/s^2)",
            f"Drag, eq. (18): k_d{key} = {res['fits'][key]['coef'][0]:.4g}",
            out / f"drag_{key}.png",
        )
    return res


def run_deadreckon_log(cfg, out: Path) -> dict:
    from gpquad.physics.plots import tracks_figure

    segs, summary = load_log_segments(cfg, ("rotor", "acc", "vel", "pos"), "deadreckon")
    thrust, drag = identify_thrust_log(cfg, segs), identify_drag_log(cfg, segs)
    coef = coefficients(thrust, drag, cfg.regression.parasitic_drag)
    notes = []
    for name in ("k_dx", "k_dy", "c_dx", "c_dy"):  # drag that pushes along the velocity
        if coef["drag"].get(name, 0.0) > 0:  # would make dead reckoning diverge
            notes.append(
                f"{name} = {coef['drag'][name]:.3g} is positive (the log does not "
                "identify it); dead reckoning uses 0"
            )
            coef["drag"][name] = 0.0
    mass = cfg.vehicle.mass
    flights = []
    for seg in segs:
        parts = [
            (a0 + a, a0 + b)
            for a0, b0 in runs_of(seg["airborne"])
            if b0 - a0 >= 10
            for a, b in windows({"t": seg["t"][a0:b0]}, cfg.deadreckon.window_s)
        ]
        for a, b in parts:
            cmp = compare_models(seg, coef, mass, a, b)
            rmse = {m: cmp[m]["rmse"] for m in MODELS}
            norms = {m: float(np.linalg.norm(rmse[m])) for m in MODELS}
            name = (
                seg["name"] if (a, b) == (0, len(seg["t"])) else f"{seg['name']}+{seg['t'][a]:.1f}s"
            )
            flights.append(
                {
                    "name": name,
                    "duration_s": float(seg["t"][b - 1] - seg["t"][a]),
                    "models": {m: {"rmse": rmse[m]} for m in MODELS},
                    "thesis_order": models_ordered(rmse),
                    "model_order": models_ordered(rmse, THESIS_ORDER[:3]),
                    "accelerometer_worse_than_base": norms["accelerometer"] > norms["base"],
                    "best": min(norms, key=norms.get),
                }
            )
            if len(flights) <= MAX_TRACK_FIGURES:
                safe = "".join(c if c.isalnum() or c in "-_." else "_" for c in name)
                tracks_figure(
                    seg["t"][a:b],
                    seg["pos"][a:b],
                    {m: cmp[m]["_track"] for m in MODELS},
                    f"Dead reckoning, {name}",
                    out / f"tracks_{safe}.png",
                )
    return {
        "source": "log",
        "log": summary,
        "coefficients": coef,
        "notes": notes,
        "warnings": drag.get("warnings", []),
        "flights": flights,
        "ordered_count": sum(f["thesis_order"] for f in flights),
        "model_order_count": sum(f["model_order"] for f in flights),
        "accelerometer_worst_count": sum(f["accelerometer_worse_than_base"] for f in flights),
        "coriolis_best_count": sum(f["best"] == "coriolis" for f in flights),
    }
