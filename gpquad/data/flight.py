"""The Flight record and the generic flight file (CSV or Parquet).

Generic columns: `t` (s); `qw, qx, qy, qz` (body-to-world quaternion);
`u, v, w` (body velocity, m/s) or `vx, vy, vz` (world velocity, m/s);
`p, q, r` (body rates, rad/s); the input columns; optional `x, y, z` (m).
Frames: NED/FRD or ENU/FLU, converted to NED/FRD, which the engine uses.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from gpquad.data.plausibility import (
    MAX_PLAUSIBLE_RATE,
    check_excitation,
    check_rates_follow_quaternion,
    check_sample_rate,
)
from gpquad.engine.kernels.integrator import world_to_body
from gpquad.engine.variables import (
    BODY_VEL_COLUMNS,
    POSITION_COLUMNS,
    QUAT_COLUMNS,
    RATE_COLUMNS,
    WORLD_VEL_COLUMNS,
)
from gpquad.errors import GpquadError
from gpquad.extras import require

if TYPE_CHECKING:  # pandas loads where a table is read or made (a search needs none)
    import pandas as pd

#: Allowed relative jitter of the sample period.
DT_TOLERANCE = 0.01


@dataclass
class Flight:
    """One uniformly sampled, in-flight segment in NED/FRD.

    t (N,) s; quat (N, 4) body-to-world (w, x, y, z); vel (N, 3) body m/s;
    rates (N, 3) body rad/s; inputs (N, n_inputs); pos (N, 3) world m or None.
    """

    name: str
    t: np.ndarray
    quat: np.ndarray
    vel: np.ndarray
    rates: np.ndarray
    inputs: np.ndarray
    input_names: tuple[str, ...]
    pos: np.ndarray | None = None
    meta: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.t)

    @property
    def dt(self) -> float:
        return float(np.median(np.diff(self.t)))

    def to_frame(self) -> pd.DataFrame:
        """The flight as a generic-format table (NED/FRD)."""
        import pandas as pd

        cols = {"t": self.t}
        cols.update({c: self.quat[:, i] for i, c in enumerate(QUAT_COLUMNS)})
        cols.update({c: self.vel[:, i] for i, c in enumerate(BODY_VEL_COLUMNS)})
        cols.update({c: self.rates[:, i] for i, c in enumerate(RATE_COLUMNS)})
        if self.pos is not None:
            cols.update({c: self.pos[:, i] for i, c in enumerate(POSITION_COLUMNS)})
        cols.update({c: self.inputs[:, i] for i, c in enumerate(self.input_names)})
        return pd.DataFrame(cols)


# Frame conversion ENU/FLU -> NED/FRD: q_ned_frd = Q_WORLD * q_enu_flu * Q_BODY.
_Q_WORLD = np.array([0.0, np.sqrt(0.5), np.sqrt(0.5), 0.0])  # pi about (1, 1, 0)/sqrt(2)
_Q_BODY = np.array([0.0, 1.0, 0.0, 0.0])  # pi about x


def _quat_mul_rows(a, b):
    a0, a1, a2, a3 = np.moveaxis(np.broadcast_to(a, np.broadcast_shapes(a.shape, b.shape)), -1, 0)
    b0, b1, b2, b3 = np.moveaxis(np.broadcast_to(b, np.broadcast_shapes(a.shape, b.shape)), -1, 0)
    return np.stack(
        [
            a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3,
            a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2,
            a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1,
            a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0,
        ],
        axis=-1,
    )


def enu_flu_quat(quat):
    """Body-to-world quaternions (N, 4) from ENU/FLU to NED/FRD (its own inverse)."""
    q = _quat_mul_rows(_quat_mul_rows(_Q_WORLD, quat), _Q_BODY)
    return np.where(q[:, :1] < 0, -q, q)  # same rotation, w >= 0


def flip_body(vectors):
    """Body vectors (N, 3) FLU <-> FRD."""
    return vectors * np.array([1.0, -1.0, -1.0])


def flip_world(vectors):
    """World vectors (N, 3) ENU <-> NED."""
    return vectors[:, [1, 0, 2]] * np.array([1.0, 1.0, -1.0])


def _read_table(path: Path) -> pd.DataFrame:
    import pandas as pd

    if not path.is_file():
        raise GpquadError("file not found", source=str(path))
    suffix = path.suffix.lower()
    try:
        if suffix == ".csv":
            return pd.read_csv(path)
        if suffix in (".parquet", ".pq"):
            require("pyarrow", "reading Parquet files")
            return pd.read_parquet(path)
    except GpquadError:
        raise
    except Exception as exc:  # truncated or corrupt files
        raise GpquadError(
            f"cannot read the file ({type(exc).__name__}: {exc})", source=str(path)
        ) from None
    raise GpquadError(
        f"unknown file type '{suffix}'; the generic format is .csv or .parquet "
        "(set data.format for PX4 or Betaflight logs)",
        source=str(path),
    )


def _column(df: pd.DataFrame, name: str, columns: dict, source: str) -> np.ndarray:
    import pandas as pd

    col = columns.get(name, name)
    if col not in df.columns:
        raise GpquadError(
            f"missing column '{col}'; map it with [data.columns] {name} = \"...\"",
            source=source,
            field=col,
        )
    values = pd.to_numeric(df[col], errors="coerce").to_numpy(dtype=float)
    bad = ~np.isfinite(values)
    if bad.any():
        first = int(np.argmax(bad))
        raise GpquadError(
            f"{int(bad.sum())} NaN or non-numeric values (first at row {first}); "
            "clean or cut the log",
            source=source,
            field=col,
        )
    return values


def check_time(t: np.ndarray, source: str, column: str = "t") -> float:
    """Validate a time column (s): strictly increasing and uniformly sampled. Returns dt."""
    if len(t) < 3:
        raise GpquadError(f"only {len(t)} samples", source=source, field=column)
    steps = np.diff(t)
    if (steps <= 0).any():
        i = int(np.argmax(steps <= 0))
        raise GpquadError(
            f"time is not increasing at row {i + 1} ({t[i]} then {t[i + 1]}); "
            "sort the log or drop duplicate rows",
            source=source,
            field=column,
        )
    dt = float(np.median(steps))
    if np.abs(steps - dt).max() > DT_TOLERANCE * dt:
        raise GpquadError(
            f"sampling is not uniform (dt from {steps.min():.4g} to "
            f"{steps.max():.4g} s); resample the log first "
            "(gpquad's PX4/Betaflight readers do this)",
            source=source,
            field=column,
        )
    return dt


def check_units(quat, rates, source: str):
    """Catch quaternions that are not unit and rates that look like deg/s."""
    norm = np.linalg.norm(quat, axis=1)
    if np.abs(norm - 1.0).max() > 1e-2:
        raise GpquadError(
            f"quaternion norm ranges {norm.min():.3f}..{norm.max():.3f}, not 1; "
            "give a unit quaternion (w, x, y, z)",
            source=source,
            field="qw",
        )
    peaks = np.abs(rates).max(axis=0)
    if peaks.max() > MAX_PLAUSIBLE_RATE:
        column = RATE_COLUMNS[int(np.argmax(peaks))]
        raise GpquadError(
            f"body rate reaches {peaks.max():.1f}, implausible in rad/s; convert deg/s to rad/s",
            source=source,
            field=column,
        )


def read_flight_file(
    path, input_names, frame: str = "NED/FRD", columns: dict | None = None
) -> Flight:
    """Read and validate one generic flight file (CSV or Parquet)."""
    path = Path(path)
    return flight_from_frame(_read_table(path), input_names, frame, columns, str(path), path.name)


def flight_from_frame(
    df: pd.DataFrame,
    input_names,
    frame: str = "NED/FRD",
    columns: dict | None = None,
    source: str = "DataFrame",
    name: str = "flight",
) -> Flight:
    """Validate a table of the generic columns (module notes) and make it a Flight."""
    columns = columns or {}
    t = _column(df, "t", columns, source)
    dt = check_time(t, source, columns.get("t", "t"))
    check_sample_rate(dt, source, columns.get("t", "t"))
    quat = np.column_stack([_column(df, c, columns, source) for c in QUAT_COLUMNS])
    rates = np.column_stack([_column(df, c, columns, source) for c in RATE_COLUMNS])
    check_units(quat, rates, source)
    quat = quat / np.linalg.norm(quat, axis=1, keepdims=True)
    has_body = all(columns.get(c, c) in df.columns for c in BODY_VEL_COLUMNS)
    has_world = all(columns.get(c, c) in df.columns for c in WORLD_VEL_COLUMNS)
    if not (has_body or has_world):
        raise GpquadError(
            "needs body velocity columns u, v, w or world velocity vx, vy, vz",
            source=source,
            field="u",
        )
    vel_cols = BODY_VEL_COLUMNS if has_body else WORLD_VEL_COLUMNS
    vel = np.column_stack([_column(df, c, columns, source) for c in vel_cols])
    pos = None
    if all(columns.get(c, c) in df.columns for c in POSITION_COLUMNS):
        pos = np.column_stack([_column(df, c, columns, source) for c in POSITION_COLUMNS])
    inputs = np.column_stack([_column(df, c, columns, source) for c in input_names])
    if frame == "ENU/FLU":
        quat = enu_flu_quat(quat)
        rates = flip_body(rates)
        vel = flip_body(vel) if has_body else flip_world(vel)
        pos = None if pos is None else flip_world(pos)
    elif frame != "NED/FRD":
        raise GpquadError(f"unknown frame '{frame}'", source=source, field="frame")
    if not has_body:
        vel = world_to_body(np.ascontiguousarray(quat), np.ascontiguousarray(vel))
    check_rates_follow_quaternion(
        quat,
        rates,
        dt,
        source,
        tuple(columns.get(c, c) for c in RATE_COLUMNS),
        columns.get("qw", "qw"),
    )
    check_excitation(rates, vel, inputs, [columns.get(c, c) for c in input_names], source)
    return Flight(
        name=name,
        t=t - t[0],
        quat=quat,
        vel=vel,
        rates=rates,
        inputs=inputs,
        input_names=tuple(input_names),
        pos=pos,
        meta={"source": source, "dt": dt},
    )


def flights_of(
    items, input_names, frame: str = "NED/FRD", columns: dict | None = None, read=None
) -> list[Flight]:
    """Flights from a list of Flights, DataFrames of the generic columns (module notes) and,
    with `read(path) -> list[Flight]`, log paths; anything else is one line naming it."""
    import pandas as pd

    flights: list[Flight] = []
    for k, item in enumerate(items):
        if isinstance(item, Flight):
            flights.append(item)
        elif isinstance(item, pd.DataFrame):
            flights.append(
                flight_from_frame(item, input_names, frame, columns, f"DataFrame {k}", f"flight{k}")
            )
        elif read is not None and isinstance(item, (str, Path)):
            flights.extend(read(item))
        else:
            raise GpquadError(
                f"data[{k}] is a {type(item).__name__}; give DataFrames, Flights or log paths",
                field="data",
            )
    return flights


def write_flight_file(flight: Flight, path) -> Path:
    """Write a flight in the generic format (by suffix: .csv or .parquet)."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".csv", ".parquet", ".pq"):
        raise GpquadError(
            f"cannot tell the format from '{path.suffix or 'no suffix'}'; name the "
            "file .csv or .parquet",
            source=str(path),
            field="--out",
        )
    path.parent.mkdir(parents=True, exist_ok=True)
    frame = flight.to_frame()
    if suffix == ".csv":
        frame.to_csv(path, index=False, float_format="%.17g")
    else:
        require("pyarrow", "writing Parquet files")
        frame.to_parquet(path, index=False)
    return path
