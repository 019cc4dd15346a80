"""Log synchronisation and smoothing (thesis III.B, III.C).

- `peak_sync`: eq. (12). Both logs see one attitude angle; the time of its peak in each log
  gives the offset between the clocks, and log A's arm and disarm times map onto log B's clock
  keeping their distance to the peak.
- `xcorr_sync`: the cross-correlation alternative (`gpquad.data.align.estimate_offset`).
- `causal_moving_average`: the online smoother of Fig. 4, past values only.
Convention (as gpquad.data.align): an event at tau on clock A is at tau + offset on clock B.
"""

from __future__ import annotations

import numpy as np

from gpquad.errors import GpquadError


def causal_moving_average(x: np.ndarray, window: int) -> np.ndarray:
    """Mean of the last `window` samples (fewer at the start, where the window is not full).
    Works along axis 0."""
    if window < 1:
        raise GpquadError(
            f"smoothing window must be >= 1 sample, not {window}", field="smoothing.window"
        )
    x = np.asarray(x, dtype=float)
    c = np.cumsum(np.concatenate([np.zeros((1,) + x.shape[1:]), x]), axis=0)
    k = np.arange(1, len(x) + 1)
    lo = np.maximum(k - window, 0)
    counts = (k - lo).reshape((-1,) + (1,) * (x.ndim - 1))
    return (c[k] - c[lo]) / counts


def peak_sync(
    t_a, angle_a, t_b, angle_b, t_in_a: float | None = None, t_end_a: float | None = None
) -> dict:
    """Offset of clock B vs clock A from the peak of |angle| in each log (eq. 12), and log A's
    arm/disarm times on clock B (t_inOT, t_endOT). The peak must be one clear event."""
    t_a, t_b = np.asarray(t_a, float), np.asarray(t_b, float)
    a, b = np.abs(np.asarray(angle_a, float)), np.abs(np.asarray(angle_b, float))
    if len(a) < 3 or len(b) < 3 or not np.isfinite(a).any() or not np.isfinite(b).any():
        raise GpquadError(
            "need at least 3 finite samples of the shared angle in each log", field="angle"
        )
    t_peak_a = float(t_a[np.nanargmax(a)])
    t_peak_b = float(t_b[np.nanargmax(b)])
    t_in_a = float(t_a[0]) if t_in_a is None else t_in_a
    t_end_a = float(t_a[-1]) if t_end_a is None else t_end_a
    return {
        "offset_s": t_peak_b - t_peak_a,
        "t_peak_a": t_peak_a,
        "t_peak_b": t_peak_b,
        "t_in_b": t_peak_b - (t_peak_a - t_in_a),
        "t_end_b": t_peak_b + (t_end_a - t_peak_a),
    }


def xcorr_sync(t_a, angle_a, t_b, angle_b, rate_hz: float = 100.0) -> dict:
    from gpquad.data.align import estimate_offset

    al = estimate_offset(t_a, angle_a, t_b, angle_b, rate_hz=rate_hz)
    return {"offset_s": al.offset_s, "correlation": al.correlation, "rmse": al.rmse}


def residual_rmse(t_a, angle_a, t_b, angle_b, offset_s: float) -> float:
    """RMSE of the shared angle after shifting log B by the offset (the thesis's 1.59 deg)."""
    t_a, t_b = np.asarray(t_a, float), np.asarray(t_b, float)
    keep = (t_a + offset_s >= t_b[0]) & (t_a + offset_s <= t_b[-1])
    if keep.sum() < 2:
        raise GpquadError("the logs do not overlap after the shift", field="t")
    resampled = np.interp(t_a[keep] + offset_s, t_b, np.asarray(angle_b, float))
    return float(np.sqrt(np.mean((resampled - np.asarray(angle_a, float)[keep]) ** 2)))
