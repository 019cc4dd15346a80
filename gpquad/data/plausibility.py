"""Checks on a flight's signals that their types cannot show: clock units, quaternion component
order, rates against the attitude, and excitation.

The log readers resample, filter and derive rates from the quaternion, and then compare the
logged gyro with the quaternion (`pipeline.check_rate_units`). A generic file is taken as it
is, so the same questions are asked of it here, each as a one-line error naming the field:

- the sample rate is plausible for a flight log (1 Hz to 2 kHz): a time column in
  microseconds or milliseconds is caught before anything is resampled or allocated;
- the logged body rates follow the rates the attitude quaternion implies, axis by axis
  (least-squares scale near 1, correlation above `MIN_RATE_CORRELATION`): deg/s, an axis of
  the wrong sign, or a quaternion stored x, y, z, w are errors, the last one named as such;
- the flight moves: rates and velocities that do not change, or inputs that never change,
  cannot identify anything.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from gpquad.engine.kernels.integrator import rates_from_quaternions
from gpquad.engine.variables import QUAT_COLUMNS, RATE_COLUMNS
from gpquad.errors import GpquadError

if TYPE_CHECKING:
    import pandas as pd

#: Body rates above this (rad/s) are implausible for a multirotor: degrees logged as radians.
MAX_PLAUSIBLE_RATE = 40.0
#: Plausible sample rates of a flight log (Hz).
MIN_RATE_HZ, MAX_RATE_HZ = 1.0, 2000.0
#: Axes rotating less than this (RMS about zero, rad/s) are not judged against the quaternion.
MIN_JUDGED_RATE = 0.05
#: Below this correlation a logged rate does not follow the attitude quaternion.
MIN_RATE_CORRELATION = 0.5
#: A flight whose rates (rad/s) and velocities (m/s) vary less than this (SD) does not move.
MIN_MOTION_SD = 1e-3


def check_sample_rate(dt: float, source: str, field: str = "t") -> None:
    """A one-line error when 1 / dt is not a flight log's sample rate."""
    rate = 1.0 / dt if dt > 0 else np.inf
    if MIN_RATE_HZ <= rate <= MAX_RATE_HZ:
        return
    hint = (
        "time in microseconds or milliseconds? give it in seconds"
        if rate < MIN_RATE_HZ
        else "time in a unit larger than seconds? give it in seconds"
    )
    raise GpquadError(
        f"samples every {dt:.6g} s ({rate:.4g} Hz), outside the plausible "
        f"{MIN_RATE_HZ:g}..{MAX_RATE_HZ:g} Hz of a flight log: {hint}",
        source=source,
        field=field,
    )


def _agreement(quat: np.ndarray, rates: np.ndarray, dt: float) -> list[tuple[float, float]]:
    """(scale, correlation) per moving axis of logged rates vs quaternion rates; NaN if still."""
    implied = rates_from_quaternions(np.ascontiguousarray(quat), dt)
    logged = rates[: len(implied)]
    out = []
    for j in range(3):
        power = float(np.mean(implied[:, j] ** 2))
        if power < MIN_JUDGED_RATE**2 and float(np.mean(logged[:, j] ** 2)) < MIN_JUDGED_RATE**2:
            out.append((np.nan, np.nan))
            continue
        scale = float(np.mean(logged[:, j] * implied[:, j])) / max(power, 1e-300)
        den = np.sqrt(power * float(np.mean(logged[:, j] ** 2)))
        out.append((scale, float(np.mean(logged[:, j] * implied[:, j])) / den if den > 0 else 0.0))
    return out


def check_rates_follow_quaternion(
    quat: np.ndarray,
    rates: np.ndarray,
    dt: float,
    source: str,
    fields=("p", "q", "r"),
    quat_field: str = "qw",
) -> None:
    """One-line errors for rates that disagree with the attitude (see the module doc)."""
    for j, (scale, corr) in enumerate(_agreement(quat, rates, dt)):
        if np.isnan(scale):
            continue
        if 20.0 < scale < 200.0:
            raise GpquadError(
                f"body rates are {scale:.0f} times those the attitude quaternion "
                "implies: degrees where radians are expected? convert deg/s to "
                "rad/s",
                source=source,
                field=fields[j],
            )
        if corr < MIN_RATE_CORRELATION:
            swapped = quat[:, [3, 0, 1, 2]]  # read as x, y, z, w
            if all(np.isnan(c) or c > 0.9 for _, c in _agreement(swapped, rates, dt)):
                raise GpquadError(
                    "the quaternion looks stored as x, y, z, w; gpquad reads w, x, "
                    "y, z: reorder the columns or map them with [data.columns]",
                    source=source,
                    field=quat_field,
                )
            sign = "the opposite sign of" if scale < 0 else "little to do with"
            raise GpquadError(
                f"body rate {fields[j]} has {sign} the rate the attitude "
                f"quaternion implies (correlation {corr:.2f}, scale {scale:.2f}): "
                "rates and attitude in different frames or axes? declare "
                "data.frame, or fix the column",
                source=source,
                field=fields[j],
            )


