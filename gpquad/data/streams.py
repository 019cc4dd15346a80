"""Streams on one clock, and which samples are in flight: the readers' side of the pipeline.

A reader (px4, ulog, betaflight, ardupilot, table) turns a log into `Stream`s, puts them on
one uniform clock with `resample` (step 1 of gpquad.data.pipeline: states interpolated,
inputs and flags held, gaps never bridged) and marks the in-flight samples with
`in_flight_mask` (step 2); gpquad.data.pipeline does the rest.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy.ndimage import uniform_filter1d

from gpquad.data.plausibility import check_stream_time, runs
from gpquad.errors import GpquadError

#: Stream kinds: interpolated states, interpolated quaternion, held inputs/flags.
KINDS = ("state", "quat", "hold")
#: Thrust dips shorter than this (s) inside a flight do not end the flight.
THRUST_DIP_S = 1.0
#: A slow stream's gap threshold is at least this many of its median sample periods.
GAP_PERIODS = 2.5


@dataclass
class Stream:
    """One group of signals sampled on its own clock.

    t (M,) s; values (M, k) in SI units and NED/FRD; columns names the k output columns.
    kind: "state" (linear interpolation), "quat" (normalised interpolation) or "hold".
    Gaps in a `required` stream split the flight; `source`/`field` name it in errors.
    """

    name: str
    t: np.ndarray
    values: np.ndarray
    columns: tuple[str, ...]
    kind: str
    source: str
    field: str = "timestamp"
    required: bool = True


def continuous_quat(q: np.ndarray) -> np.ndarray:
    """Flip signs so that consecutive quaternions are in the same hemisphere."""
    q = np.array(q, dtype=float)
    dots = np.einsum("ij,ij->i", q[1:], q[:-1])
    flips = np.concatenate([[1.0], np.cumprod(np.where(dots < 0, -1.0, 1.0))])
    return q * flips[:, None]


#: A state stream logged slower than this (median period) has its clock in the wrong unit
#: (events and modes may be sparse).
MIN_STREAM_HZ = 0.2


def resample(
    streams: list[Stream], rate_hz: float, max_gap_s: float
) -> tuple[pd.DataFrame, np.ndarray, list[dict]]:
    """Put streams on one uniform clock over their common time span.

    Returns (table with t and every stream column, valid (N,) bool, per-stream info rows).
    Rows of a stream with NaN are dropped first, so a NaN run becomes a gap.
    """
    clean = []
    info = []
    for s in streams:
        if s.kind not in KINDS:
            raise ValueError(f"unknown stream kind {s.kind}")
        t = np.asarray(s.t, dtype=float)
        if len(t) == 0:
            raise GpquadError(
                f"'{s.name}' has no rows (a header only?); give a log in which it was recorded",
                source=s.source,
                field=s.field,
            )
        values = np.asarray(s.values, dtype=float).reshape(len(t), -1)
        check_stream_time(t, s.source, s.field)
        finite = np.isfinite(values).all(axis=1)
        if not finite.any():
            blank = [
                c
                for c, ok in zip(s.columns, np.isfinite(values).any(axis=0), strict=True)
                if not ok
            ]
            raise GpquadError(
                f"every row of '{s.name}' is NaN or empty",
                source=s.source,
                field=",".join(blank or s.columns),
            )
        dropped = int((~finite).sum())
        t, values = t[finite], values[finite]
        if len(t) < 2:
            raise GpquadError(
                f"only {len(t)} usable rows in '{s.name}'", source=s.source, field=s.field
            )
        if s.kind == "quat":
            norm = np.linalg.norm(values, axis=1)
            if np.abs(norm - 1).max() > 0.05:
                raise GpquadError(
                    f"quaternion norm ranges {norm.min():.3f}..{norm.max():.3f}, not 1",
                    source=s.source,
                    field=s.columns[0],
                )
            values = continuous_quat(values / norm[:, None])
        period = float(np.median(np.diff(t)))
        if s.kind in ("quat", "state") and not 1.0 / period >= MIN_STREAM_HZ:
            raise GpquadError(
                f"'{s.name}' is logged every {period:.6g} s, slower than "
                f"{MIN_STREAM_HZ:g} Hz: time in microseconds or milliseconds? give "
                "it in seconds",
                source=s.source,
                field=s.field,
            )
        width = int(round(1.0 / (rate_hz * period)))
        if s.kind == "state" and width >= 2:  # anti-aliasing: centred boxcar of one new period
            width = 2 * (width // 2) + 1
            values = uniform_filter1d(values, width, axis=0, mode="nearest")
        clean.append((s, t, values, max(max_gap_s, GAP_PERIODS * period)))
        info.append(
            {
                "stream": s.name,
                "rows": len(t),
                "rate_hz": 1.0 / period,
                "start_s": float(t[0]),
                "stop_s": float(t[-1]),
                "nan_rows": dropped,
                "required": s.required,
            }
        )
    start = max(c[1][0] for c in clean)
    stop = min(c[1][-1] for c in clean)
    if stop - start < 2.0 / rate_hz:
        raise GpquadError(
            f"the streams do not overlap in time ({start:.3f}..{stop:.3f} s)",
            source=streams[0].source,
            field="timestamp",
        )
    n = int(np.floor((stop - start) * rate_hz + 1e-9)) + 1
    grid = start + np.arange(n) / rate_hz
    cols = {"t": grid}
    valid = np.ones(n, dtype=bool)
    for s, t, values, gap in clean:
        idx = np.clip(np.searchsorted(t, grid, side="right") - 1, 0, len(t) - 2)
        if s.required:
            span = t[idx + 1] - t[idx]
            valid &= ~((span > gap) & (grid > t[idx]))
        if s.kind == "hold":
            held = np.searchsorted(t, grid, side="right") - 1
            out = values[np.clip(held, 0, None)]
        else:
            out = np.column_stack(
                [np.interp(grid, t, values[:, j]) for j in range(values.shape[1])]
            )
            if s.kind == "quat":
                out /= np.linalg.norm(out, axis=1, keepdims=True)
        for j, c in enumerate(s.columns):
            cols[c] = out[:, j]
    for row, (_, t, _, gap) in zip(info, clean, strict=False):
        row["gaps"] = int((np.diff(t) > gap).sum())
    return pd.DataFrame(cols), valid, info


def in_flight_mask(
    t: np.ndarray, armed: np.ndarray | None, thrust: np.ndarray | None, data, source: str
) -> np.ndarray:
    """In-flight samples by `data.segment`: armed, thrust above threshold, both, a range or all.

    armed (N,) bool or None when the log has no arming state; thrust (N,) normalised or None.
    """
    mode = data.segment
    if mode == "none":
        return np.ones(len(t), dtype=bool)
    if mode == "range":
        lo, hi = data.time_range
        return (t >= lo) & (t <= hi)
    mask = np.ones(len(t), dtype=bool)
    if mode in ("armed", "auto"):
        if armed is None:
            if mode == "armed":
                raise GpquadError(
                    "the log has no arming state; use segment = 'thrust' or 'range'",
                    source=source,
                    field="data.segment",
                )
        else:
            mask &= armed
    if mode in ("thrust", "auto"):
        if thrust is None:
            raise GpquadError(
                "the log has no thrust signal; use segment = 'armed' or 'range'",
                source=source,
                field="data.segment",
            )
        flying = thrust > data.thrust_threshold
        rate = (len(t) - 1) / (t[-1] - t[0]) if len(t) > 1 else 1.0
        for a, b in runs(~flying):  # bridge short throttle dips inside a flight
            if a > 0 and b < len(t) and (b - a) < THRUST_DIP_S * rate:
                flying[a:b] = True
        mask &= flying
    return mask
