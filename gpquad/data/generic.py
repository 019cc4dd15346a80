"""Reader for `data.format = "generic"`: one flight per file, or one per `segment` of a file
written by `gpquad data export`, whose values are read back exactly (no re-normalising or
re-timing), so that a run on an export sees the same data as a run on the log."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from gpquad.data.flight import Flight, _read_table, check_time, read_flight_file
from gpquad.engine.variables import BODY_VEL_COLUMNS, QUAT_COLUMNS, RATE_COLUMNS
from gpquad.errors import GpquadError

SEGMENT = "segment"
#: States whose `measured_<state>` column (1/0) an export carries, so that a run on the export
#: knows, as a run on the log does, which states the log does not measure.
MEASURED_STATES = ("u", "v", "w", "p", "q", "r")


def _exact_flight(df: pd.DataFrame, path: Path, seg, input_names, columns) -> Flight:
    """One segment of an export, values as stored (checked like any generic file)."""
    source = f"{path} (segment {seg})"
    missing = [
        c
        for c in ("t", *QUAT_COLUMNS, *BODY_VEL_COLUMNS, *RATE_COLUMNS, *input_names)
        if columns.get(c, c) not in df.columns
    ]
    if missing:
        raise GpquadError(
            f"missing column '{columns.get(missing[0], missing[0])}' in an exported file",
            source=source,
            field=missing[0],
        )

    def col(name):
        values = pd.to_numeric(df[columns.get(name, name)], errors="coerce").to_numpy(float)
        if not np.isfinite(values).all():
            raise GpquadError("NaN or non-numeric values", source=source, field=name)
        return values

    t = col("t")
    dt = check_time(t, source)
    quat = np.column_stack([col(c) for c in QUAT_COLUMNS])
    norm = np.linalg.norm(quat, axis=1)
    if np.abs(norm - 1.0).max() > 1e-9:
        raise GpquadError(
            f"quaternion norm ranges {norm.min():.6f}..{norm.max():.6f}; an "
            "exported file holds unit quaternions",
            source=source,
            field="qw",
        )
    return Flight(
        name=f"{path.name}#{seg}",
        t=t,
        quat=np.ascontiguousarray(quat),
        vel=np.ascontiguousarray(np.column_stack([col(c) for c in BODY_VEL_COLUMNS])),
        rates=np.ascontiguousarray(np.column_stack([col(c) for c in RATE_COLUMNS])),
        inputs=np.ascontiguousarray(np.column_stack([col(c) for c in input_names])),
        input_names=tuple(input_names),
        meta={"source": str(path), "dt": dt, **_measured(df)},
    )


def _measured(df: pd.DataFrame) -> dict:
    """{"measured": {...}} from an export's measured_<state> columns ({} without them)."""
    flags = {
        s: df[f"measured_{s}"].iloc[0]
        for s in MEASURED_STATES
        if f"measured_{s}" in df.columns and len(df)
    }
    if not flags:
        return {}
    return {
        "measured": {
            s: "measured (export)" if int(v) else "not measured (export)" for s, v in flags.items()
        }
    }


def read_generic(path, data) -> list[Flight]:
    """Reader for format "generic": one flight per file, or one per `segment` of an export."""
    path = Path(path)
    df = _read_table(path)
    if SEGMENT not in df.columns:
        return [read_flight_file(path, data.inputs, data.frame, data.columns)]
    if data.frame != "NED/FRD":
        raise GpquadError("an exported file is NED/FRD", source=str(path), field="data.frame")
    seg = pd.to_numeric(df[SEGMENT], errors="coerce").to_numpy(float)
    if not np.isfinite(seg).all():
        raise GpquadError("NaN or non-numeric segment ids", source=str(path), field=SEGMENT)
    order = list(dict.fromkeys(seg.tolist()))
    return [
        _exact_flight(df[seg == s].reset_index(drop=True), path, int(s), data.inputs, data.columns)
        for s in order
    ]
