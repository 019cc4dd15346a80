"""Figures of the physics commands (matplotlib, Agg); the rest of the package never imports it."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _shade(ax, t, flag):
    from gpquad.physics.mixer import runs_of

    for a, b in runs_of(flag):
        ax.axvspan(t[a], t[b - 1], color="tab:red", alpha=0.15, lw=0)


def motors_figure(series: dict, title: str, path: Path) -> Path:
    """Predicted vs logged motor commands over the flight, saturated stretches shaded."""
    plt = _plt()
    t, armed = series["t"], series["armed"]
    t = t - t[0]
    fig, axes = plt.subplots(4, 1, figsize=(11, 8), sharex=True)
    for k, ax in enumerate(axes):
        ax.plot(t[armed], series["logged"][armed, k], lw=0.6, label="logged")
        ax.plot(t[armed], series["predicted"][armed, k], lw=0.6, label="mixer model", alpha=0.8)
        _shade(ax, t, series["saturated"] & armed)
        ax.set_ylabel(f"motor[{k}] (DShot)")
    axes[0].legend(loc="upper right", fontsize=8)
    axes[0].set_title(title + " (red: saturated)")
    axes[-1].set_xlabel("time since log start (s)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def regression_figure(
    x: np.ndarray,
    y: np.ndarray,
    fitted: np.ndarray,
    xlabel: str,
    ylabel: str,
    title: str,
    path: Path,
) -> Path:
    """Measured target against one regressor, with the fitted values."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6, 4.5))
    ax.plot(x, y, ".", ms=2, alpha=0.4, label="measured")
    order = np.argsort(x)
    ax.plot(x[order], fitted[order], "-", lw=1.2, color="tab:red", label="fit")
    return _finish(plt, fig, ax, xlabel, ylabel, title, path)


def series_figure(
    t: np.ndarray, measured: np.ndarray, predicted: dict, ylabel: str, title: str, path: Path
) -> Path:
    """Measured target over time with the predictions of several fits."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(9, 4))
    ax.plot(t, measured, lw=0.8, color="k", label="measured")
    for name, values in predicted.items():
        ax.plot(t, values, lw=0.8, label=name)
    return _finish(plt, fig, ax, "time (s)", ylabel, title, path)


def _finish(plt, fig, ax, xlabel: str, ylabel: str, title: str, path: Path) -> Path:
    """Labels, title and legend of a one-axes figure; saved to path and closed."""
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def tracks_figure(
    t: np.ndarray, truth: np.ndarray, estimates: dict, title: str, path: Path
) -> Path:
    """Position per axis: ground truth and the dead-reckoning models (thesis Figs. 14-16)."""
    plt = _plt()
    fig, axes = plt.subplots(3, 1, figsize=(9, 8), sharex=True)
    for k, ax in enumerate(axes):
        ax.plot(t, truth[:, k], color="k", lw=1.4, label="ground truth")
        for name, pos in estimates.items():
            ax.plot(t, pos[:, k], lw=0.9, label=name)
        ax.set_ylabel(f"{'xyz'[k]} (m)")
    axes[0].legend(fontsize=8, ncol=3)
    axes[0].set_title(title)
    axes[-1].set_xlabel("time (s)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
