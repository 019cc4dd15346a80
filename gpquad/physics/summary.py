"""The one-line JSON of `gpquad physics thrust|drag|deadreckon --json`, in SI units.

thrust: k_t in N per (rad/s)^2 (eq. 5 on near-hover samples; `k_t_se` its standard error,
`rmse_val` the validation RMSE in N), and the refined model's k_t, k_z (N per (rad/s) per
(m/s)), k_h (N per (m/s)^2) when it was fitted.
drag: k_dx, k_dy in N per (rad/s) per (m/s), the force form m x the thesis's coefficient of
eq. (18), which `k_dx_specific` gives in (m/s^2) per (rad/s) per (m/s); parasitic c_dx, c_dy
in N per (m/s)^2 and the bias in m/s^2 when fitted; `rmse_val_x` in m/s^2.
deadreckon: per segment (or window) and model the position RMSE (x, y, z), m.
"""

from __future__ import annotations

import math

UNITS = {
    "k_t": "N/(rad/s)^2",
    "k_z": "N/((rad/s)(m/s))",
    "k_h": "N/(m/s)^2",
    "k_dx": "N/((rad/s)(m/s))",
    "k_dy": "N/((rad/s)(m/s))",
    "c_dx": "N/(m/s)^2",
    "c_dy": "N/(m/s)^2",
    "bias_x": "m/s^2",
    "bias_y": "m/s^2",
    "k_dx_specific": "(m/s^2)/((rad/s)(m/s))",
    "rmse_val": "N",
    "rmse_val_x": "m/s^2",
}


def _num(x):
    if isinstance(x, int) or x is None:
        return x
    return None if not math.isfinite(x) else float(x)


def thrust_json(res: dict, mass: float) -> dict:
    hover = res["fits"]["standard_hover"]
    out = {
        "k_t": hover["coef"][0],
        "k_t_se": hover["se"][0],
        "rmse_val": hover["rmse_val"],
        "r2": hover["r2"],
        "n": hover["n"],
        "mass": mass,
    }
    ref = res["fits"].get("refined_forward")
    if ref is not None:
        for name, c, se in zip(ref["names"], ref["coef"], ref["se"]):
            key = "k_t_refined" if name == "k_t" else name
            out[key], out[f"{key}_se"] = c, se
        out["refined_rmse_val"] = ref["rmse_val"]
    out["units"] = {k: v for k, v in UNITS.items() if k in ("k_t", "k_z", "k_h", "rmse_val")}
    return {k: _num(v) if not isinstance(v, dict) else v for k, v in out.items()}


def drag_json(res: dict, mass: float, parasitic: bool) -> dict:
    """The parasitic fits when [regression] parasitic_drag, else the plain eq. (18) ones."""
    out = {"mass": mass}
    for axis in "xy":
        key = f"{axis}_parasitic" if parasitic and f"{axis}_parasitic" in res["fits"] else axis
        fit = res["fits"][key]
        for name, c, se in zip(fit["names"], fit["coef"], fit["se"]):
            scale = 1.0 if name.startswith("bias") else mass
            out[name], out[f"{name}_se"] = scale * c, scale * se
            if name.startswith("k_d"):
                out[f"{name}_specific"], out[f"{name}_specific_se"] = c, se
        out[f"rmse_val_{axis}"] = fit["rmse_val"]
        out[f"r2_{axis}"] = fit["r2"]
    out["units"] = {
        k: v for k, v in UNITS.items() if k[0] in "cb" or k.startswith(("k_d", "rmse_val_"))
    }
    return {k: _num(v) if not isinstance(v, dict) else v for k, v in out.items()}


def deadreckon_json(res: dict) -> dict:
    return {
        "segments": [
            {
                "name": f["name"],
                "duration_s": f["duration_s"],
                "rmse_m": {m: v["rmse"] for m, v in f["models"].items()},
                "best": f["best"],
            }
            for f in res["flights"]
        ],
        "coriolis_best_count": res["coriolis_best_count"],
        "ordered_count": res["ordered_count"],
    }