def check_excitation(
    rates: np.ndarray, vel: np.ndarray, inputs: np.ndarray, input_names, source: str
) -> None:
    """One-line errors for a flight that does not move or whose inputs never change."""
    if (
        max(float(np.max(np.std(rates, axis=0))), float(np.max(np.std(vel, axis=0))))
        < MIN_MOTION_SD
    ):
        raise GpquadError(
            "the flight does not move (rates and velocities constant): nothing "
            "to identify; give an in-flight log",
            source=source,
            field="p",
        )
    if len(input_names) and float(np.max(np.ptp(inputs, axis=0))) == 0.0:
        raise GpquadError(
            f"the inputs {list(input_names)} never change: nothing to identify "
            "their effect from; check the input columns",
            source=source,
            field=input_names[0],
        )


def check_stream_time(t: np.ndarray, source: str, field: str) -> None:
    """Timestamps must be finite and strictly increasing (no duplicates, no steps back)."""
    if len(t) < 2:
        raise GpquadError(f"only {len(t)} samples", source=source, field=field)
    if not np.isfinite(t).all():
        raise GpquadError("non-numeric or NaN timestamps", source=source, field=field)
    steps = np.diff(t)
    bad = np.flatnonzero(steps <= 0)
    if bad.size:
        i = int(bad[0])
        kind = "duplicate" if steps[i] == 0 else "backwards"
        raise GpquadError(
            f"{bad.size} {kind} timestamps (first at row {i + 1}: {t[i]:.6f} then "
            f"{t[i + 1]:.6f} s); the log is damaged or unsorted",
            source=source,
            field=field,
        )


def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) index ranges of the True runs of a boolean array."""
    m = np.concatenate([[False], np.asarray(mask, dtype=bool), [False]])
    edges = np.flatnonzero(np.diff(m.astype(np.int8)))
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=False)]


def check_rate_peak(values: np.ndarray, source: str, fields: tuple[str, ...]) -> None:
    """Rates (M, 3) beyond MAX_PLAUSIBLE_RATE rad/s are a one-line error naming the axis."""
    values = np.asarray(values, dtype=float).reshape(-1, len(fields))
    finite = np.where(np.isfinite(values), np.abs(values), 0.0)
    peaks = finite.max(axis=0) if len(values) else np.zeros(len(fields))
    j = int(np.argmax(peaks))
    if peaks[j] > MAX_PLAUSIBLE_RATE:
        raise GpquadError(
            f"body rates reach {peaks[j]:.1f}, implausible in rad/s: degrees "
            "where radians are expected? convert deg/s to rad/s",
            source=source,
            field=fields[j],
        )


#: Axes rotating less than this (RMS, rad/s) are not used to check the gyro's units.
UNIT_CHECK_MIN_RATE = 0.05


def check_rate_units(
    table: pd.DataFrame, valid: np.ndarray, source: str, fields: tuple[str, str, str]
) -> None:
    """Compare the logged body rates with those implied by the quaternion, axis by axis.

    On the longest gap-free run, the least-squares scale s of log rate = s * quaternion rate
    is about 1 for consistent data, about 57 for deg/s logged as rad/s, and about -1 for an
    axis whose sign follows another frame (FLU vs FRD). The two last are one-line errors
    naming `fields[axis]`. Axes that hardly rotate are not judged.
    """
    if not all(c in table.columns for c in RATE_COLUMNS) or not valid.any():
        return
    a, b = max(runs(valid), key=lambda r: r[1] - r[0])
    if b - a < 3:
        return
    t = table["t"].to_numpy()
    quat = np.ascontiguousarray(table[list(QUAT_COLUMNS)].to_numpy()[a:b])
    implied = rates_from_quaternions(quat, float(t[a + 1] - t[a]))
    logged = table[list(RATE_COLUMNS)].to_numpy()[a : b - 1]
    for j in range(3):
        power = float(np.mean(implied[:, j] ** 2))
        if power < UNIT_CHECK_MIN_RATE**2:
            continue
        scale = float(np.mean(logged[:, j] * implied[:, j])) / power
        if 20.0 < scale < 200.0:
            raise GpquadError(
                f"body rates are {scale:.0f} times those the attitude quaternion "
                "implies: degrees where radians are expected? convert deg/s to "
                "rad/s",
                source=source,
                field=fields[j],
            )
        if scale < -0.5:
            raise GpquadError(
                f"body rate {RATE_COLUMNS[j]} has the opposite sign of the rate the "
                f"attitude quaternion implies (scale {scale:.2f}): rates and "
                "attitude in different frames? declare data.frame or flip the "
                "column",
                source=source,
                field=fields[j],
            )
