"""Time alignment of two logs recorded on different clocks (thesis section III.B).

Both logs must hold a shared signal (body rates, a roll angle ...). Each is put on a uniform
grid, standardised, and the clock offset is the lag of the peak of their cross-correlation
(summed over channels), refined to a fraction of a sample by a parabola through the peak.
The residual RMSE of the shared signal after the shift says how good the alignment is.

Convention: an event at time tau on clock A is at tau + offset on clock B, so
x_b(t + offset) ~ x_a(t).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import correlate

from gpquad.errors import GpquadError


@dataclass(frozen=True)
class Alignment:
    """offset_s: clock B minus clock A (s); correlation: Pearson's r after the shift;
    rmse: residual RMSE of the shared signal after the shift (its units); overlap_s."""

    offset_s: float
    correlation: float
    rmse: float
    overlap_s: float

    def shift(self, t_b: np.ndarray) -> np.ndarray:
        """Times of log B expressed on clock A."""
        return np.asarray(t_b) - self.offset_s


def _uniform(t, x, rate_hz, source):
    t = np.asarray(t, dtype=float)
    x = np.asarray(x, dtype=float)
    x = x[:, None] if x.ndim == 1 else x
    if len(t) != len(x) or len(t) < 4:
        raise GpquadError(
            "need at least 4 samples with matching time and signal lengths",
            source=source,
            field="t",
        )
    if np.any(np.diff(t) <= 0) or not np.isfinite(t).all():
        raise GpquadError("time must be finite and strictly increasing", source=source, field="t")
    ok = np.isfinite(x).all(axis=1)
    t, x = t[ok], x[ok]
    grid = np.arange(t[0], t[-1], 1.0 / rate_hz)
    return grid, np.column_stack([np.interp(grid, t, x[:, j]) for j in range(x.shape[1])])


def estimate_offset(
    t_a, x_a, t_b, x_b, rate_hz: float = 100.0, max_lag_s: float | None = None
) -> Alignment:
    """Clock offset of log B relative to log A from a shared signal.

    t_a (Na,), x_a (Na,) or (Na, k); t_b, x_b likewise with the same k; s and any unit.
    max_lag_s bounds the search (default: the shorter log's duration).
    """
    ga, ya = _uniform(t_a, x_a, rate_hz, "log A")
    gb, yb = _uniform(t_b, x_b, rate_hz, "log B")
    if ya.shape[1] != yb.shape[1]:
        raise GpquadError(
            f"log A has {ya.shape[1]} shared channels, log B {yb.shape[1]}", field="columns"
        )
    za = (ya - ya.mean(0)) / np.where(ya.std(0) > 0, ya.std(0), 1.0)
    zb = (yb - yb.mean(0)) / np.where(yb.std(0) > 0, yb.std(0), 1.0)
    if not (ya.std(0) > 0).any() or not (yb.std(0) > 0).any():
        raise GpquadError("the shared signal is constant: nothing to align on", field="columns")
    cc = sum(correlate(zb[:, j], za[:, j], mode="full", method="fft") for j in range(za.shape[1]))
    lags = np.arange(-(len(za) - 1), len(zb))  # index lag of B relative to A
    limit = max_lag_s if max_lag_s is not None else min(len(za), len(zb)) / rate_hz
    # normalise by overlap length so that short overlaps at the edges do not win by accident
    overlap = np.minimum(len(zb), lags + len(za)) - np.maximum(0, lags)
    score = np.where(overlap > 0.25 * min(len(za), len(zb)), cc / np.maximum(overlap, 1), -np.inf)
    score[np.abs(lags) / rate_hz > limit] = -np.inf
    k = int(np.argmax(score))
    frac = 0.0
    if 0 < k < len(score) - 1 and np.isfinite(score[k - 1]) and np.isfinite(score[k + 1]):
        den = score[k - 1] - 2 * score[k] + score[k + 1]
        frac = 0.5 * (score[k - 1] - score[k + 1]) / den if den != 0 else 0.0
    lag = (lags[k] + frac) / rate_hz
    offset = gb[0] - ga[0] + lag
    # residual of the shared signal after the shift, over the overlap
    t_common = ga[(ga + offset >= gb[0]) & (ga + offset <= gb[-1])]
    if len(t_common) < 2:
        raise GpquadError("the logs do not overlap after alignment", field="t")
    resid = np.column_stack(
        [
            np.interp(t_common + offset, gb, yb[:, j]) - np.interp(t_common, ga, ya[:, j])
            for j in range(ya.shape[1])
        ]
    )
    rmse = float(np.sqrt(np.mean(resid**2)))
    pairs = [
        (np.interp(t_common + offset, gb, yb[:, j]), np.interp(t_common, ga, ya[:, j]))
        for j in range(ya.shape[1])
    ]
    corr = float(
        np.mean([np.corrcoef(b, a)[0, 1] for b, a in pairs if b.std() > 0 and a.std() > 0])
    )
    return Alignment(float(offset), corr, rmse, float(t_common[-1] - t_common[0]))
