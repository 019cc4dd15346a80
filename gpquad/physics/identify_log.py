"""Thrust, drag and dead reckoning on a user's log (thesis IV.B-C, V), as plain results of
the same form as the simulated-truth ones (gpquad.physics.identify), without a truth column.

Every fit pools the segments of the log: the first 1 - validation_fraction of each segment
trains, its last part validates (as the truth mode splits each flight). The standard thrust
of eq. (5) is fitted on the near-hover samples (`logdata.hover_mask`); the standard and
refined (eq. 19) models on every in-flight sample, the refined one only with a measured
velocity; drag (eq. 18) on every in-flight sample, with the optional parasitic term and
accelerometer-bias intercept.
"""

from __future__ import annotations

import numpy as np

from gpquad.errors import GpquadError
from gpquad.physics.aero import THRUST_MODELS, drag_regressors, thrust_regressors
from gpquad.physics.regression import fit, predict, r_squared

MIN_SAMPLES = 20


def _pooled(segs, masks, build, fraction: float):
    """Training and validation rows of every segment (first part / last part), pooled."""
    parts = {"Xtr": [], "ytr": [], "Xva": [], "yva": [], "tva": []}
    offset = 0.0
    for seg, mask in zip(segs, masks):
        X, y = build(seg)
        n = len(y)
        cut = int(round(n * (1.0 - fraction)))
        idx = np.arange(n)
        tr, va = mask & (idx < cut), mask & (idx >= cut)
        parts["Xtr"].append(X[tr])
        parts["ytr"].append(y[tr])
        parts["Xva"].append(X[va])
        parts["yva"].append(y[va])
        parts["tva"].append(seg["t"][va] + offset)
        offset += float(seg["t"][-1]) + 1.0
    return {k: np.concatenate(v) if k[0] != "X" else np.vstack(v) for k, v in parts.items()}


def _fit_pooled(p: dict, names, cfg, what: str, source: str, fix: str) -> dict:
    if len(p["ytr"]) < MIN_SAMPLES:
        raise GpquadError(
            f"{len(p['ytr'])} training samples for the {what} fit; {fix}",
            source=source,
            field="thrust",
        )
    has_val = len(p["yva"]) >= 2
    res = fit(
        p["Xtr"],
        p["ytr"],
        names,
        cfg.regression.method,
        X_val=p["Xva"] if has_val else None,
        y_val=p["yva"] if has_val else None,
        window=cfg.regression.wls_window,
    )
    res["relative_error"] = {}
    if not has_val:
        res["r2_val"] = res["rmse_val"] = float("nan")
    return res


def identify_thrust_log(cfg, segs: list[dict]) -> dict:
    """Standard thrust from hover samples (eq. 5); standard and refined (eq. 19) from all."""
    mass = cfg.vehicle.mass
    frac = cfg.regression.validation_fraction
    source = segs[0]["source"]
    has_vel = all("vel_body" in s for s in segs)

    def build(model):
        def make(seg):
            vel = seg.get("vel_body", np.zeros((len(seg["t"]), 3)))
            return thrust_regressors(model, seg["rotor"], vel), mass * seg["force"][:, 2]

        return make

    every = [s["airborne"] for s in segs]
    hover = _pooled(segs, [s["hover"] for s in segs], build("standard"), frac)
    fits = {
        "standard_hover": _fit_pooled(
            hover,
            THRUST_MODELS["standard"],
            cfg,
            "hover thrust",
            source,
            f"the log has few near-hover samples (speed < {cfg.thrust.hover_max_speed:g} m/s, "
            f"rate < {cfg.thrust.hover_max_rate:g} rad/s); raise thrust.hover_max_speed or "
            "hover_max_rate",
        )
    }
    forward = _pooled(segs, every, build("standard"), frac)
    fits["standard_forward"] = _fit_pooled(
        forward, THRUST_MODELS["standard"], cfg, "forward thrust", source, "log a longer flight"
    )
    out = {"source": "log", "mass": mass, "truth": {}, "fits": fits, "velocity_measured": has_vel}
    pf = predict(fits["standard_hover"], forward["Xva"])
    out["hover_fit_on_forward_validation"] = {
        "r2": r_squared(forward["yva"], pf) if len(pf) > 1 else float("nan"),
        "rmse": float(np.sqrt(np.mean((forward["yva"] - pf) ** 2))) if len(pf) else float("nan"),
    }
    series = {
        "hover": hover,
        "forward": forward,
        "mass": mass,
        "preds": {"standard": predict(fits["standard_forward"], forward["Xva"])},
    }
    if has_vel:
        refined = _pooled(segs, every, build("refined"), frac)
        fits["refined_forward"] = _fit_pooled(
            refined, THRUST_MODELS["refined"], cfg, "refined thrust", source, "log a longer flight"
        )
        out["refined_beats_standard"] = bool(
            fits["refined_forward"]["rmse_val"] < fits["standard_forward"]["rmse_val"]
        )
        series["preds"]["refined"] = predict(fits["refined_forward"], refined["Xva"])
    else:
        out["refined_beats_standard"] = None
        out["notes"] = [
            "no measured velocity: the refined thrust (eq. 19) needs u, v, w; "
            "only the standard model (eq. 5) is fitted"
        ]
    out["_series"] = series
    return out


