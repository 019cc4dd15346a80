"""Markdown pieces shared by the physics commands (simulated truth and logs)."""

from __future__ import annotations

import numpy as np

THESIS_ORDER = ("coriolis", "refined", "base", "accelerometer")


def pct(x):
    return "-" if x is None else f"{100 * x:+.2f} %"


def fits_table(fits: dict, truth: dict) -> list[str]:
    lines = [
        "| fit | coefficient | estimate | SE | truth | error | R^2 | R^2 val | RMSE val |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for key, res in fits.items():
        for name, c, se in zip(res["names"], res["coef"], res["se"]):
            true = truth.get(name)
            true_text = "-" if true is None else f"{true:.4g}"
            lines.append(
                f"| {key} | {name} | {c:.4g} | {se:.2g} | {true_text} | "
                f"{pct(res['relative_error'].get(name))} | {res['r2']:.4f} | "
                f"{res.get('r2_val', float('nan')):.4f} | "
                f"{res.get('rmse_val', float('nan')):.4f} |"
            )
    return lines


def models_ordered(rmse: dict, models=THESIS_ORDER) -> bool:
    total = [float(np.linalg.norm(rmse[m])) for m in models]
    return all(a < b for a, b in zip(total, total[1:]))
