"""One figure per scenario: the 7 s prediction of each method against the test data.

Report code: the only benchmark module that imports matplotlib. Each method is shown by
its lowest seed's cell; every method flies the same test window from the same recorded
state (the middle window of the 7 s tiling).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gpquad.models.scoring import SCORED_STATES

UNITS = ("m/s",) * 3 + ("rad/s",) * 3


def scenario_figure(name: str, data: dict, cells: list[dict], out: Path) -> Path | None:
    """Write figures/<name>.png; data = {"dt", "steps", "states": [[u..r], ...]}."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if data is None:
        return None
    t = np.arange(data["steps"] + 1) * data["dt"]
    truth = np.array(data["states"], dtype=float)
    fig, axes = plt.subplots(3, 2, figsize=(10, 8), sharex=True)
    shown = {}
    for cell in sorted(cells, key=lambda c: c["seed"]):
        if cell["scenario"] == name and cell.get("figure") and cell["method"] not in shown:
            shown[cell["method"]] = np.array(cell["figure"]["pred"], dtype=float)
    for j, ax in enumerate(axes.T.ravel()):
        ax.plot(t, truth[:, j], color="black", lw=2, label="data")
        lim = 3 * np.max(np.abs(truth[:, j])) + 1e-3
        for method, pred in shown.items():
            ax.plot(t, np.clip(pred[:, j], -lim, lim), lw=1, label=method)
        ax.set_ylabel(f"{SCORED_STATES[j]} ({UNITS[j]})")
        ax.set_ylim(-lim, lim)
    for ax in axes[-1]:
        ax.set_xlabel("time from window start (s)")
    axes[0, 0].legend(fontsize=8, loc="best")
    fig.suptitle(f"{name}: 7 s prediction from the recorded state with the recorded inputs")
    fig.tight_layout()
    path = Path(out) / "figures" / f"{name}.png"
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
