"""Engine-ready data as a file, and reading it back (`gpquad data export`).

An export holds every in-flight segment that passes the integration check, after the whole
pipeline, in the generic format: `t`, `qw..qz`, `u, v, w` (body, NED/FRD), `p, q, r`, the
chosen inputs (untrimmed), the accelerations of the integrator's exact inverse (`a_x` ..
`r_dot`, for reference; the reader recomputes them) and `segment` (0, 1, ...). Values are
written exactly (`%.17g` in CSV, float64 in Parquet), and a generic file with a `segment`
column is read back segment by segment without re-normalising or re-timing anything, so a
run on the export sees bit-identical data and gives the same equations as a run on the log.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pandas as pd

from gpquad.data.flight import Flight, _read_table, check_time, read_flight_file
from gpquad.errors import GpquadError
from gpquad.kernels.integrator import body_accelerations
from gpquad.variables import (
    BODY_VEL_COLUMNS,
    QUAT_COLUMNS,
    RATE_COLUMNS,
    TARGET_NAMES,
)

SEGMENT = "segment"


def export_frame(flights: list[Flight]) -> pd.DataFrame:
    """The flights as one generic table with accelerations and segment ids."""
    parts = []
    for k, f in enumerate(flights):
        frame = f.to_frame()
        acc = np.zeros((len(f), 6))
        acc[:-1] = body_accelerations(np.ascontiguousarray(f.vel), np.ascontiguousarray(f.rates),
                                      f.dt)
        for j, name in enumerate(TARGET_NAMES):
            frame[name] = acc[:, j]
        frame[SEGMENT] = k
        parts.append(frame)
    return pd.concat(parts, ignore_index=True)


def write_export(flights: list[Flight], path) -> Path:
    path = Path(path)
    if path.suffix.lower() not in (".csv", ".parquet", ".pq"):
        raise GpquadError("give a .csv or .parquet file", source=str(path), field="--out")
    path.parent.mkdir(parents=True, exist_ok=True)
    frame = export_frame(flights)
    if path.suffix.lower() == ".csv":
        frame.to_csv(path, index=False, float_format="%.17g")
    else:
        frame.to_parquet(path, index=False)
    return path


def _exact_flight(df: pd.DataFrame, path: Path, seg, input_names, columns) -> Flight:
    """One segment of an export, values as stored (checked like any generic file)."""
    source = f"{path} (segment {seg})"
    missing = [c for c in ("t", *QUAT_COLUMNS, *BODY_VEL_COLUMNS, *RATE_COLUMNS, *input_names)
               if columns.get(c, c) not in df.columns]
    if missing:
        raise GpquadError(f"missing column '{columns.get(missing[0], missing[0])}' in an "
                          "exported file", source=source, field=missing[0])

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
        raise GpquadError(f"quaternion norm ranges {norm.min():.6f}..{norm.max():.6f}; an "
                          "exported file holds unit quaternions", source=source, field="qw")
    return Flight(name=f"{path.name}#{seg}", t=t,
                  quat=np.ascontiguousarray(quat),
                  vel=np.ascontiguousarray(np.column_stack([col(c) for c in BODY_VEL_COLUMNS])),
                  rates=np.ascontiguousarray(np.column_stack([col(c) for c in RATE_COLUMNS])),
                  inputs=np.ascontiguousarray(np.column_stack([col(c) for c in input_names])),
                  input_names=tuple(input_names), meta={"source": str(path), "dt": dt})


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
    return [_exact_flight(df[seg == s].reset_index(drop=True), path, int(s), data.inputs,
                          data.columns) for s in order]


def export_flights(path, fmt: str | None, config=None) -> tuple[list[Flight], list[str]]:
    """Flights of a log after the pipeline and the per-segment integration check."""
    from gpquad.config import Config, load_config, validate
    from gpquad.data.cli import guess_format
    from gpquad.data.integration_check import screen_segments
    from gpquad.data.io import READERS

    path = Path(path)
    if not path.exists():
        raise GpquadError("no such file or folder", source=str(path))
    cfg = load_config(config) if config else Config()
    fmt = fmt or (cfg.data.format if config and cfg.data.format != "generic" else None) \
        or guess_format(path)
    data = dataclasses.replace(cfg.data, format=fmt, files=(str(path),))
    validate(dataclasses.replace(cfg, data=data), "command line")
    if fmt not in READERS:
        raise GpquadError(f"unknown format '{fmt}'; known: {sorted(READERS)}", source=str(path),
                          field="--format")
    flights = READERS[fmt](path, data)
    dropped: list[str] = []
    if data.check_before_run:
        flights, dropped, _ = screen_segments(flights, data.check_steps, data.check_max_rse,
                                              source=str(path))
    return flights, dropped
