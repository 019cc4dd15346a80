"""Figures of `gpquad control` (the only module of the package that imports matplotlib)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gpquad.control.courses import vertices


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def paths_figure(test: dict, path: Path, title: str = "", dt: float = 1.0) -> Path:
    """Top view (east, north) and altitude of the course, the model path and the truth paths
    (paper Fig. 3: model continuous, repetitions on the other plant dashed)."""
    plt = _plt()
    fig, (top, alt) = plt.subplots(1, 2, figsize=(11, 4.8), gridspec_kw={"width_ratios": [1.4, 1]})
    v = vertices(test["waypoints"])
    top.plot(v[:, 1], v[:, 0], "k:", lw=1, label="course")
    top.plot(v[1:, 1], v[1:, 0], "ks", ms=5)
    styles = ["tab:red", "tab:green", "tab:cyan", "tab:orange", "tab:purple"]
    for f in test["model"][:1]:
        p = f.pos[: f.flown + 1]
        top.plot(p[:, 1], p[:, 0], "-", color="tab:blue", lw=1.8, label="model")
        alt.plot(np.arange(len(p)) * dt, -p[:, 2], "-", color="tab:blue", lw=1.8)
    for i, f in enumerate(test["truth"]):
        p = f.pos[: f.flown + 1]
        top.plot(
            p[:, 1],
            p[:, 0],
            "--",
            color=styles[i % len(styles)],
            lw=1.2,
            label=f"truth plant, repetition {i + 1}",
        )
        alt.plot(np.arange(len(p)) * dt, -p[:, 2], "--", color=styles[i % len(styles)], lw=1.2)
    top.set_xlabel("east (m)")
    top.set_ylabel("north (m)")
    top.set_aspect("equal", adjustable="datalim")
    top.legend(fontsize=8)
    top.set_title(title)
    alt.set_xlabel("t (s)")
    alt.set_ylabel("altitude (m)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def evolution_figure(history: list[dict], path: Path) -> Path:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6, 3.6))
    g = [h["generation"] for h in history]
    ax.plot(g, [h["best"] for h in history], label="best of generation")
    ax.plot(g, [h["median"] for h in history], label="median")
    ax.set_xlabel("generation")
    ax.set_ylabel("fitness")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def tracking_figure(
    t: np.ndarray,
    ref: np.ndarray,
    acc: np.ndarray,
    path: Path,
    title: str = "",
    angles: np.ndarray | None = None,
) -> Path:
    """Reference and flown body accelerations a_x, a_y, a_z (paper Figs. 8-9); angles, if
    given, [phi, theta] in a fourth panel."""
    plt = _plt()
    rows = 4 if angles is not None else 3
    fig, axes = plt.subplots(rows, 1, figsize=(8, 2.0 * rows), sharex=True)
    for i, name in enumerate(("a_x", "a_y", "a_z")):
        axes[i].plot(t, ref[:, i], "k--", lw=1.2, label="reference")
        axes[i].plot(t, acc[:, i], "tab:blue", lw=1.0, label="flown")
        axes[i].set_ylabel(f"{name} (m/s$^2$)")
    axes[0].legend(fontsize=8, loc="upper right")
    if angles is not None:
        axes[3].plot(t, angles[:, 0], label="phi")
        axes[3].plot(t, angles[:, 1], label="theta")
        axes[3].set_ylabel("rad")
        axes[3].legend(fontsize=8, loc="upper right")
    axes[-1].set_xlabel("t (s)")
    axes[0].set_title(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
