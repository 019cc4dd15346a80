"""Figures of a sweep, drawn from its result files only (matplotlib, Agg backend).

- `prediction_figure`: data, best model and the min-max envelope of the full models over
  one validation window (paper Figure 2), from predictions.npz;
- `convergence_figure`: best suite error against generation per equation, one line per
  run plus the median over runs, from the runs' history.csv files.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from gpquad.engine.variables import (  # noqa: E402
    STATE_LATEX,
    STATE_NAMES,
    STATE_UNITS,
    TARGET_LATEX,
    TARGET_NAMES,
    TARGET_STATE,
    target_index,
)

#: Paper-size figures: two-column width (7 in), 9 pt text.
STYLE = {
    "font.size": 9,
    "axes.titlesize": 9,
    "axes.labelsize": 9,
    "legend.fontsize": 8,
    "xtick.labelsize": 8,
    "ytick.labelsize": 8,
    "savefig.dpi": 200,
    "axes.grid": True,
    "grid.alpha": 0.3,
}
PLOTTED = ("u", "v", "w", "p", "q", "r")


def _save(fig, stem: Path, formats) -> list[Path]:
    stem.parent.mkdir(parents=True, exist_ok=True)
    paths = []
    for ext in formats:
        path = stem.with_suffix(f".{ext}")
        tmp = path.with_name(f".{path.name}.tmp.{ext}")
        fig.savefig(tmp)
        tmp.replace(path)
        paths.append(path)
    plt.close(fig)
    return paths


def _label(name: str) -> str:
    i = STATE_NAMES.index(name)
    return f"${STATE_LATEX[i]}$ [{STATE_UNITS[i]}]"


def prediction_figure(
    npz_path,
    stem,
    formats=("png", "pdf"),
    n_models: int | None = None,
    best_label: str = "best model",
) -> list[Path]:
    """Six panels (u, v, w, p, q, r) against time: data, best model, envelope (if any)."""
    d = np.load(npz_path, allow_pickle=False)
    t, data, best, full = d["t"], d["data"], d["best"], d["full"]
    n = len(full) if n_models is None else n_models
    targets = d["targets"].tolist() if "targets" in d.files else list(TARGET_NAMES)
    identified = {TARGET_STATE[t] for t in targets}
    unmeasured = set(d["unmeasured"].tolist()) if "unmeasured" in d.files else set()
    with plt.rc_context(STYLE):
        fig, axes = plt.subplots(3, 2, figsize=(7.0, 6.0), sharex=True)
        for j, name in enumerate(PLOTTED):
            ax = axes[j % 3, j // 3]
            k = STATE_NAMES.index(name)
            if len(full):
                with np.errstate(invalid="ignore"):
                    lo = np.nanmin(full[:, :, k], axis=0)
                    hi = np.nanmax(full[:, :, k], axis=0)
                ax.fill_between(
                    t,
                    lo,
                    hi,
                    color="tab:blue",
                    alpha=0.25,
                    linewidth=0,
                    label=f"min-max of {n} full models",
                )
            ax.plot(t, data[:, k], color="black", linewidth=1.3, label="data")
            ax.plot(t, best[:, k], color="tab:red", linestyle="--", linewidth=1.3, label=best_label)
            ref = np.concatenate([data[:, k], best[:, k][np.isfinite(best[:, k])]])
            span = max(float(np.ptp(ref)), 1e-3)
            ax.set_ylim(ref.min() - 0.4 * span, ref.max() + 0.4 * span)
            ax.set_ylabel(_label(name))
            if name in unmeasured:
                ax.set_title("not measured by the log: its values are placeholders", fontsize=8)
            elif name not in identified:
                ax.set_title("not identified: flown with the data's acceleration", fontsize=8)
            else:
                err = best[1:, k] - data[1:, k]
                spread = float(((data[1:, k] - data[1:, k].mean()) ** 2).sum())
                rse = float((err**2).sum() / spread) if spread > 0 else float("nan")
                ax.set_title(f"RSE {rse:.3g}" if np.isfinite(rse) else "RSE -", fontsize=8)
        for ax in axes[-1]:
            ax.set_xlabel("time from window start [s]")
        handles, labels = axes[0, 0].get_legend_handles_labels()
        fig.legend(
            handles, labels, loc="upper center", ncol=3, frameon=False, bbox_to_anchor=(0.5, 0.965)
        )
        clipped = " (envelope clipped to the axes)" if len(full) else ""
        where = ""
        if "start" in d.files and "dt" in d.files:
            where = (
                f" from sample {int(np.ravel(d['start'])[0])} "
                f"(t = {float(np.ravel(d['start'])[0]) * float(d['dt']):.1f} s of the data)"
            )
        fig.suptitle(
            f"Prediction over a {t[-1]:.3g} s validation window{where}{clipped}", y=0.99, fontsize=9
        )
        # fixed margins: no text is measured when the figure is saved
        fig.subplots_adjust(left=0.1, right=0.98, bottom=0.08, top=0.88, hspace=0.3, wspace=0.28)
        return _save(fig, Path(stem), formats)


def read_history(
    path, iterations_per_gen: int | None = None, target: str | None = None
) -> pd.DataFrame:
    """A run's history with a cumulative `step` column (model generation count).

    target: keep only that equation's rows (a `gpquad run` history holds every target).
    """
    from gpquad.errors import GpquadError

    columns = ["target", "iteration", "generation", "best_suite_error"]
    try:
        h = pd.read_csv(path, usecols=columns)
        h[columns[1:3]] = h[columns[1:3]].astype(np.int64)
        h["best_suite_error"] = h["best_suite_error"].astype(float)
    except (
        ValueError,
        TypeError,
        OSError,
        pd.errors.ParserError,
        pd.errors.EmptyDataError,
        UnicodeDecodeError,
    ) as exc:
        raise GpquadError(
            f"damaged history ({type(exc).__name__}); restore it or run again", source=str(path)
        ) from None
    if target is not None:
        h = h[h["target"] == target].reset_index(drop=True)
    if h.empty:
        raise GpquadError(
            f"no rows{' of ' + target if target else ''}: a damaged history or "
            "a run that did not reach it; restore it or run again",
            source=str(path),
        )
    gens = int(h["generation"].max()) + 1 if iterations_per_gen is None else iterations_per_gen
    h["step"] = h["iteration"] * gens + h["generation"] + 1
    return h


def convergence_figure(
    histories: dict[str, list[Path]], stem, metric: str = "mae", formats=("png", "pdf")
) -> list[Path]:
    """Best suite error against model generation, one panel per equation."""
    targets = [t for t in TARGET_NAMES if histories.get(t)]
    cols = 3 if len(targets) > 2 else len(targets)
    rows = int(np.ceil(len(targets) / cols))
    with plt.rc_context(STYLE):
        fig, axes = plt.subplots(rows, cols, figsize=(7.0, 2.3 * rows + 0.4), squeeze=False)
        for ax in axes.ravel()[len(targets) :]:
            ax.set_visible(False)
        for ax, target in zip(axes.ravel()[: len(targets)], targets, strict=True):
            frames = [read_history(p, target=target) for p in histories[target]]
            single = len(frames) == 1
            for h in frames:
                ax.plot(
                    h["step"],
                    h["best_suite_error"],
                    color="tab:blue" if single else "tab:gray",
                    alpha=1.0 if single else 0.45,
                    linewidth=1.2 if single else 0.7,
                )
            if not single:
                merged = pd.concat(
                    [h.set_index("step")["best_suite_error"] for h in frames], axis=1
                )
                ax.plot(merged.index, merged.median(axis=1), color="tab:blue", linewidth=1.6)
            state = TARGET_STATE[target]
            unit = STATE_UNITS[STATE_NAMES.index(state)]
            if metric == "mse":
                unit = f"({unit})$^2$"
            values = pd.concat([h["best_suite_error"] for h in frames])
            values = values[np.isfinite(values) & (values > 0)]
            if len(values) and values.max() > 10 * values.min():  # log only over decades
                ax.set_yscale("log")
            for it in range(1, int(frames[0]["iteration"].max()) + 1):
                ax.axvline(
                    it * (int(frames[0]["generation"].max()) + 1),
                    color="0.9",
                    linewidth=0.6,
                    zorder=0,
                )
            runs = f"{len(frames)} run" + ("s" if len(frames) != 1 else "")
            ax.set_title(f"${TARGET_LATEX[target_index(target)]}$ ({runs})")
            ax.set_xlabel("model generation")
            ax.set_ylabel(
                f"suite {metric.upper()} of ${STATE_LATEX[STATE_NAMES.index(state)]}$ [{unit}]"
            )
        several = any(len(histories[t]) > 1 for t in targets)
        boundary = plt.Line2D([], [], color="0.9", linewidth=0.6)
        if several:
            handles = [
                plt.Line2D([], [], color="tab:gray", alpha=0.6, linewidth=0.8),
                plt.Line2D([], [], color="tab:blue", linewidth=1.6),
                boundary,
            ]
            labels = [
                "one run (best climber)",
                "median over runs",
                "iteration boundary (new test suite)",
            ]
        else:
            handles = [plt.Line2D([], [], color="tab:blue", linewidth=1.2), boundary]
            labels = [
                "best climber on the current test suite",
                "iteration boundary (new test suite)",
            ]
        fig.subplots_adjust(
            left=0.12 if cols > 1 else 0.25,
            right=0.98,
            bottom=0.45 / fig.get_figheight(),
            top=1 - 0.6 / fig.get_figheight(),
            hspace=0.6,
            wspace=0.62,
        )
        fig.legend(
            handles,
            labels,
            loc="upper center",
            ncol=len(handles),
            frameon=False,
            bbox_to_anchor=(0.5, 1.0),
        )
        return _save(fig, Path(stem), formats)
