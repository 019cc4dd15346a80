"""Estimator resets split a flight; they never reject it whole.

An EKF may reset its attitude (PX4: yaw alignment, `quat_reset_counter` and `delta_q_reset`),
position or velocity (`xy_reset_counter`, `vxy_reset_counter`, ...) in flight. Across a reset
the logged state jumps while the vehicle does not, so rates derived from the quaternion (or
velocity differences) are garbage there. Two signs are used, on the log's common clock:

1. a change of a reset counter between two clock samples (where the log has counters);
2. an attitude step that the gyro does not explain: the rotation angle between consecutive
   quaternions exceeds |gyro| dt by more than `data.max_attitude_step_deg` (without a gyro,
   a step beyond MAX_PLAUSIBLE_RATE dt).

Samples within `MARGIN_S` of either are marked invalid, so the pipeline splits the flight
there like at a logging gap; every split is described in a note with its time and reason.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from gpquad.data.plausibility import MAX_PLAUSIBLE_RATE
from gpquad.engine.variables import QUAT_COLUMNS, RATE_COLUMNS

#: Samples this close (s) to a reset are dropped on both sides.
MARGIN_S = 0.1


def counter_changes(table: pd.DataFrame, counters: dict[str, str]) -> list[tuple[int, str]]:
    """(index of the first sample after the change, reason) for every counter change.

    counters: table column -> description (e.g. "quat_reset_counter (attitude)").
    """
    events = []
    for col, label in counters.items():
        if col not in table.columns:
            continue
        c = table[col].to_numpy(dtype=float)
        ok = np.isfinite(c)
        idx = np.flatnonzero(ok[1:] & ok[:-1] & (np.diff(c) != 0)) + 1
        events.extend((int(i), f"{label} {c[i - 1]:g} -> {c[i]:g}") for i in idx)
    return events


def attitude_steps(table: pd.DataFrame, max_step_deg: float) -> list[tuple[int, str]]:
    """(index, reason) where the quaternion turns more than the gyro explains."""
    q = table[list(QUAT_COLUMNS)].to_numpy(dtype=float)
    if len(q) < 2:
        return []
    t = table["t"].to_numpy()
    dt = np.diff(t)
    dots = np.abs(np.einsum("ij,ij->i", q[1:], q[:-1]))
    angle = 2.0 * np.arccos(np.clip(dots, 0.0, 1.0))
    if all(c in table.columns for c in RATE_COLUMNS):
        w = table[list(RATE_COLUMNS)].to_numpy(dtype=float)
        explained = np.maximum(np.linalg.norm(w[1:], axis=1), np.linalg.norm(w[:-1], axis=1)) * dt
        excess = angle - np.nan_to_num(explained, nan=0.0)
        limit = np.radians(max_step_deg)
        how = "more than the gyro explains"
    else:
        excess = angle
        limit = MAX_PLAUSIBLE_RATE * float(np.median(dt))
        how = f"faster than {MAX_PLAUSIBLE_RATE:g} rad/s"
    idx = np.flatnonzero(excess > limit) + 1
    events = []
    for i in idx:
        if events and i - events[-1][0] <= 2:  # one step spread over two clock samples
            continue
        events.append(
            (
                int(i),
                f"attitude step of {np.degrees(angle[i - 1]):.0f} deg in one "
                f"sample, {how} (estimator reset?)",
            )
        )
    return events


def reset_mask(
    table: pd.DataFrame, rate_hz: float, counters: dict[str, str], max_step_deg: float
) -> tuple[np.ndarray, list[str]]:
    """(bad (N,) bool, notes): samples around resets, and one note per split."""
    n = len(table)
    bad = np.zeros(n, dtype=bool)
    events = counter_changes(table, counters) + attitude_steps(table, max_step_deg)
    if not events:
        return bad, []
    t = table["t"].to_numpy()
    margin = max(1, int(np.ceil(MARGIN_S * rate_hz)))
    notes = []
    seen: list[int] = []
    for i, why in sorted(events):
        bad[max(0, i - margin) : min(n, i + margin)] = True
        near = [j for j in seen if abs(j - i) <= margin]
        seen.append(i)
        notes.append(f"split at {t[i]:.2f} s: {why}" + (" (same reset)" if near else ""))
    return bad, notes