def _drag_design(seg: dict, axis: int, parasitic: bool, intercept: bool):
    """Columns and names of eq. (18) for one axis, optionally with a constant (bias)."""
    X, names = drag_regressors(axis, seg["rotor"], seg["vel_body"], parasitic)
    if intercept:
        X = np.column_stack([X, np.ones(len(X))])
        names = names + [f"bias_{'xy'[axis]}"]
    return X, names


def identify_drag_log(cfg, segs: list[dict]) -> dict:
    """k_dx, k_dy of eq. (18) pooled over the segments, with and without parasitic drag."""
    frac = cfg.regression.validation_fraction
    source = segs[0]["source"]
    out = {
        "source": "log",
        "mass": cfg.vehicle.mass,
        "truth": {},
        "fits": {},
        "flights": [s["name"] for s in segs],
    }
    every = [s["airborne"] for s in segs]
    variants = [False, True] if cfg.regression.parasitic_drag else [False]
    series = {}
    for axis in (0, 1):
        for parasitic in variants:

            def make(seg, axis=axis, parasitic=parasitic):
                X, _ = _drag_design(seg, axis, parasitic, cfg.regression.drag_intercept)
                return X, seg["force"][:, axis]

            names = _drag_design(segs[0], axis, parasitic, cfg.regression.drag_intercept)[1]
            p = _pooled(segs, every, make, frac)
            key = f"{'xy'[axis]}{'_parasitic' if parasitic else ''}"
            res = _fit_pooled(p, names, cfg, f"drag {key}", source, "log a longer flight")
            out["fits"][key] = res
            series[key] = p
            for name, c, se in zip(names, res["coef"], res["se"]):
                if name.startswith("bias"):
                    continue
                if not abs(se) < 0.5 * abs(c):
                    out.setdefault("warnings", []).append(
                        f"{key}: {name} = {c:.3g} +- {se:.2g} is not identified: the "
                        f"training parts barely move along {'xy'[axis]}"
                    )
                elif c >= 0:
                    out.setdefault("warnings", []).append(
                        f"{key}: {name} = {c:.3g} is not negative (drag must oppose the "
                        f"velocity); the log barely moves along {'xy'[axis]}"
                    )
    out["_series"] = series
    return out


def windows(seg: dict, window_s: float) -> list[tuple[int, int]]:
    """[start, stop) sample ranges of consecutive windows of window_s (0: the whole segment);
    a last piece shorter than half a window joins the one before."""
    n = len(seg["t"])
    if window_s <= 0:
        return [(0, n)]
    dt = float(np.median(np.diff(seg["t"])))
    step = max(int(round(window_s / dt)), 2)
    edges = list(range(0, n, step)) + [n]
    if len(edges) > 2 and edges[-1] - edges[-2] < step // 2:
        edges.pop(-2)
    return [(a, b) for a, b in zip(edges[:-1], edges[1:]) if b - a >= 2]
