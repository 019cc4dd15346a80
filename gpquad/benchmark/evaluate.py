"""Score a flown model on a scenario's test flights, the same way for every method.

For each horizon (s), the test ranges are tiled with non-overlapping windows of
round(h / dt) steps (`gpquad.models.scoring.validation_windows`, which tiles with
`gpquad.engine.evolve.windows.tile`) after MAX_LAG samples of input history, so that every
method flies the same windows; a horizon that no test range fits is skipped. A window
is diverged when a scored state is non-finite or beyond 10 x max(|data|, 1)
(`gpquad.models.scoring.diverged`, as `gpquad sweep` counts them); the RSE of each of u, v, w,
p, q, r (`gpquad.models.scoring.rse`) is taken over the windows that did not diverge, and is
NaN for a state the log does not measure. `mean` averages the measured states.
"""

from __future__ import annotations

import numpy as np

from gpquad.benchmark.rollout import MAX_LAG
from gpquad.errors import GpquadError
from gpquad.models.scoring import (
    SCORED_INDEX,
    SCORED_STATES,
    diverged,
    divergence_bound,
    rse,
    validation_windows,
)

FIGURE_HORIZON_S = 7.0


def horizon_windows(test, horizon_s: float) -> tuple[np.ndarray, int]:
    """Window starts and steps of a horizon on the test ranges (none if no range fits)."""
    steps = int(round(horizon_s / test.dt))
    try:
        starts, got = validation_windows(test, steps, MAX_LAG)
    except GpquadError:
        return np.zeros(0, dtype=np.int64), 0
    if got < steps:
        return np.zeros(0, dtype=np.int64), 0
    return starts, steps


def data_windows(test, starts, steps) -> np.ndarray:
    return test.arrays.states[starts[:, None] + np.arange(steps + 1)[None, :]]


def score(simulate, test, measured: dict, horizons_s) -> dict:
    """{"1s": {"windows", "steps", "diverged", "rse": {u..r}, "mean", "window_sse"}, ...}.

    simulate(starts, steps) -> predicted states (W, steps + 1, 9).
    """
    states = test.arrays.states[:, SCORED_INDEX]
    bound = divergence_bound(states)
    out = {}
    for h in horizons_s:
        key = f"{h:g}s"
        starts, steps = horizon_windows(test, h)
        if len(starts) == 0:
            out[key] = {"windows": 0, "steps": 0, "diverged": 0, "rse": {}, "mean": None}
            continue
        pred = simulate(starts, steps)
        data = data_windows(test, starts, steps)
        div = diverged(pred, bound)
        keep = ~div
        values = rse(pred[keep], data[keep]) if keep.any() else np.full(6, np.nan)
        per_state = {
            s: (float(v) if measured[s] and np.isfinite(v) else None)
            for s, v in zip(SCORED_STATES, values, strict=True)
        }
        kept = [v for v in per_state.values() if v is not None]
        out[key] = {
            "windows": int(len(starts)),
            "steps": int(steps),
            "diverged": int(div.sum()),
            "rse": per_state,
            "mean": float(np.mean(kept)) if kept else None,
            "window_sse": window_sse(pred, data, div),
        }
    return out


def window_sse(pred: np.ndarray, data: np.ndarray, div: np.ndarray) -> list:
    """Sum of squared errors of u..r per window (W lists of 6, 6 significant digits; None
    for a diverged window): RSE's numerator window by window, so that two methods can be
    compared on the windows both flew (gpquad.benchmark.paired)."""
    with np.errstate(over="ignore", invalid="ignore"):
        sse = ((pred[:, 1:, SCORED_INDEX] - data[:, 1:, SCORED_INDEX]) ** 2).sum(axis=1)
    return [
        None if bad else [float(f"{v:.6g}") for v in row] for row, bad in zip(sse, div, strict=True)
    ]


def figure_window(test) -> tuple[int, int] | None:
    """The test window the figure shows: the middle one of the 7 s tiling (or None)."""
    starts, steps = horizon_windows(test, FIGURE_HORIZON_S)
    if len(starts) == 0:
        return None
    return int(starts[len(starts) // 2]), steps


def figure_trace(simulate, test) -> dict | None:
    """Predicted u..r over the figure window: {"start", "steps", "pred": [[6 values]...]}."""
    window = figure_window(test)
    if window is None:
        return None
    start, steps = window
    pred = simulate(np.array([start], dtype=np.int64), steps)[0][:, SCORED_INDEX]
    return {
        "start": start,
        "steps": steps,
        "pred": [[(float(x) if np.isfinite(x) else None) for x in row] for row in pred],
    }


def figure_data(test) -> dict | None:
    """The test data u..r over the figure window: {"dt", "start", "steps", "states"}."""
    window = figure_window(test)
    if window is None:
        return None
    start, steps = window
    states = test.arrays.states[start : start + steps + 1][:, SCORED_INDEX]
    return {"dt": float(test.dt), "start": start, "steps": steps, "states": states.tolist()}
