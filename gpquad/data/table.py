"""Generic CSV/Parquet logs that are not uniformly sampled (format "table").

Same columns and `[data.columns]` mapping as the generic format (gpquad.data.flight): `t` (s),
`qw, qx, qy, qz`, `p, q, r` (optional: derived from the quaternion), `u, v, w` or
`vx, vy, vz` or only `x, y, z` (motion capture: velocity from position differences), the
inputs; `data.frame` declares NED/FRD or ENU/FLU. Unlike "generic", the rows
may be irregular and may hold NaN runs: the table goes through the whole pipeline (one clock,
gaps split, segmentation on `u_T` or a time range, filter, downsample).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gpquad.data.flight import (
    Flight,
    _read_table,
    enu_flu_quat,
    flip_body,
    flip_world,
)
from gpquad.data.pipeline import LogTable, flights_from_log
from gpquad.data.plausibility import check_rate_peak, check_rate_units
from gpquad.data.streams import Stream, in_flight_mask, resample
from gpquad.engine.variables import (
    BODY_VEL_COLUMNS,
    POSITION_COLUMNS,
    QUAT_COLUMNS,
    RATE_COLUMNS,
    WORLD_VEL_COLUMNS,
)
from gpquad.errors import GpquadError


def table_log(path, data) -> LogTable:
    """A generic table as a LogTable on one clock."""
    path = Path(path)
    source = str(path)
    df = _read_table(path)
    cols = data.columns

    def col(name):
        c = cols.get(name, name)
        if c not in df.columns:
            raise GpquadError(
                f"missing column '{c}'; map it with [data.columns] {name} = \"...\"",
                source=source,
                field=c,
            )
        import pandas as pd

        return pd.to_numeric(df[c], errors="coerce").to_numpy(dtype=float)

    def have(names):
        return all(cols.get(n, n) in df.columns for n in names)

    t = col("t")
    quat = np.column_stack([col(c) for c in QUAT_COLUMNS])
    if have(BODY_VEL_COLUMNS):
        vel, vel_cols = np.column_stack([col(c) for c in BODY_VEL_COLUMNS]), BODY_VEL_COLUMNS
    elif have(WORLD_VEL_COLUMNS):
        vel, vel_cols = np.column_stack([col(c) for c in WORLD_VEL_COLUMNS]), WORLD_VEL_COLUMNS
    elif have(POSITION_COLUMNS):  # motion capture: velocity from position differences
        vel, vel_cols = np.column_stack([col(c) for c in POSITION_COLUMNS]), POSITION_COLUMNS
    else:
        raise GpquadError(
            "needs body velocity u, v, w, world velocity vx, vy, vz or position x, y, z columns",
            source=source,
            field="u",
        )
    rates = np.column_stack([col(c) for c in RATE_COLUMNS]) if have(RATE_COLUMNS) else None
    rate_fields = tuple(cols.get(c, c) for c in RATE_COLUMNS)
    if rates is not None:
        check_rate_peak(rates, source, rate_fields)
    if data.frame == "ENU/FLU":
        ok = np.isfinite(quat).all(axis=1)
        quat[ok] = enu_flu_quat(quat[ok])
        vel = flip_body(vel) if vel_cols == BODY_VEL_COLUMNS else flip_world(vel)
        rates = None if rates is None else flip_body(rates)
    inputs = np.column_stack([col(n) for n in data.inputs])
    streams = [
        Stream("quaternion", t, quat, QUAT_COLUMNS, "quat", source, cols.get("t", "t")),
        Stream("velocity", t, vel, vel_cols, "state", source, cols.get("t", "t")),
        Stream("inputs", t, inputs, tuple(data.inputs), "hold", source, cols.get("t", "t")),
    ]
    if rates is not None:
        streams.append(Stream("rates", t, rates, RATE_COLUMNS, "state", source, cols.get("t", "t")))
    table, valid, info = resample(streams, data.resample_hz, data.max_gap_s)
    if rates is not None:
        check_rate_units(table, valid, source, rate_fields)
    thrust = table["u_T"].to_numpy() if "u_T" in table.columns else None
    mode_needs_thrust = data.segment in ("auto", "thrust")
    if mode_needs_thrust and thrust is None:
        raise GpquadError(
            "segment on thrust needs an input u_T; set data.segment = 'none' or 'range'",
            source=source,
            field="data.segment",
        )
    mask = in_flight_mask(table["t"].to_numpy(), None, thrust, data, source)
    measured = {a: "measured (file column)" for a in ("phi", "theta", "psi", "u", "v", "w")}
    if vel_cols == POSITION_COLUMNS:
        measured.update({a: "measured (from position differences)" for a in "uvw"})
    measured.update(
        {
            a: "measured (file column)"
            if rates is not None
            else "measured (derived from the quaternion)"
            for a in "pqr"
        }
    )
    return LogTable(
        name=path.stem,
        source=source,
        table=table,
        valid=valid,
        in_flight=mask,
        rate_hz=data.resample_hz,
        input_names=tuple(data.inputs),
        measured=measured,
        streams=info,
    )


def read_table_log(path, data) -> list[Flight]:
    """Reader for format "table"."""
    return flights_from_log(table_log(path, data), data)
