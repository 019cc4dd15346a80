"""Figures of baseline results (matplotlib, Agg); reads result dicts only."""

from __future__ import annotations

import io

import numpy as np


def convergence_png(study: dict, fraction: float) -> bytes:
    """Median and inter-quartile band of the relative parameter error per generation."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.0), dpi=120)
    for label, color in (("gradient", "C0"), ("traditional", "C1")):
        curves = np.array(study[label]["curves"])
        rel = curves / curves[:, :1]
        gens = np.arange(rel.shape[1])
        med = np.median(rel, axis=0)
        ax.semilogy(gens, med, color=color, label=f"{label} GA (median of {len(rel)} seeds)")
        ax.fill_between(
            gens,
            np.percentile(rel, 25, axis=0),
            np.percentile(rel, 75, axis=0),
            color=color,
            alpha=0.25,
            linewidth=0,
        )
        m = study[label]["summary"]["all"]["median"]
        ax.axvline(m, color=color, linestyle=":", linewidth=1)
    ax.axhline(
        fraction, color="k", linestyle="--", linewidth=1, label=f"{fraction:.0%} of initial error"
    )
    ax.set_xlabel("generation")
    ax.set_ylabel("parameter error / initial error")
    ax.set_title("12-state model, all loops: gradient vs traditional GA")
    ax.legend(fontsize=8)
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    plt.close(fig)
    return buf.getvalue()
