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

from pathlib import Path

import numpy as np
import pandas as pd

from gpquad.data.flight import Flight
from gpquad.data.generic import MEASURED_STATES, SEGMENT
from gpquad.engine.kernels.integrator import body_accelerations
from gpquad.engine.variables import (
    TARGET_NAMES,
)
from gpquad.errors import GpquadError


def export_frame(flights: list[Flight]) -> pd.DataFrame:
    """The flights as one generic table with accelerations and segment ids."""
    parts = []
    for k, f in enumerate(flights):
        frame = f.to_frame()
        acc = np.zeros((len(f), 6))
        acc[:-1] = body_accelerations(
            np.ascontiguousarray(f.vel), np.ascontiguousarray(f.rates), f.dt
        )
        for j, name in enumerate(TARGET_NAMES):
            frame[name] = acc[:, j]
        frame[SEGMENT] = k
        measured = f.meta.get("measured", {})
        for state in MEASURED_STATES:  # 1 where the log measures the state, 0 where not
            frame[f"measured_{state}"] = int(measured.get(state, "measured").startswith("measured"))
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
        from gpquad.extras import require

        require("pyarrow", "writing Parquet files")
        frame.to_parquet(path, index=False)
    return path


def export_flights(path, fmt: str | None, config=None) -> tuple[list[Flight], list[str]]:
    """Flights of a log after the pipeline and the per-segment integration check."""
    from gpquad.data.integration_check import screen_segments
    from gpquad.data.io import READERS, resolve_log

    path, cfg, data = resolve_log(path, fmt, config)
    fmt = data.format
    if fmt not in READERS:
        raise GpquadError(
            f"unknown format '{fmt}'; known: {sorted(READERS)}", source=str(path), field="--format"
        )
    flights = READERS[fmt](path, data)
    dropped: list[str] = []
    if data.check_before_run:
        flights, dropped, _ = screen_segments(
            flights, data.check_steps, data.check_max_rse, source=str(path)
        )
    return flights, dropped
