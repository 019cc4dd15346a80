"""A flight log's motor speeds, accelerometer and position on one clock (`MotorLog`), as
the readers of gpquad.data.motors return them, and the conversions they share."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

RPM_TO_RAD_S = 2.0 * np.pi / 60.0
ROTOR_COLUMNS = tuple(f"rotor_{i}" for i in range(1, 5))
ERPM_COLUMNS = tuple(f"erpm_{i}" for i in range(1, 5))
ACC_COLUMNS = ("acc_x", "acc_y", "acc_z")
POS_COLUMNS = ("x", "y", "z")


@dataclass
class MotorLog:
    """One log (or one piece of it) on a uniform clock, NED/FRD, SI units.

    t (N,) s; quat (N, 4) body to world (w, x, y, z); rotor (N, 4) rad/s; acc (N, 3) body
    specific force m/s^2; vel (N, 3) world m/s; pos (N, 3) world m; rates (N, 3) body rad/s.
    A signal the log does not hold is None and `missing[name]` says what would carry it.
    valid: every present signal is there (no gap); in_flight: the reader's segmentation.
    """

    name: str
    source: str
    t: np.ndarray
    quat: np.ndarray | None
    rotor: np.ndarray | None
    acc: np.ndarray | None
    vel: np.ndarray | None
    pos: np.ndarray | None
    rates: np.ndarray | None
    valid: np.ndarray
    in_flight: np.ndarray
    missing: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)


def erpm_to_rad_s(erpm: np.ndarray, pole_pairs: int) -> np.ndarray:
    """Rotor speed (rad/s) from electrical RPM: mechanical RPM = eRPM / pole pairs."""
    return np.abs(np.asarray(erpm, dtype=float)) / pole_pairs * RPM_TO_RAD_S


def on_clock(
    grid: np.ndarray, t: np.ndarray, values: np.ndarray, max_gap_s: float
) -> tuple[np.ndarray, np.ndarray]:
    """Linear interpolation of (t, values (M, k)) onto grid, and which grid points it covers:
    inside the signal's span and not inside a gap longer than max_gap_s (or 2.5 periods)."""
    t = np.asarray(t, dtype=float)
    values = np.asarray(values, dtype=float).reshape(len(t), -1)
    ok = np.isfinite(t) & np.all(np.isfinite(values), axis=1)
    t, values = t[ok], values[ok]
    if len(t) < 2:
        return np.full((len(grid), values.shape[1]), np.nan), np.zeros(len(grid), dtype=bool)
    order = np.argsort(t, kind="stable")
    t, values = t[order], values[order]
    gap = max(max_gap_s, 2.5 * float(np.median(np.diff(t))))
    out = np.column_stack([np.interp(grid, t, values[:, j]) for j in range(values.shape[1])])
    idx = np.clip(np.searchsorted(t, grid, side="right") - 1, 0, len(t) - 2)
    covered = (grid >= t[0]) & (grid <= t[-1]) & ~((t[idx + 1] - t[idx] > gap) & (grid > t[idx]))
    return out, covered
