"""PX4 ULog binary files (format "ulog"), read with pyulog.

The topics are taken from the .ulg exactly as `ulog2csv` would write them and then go through
the same PX4 path as a CSV folder (`gpquad.data.px4.px4_log_table`): same signals, frames, units,
segmentation and pipeline. A truncated file is read up to its last whole message (pyulog's
behaviour); a file that is not a ULog is a one-line error.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from gpquad.data.flight import Flight
from gpquad.data.pipeline import LogTable, flights_from_log
from gpquad.data.px4 import _WANTED, Topics, px4_log_table
from gpquad.errors import GpquadError


def read_ulog_topics(path) -> Topics:
    """Topic tables (timestamp in us) and parameters of a .ulg file."""
    path = Path(path)
    if not path.is_file():
        raise GpquadError("file not found", source=str(path))
    try:
        from pyulog import ULog

        ulog = ULog(str(path), list(_WANTED | {"vehicle_angular_velocity"}))
    except Exception as exc:  # pyulog raises many kinds on corrupt input
        raise GpquadError(
            f"not a readable ULog file ({type(exc).__name__}: {exc})", source=str(path)
        ) from None
    tables, sources = {}, {}
    for d in ulog.data_list:
        key = d.name if d.multi_id == 0 else f"{d.name}#{d.multi_id}"
        tables[key] = pd.DataFrame({k: np.asarray(v) for k, v in d.data.items()})
        sources[key] = f"{path}:{key}"
    params = {k: float(v) for k, v in ulog.initial_parameters.items()}
    return Topics(tables, sources, params, str(path))


def read_ulog_log(path, data) -> LogTable:
    """A .ulg file as one LogTable on one clock."""
    return px4_log_table(read_ulog_topics(path), data, Path(path).stem)


def read_ulog(path, data) -> list[Flight]:
    """Reader for format "ulog": in-flight segments of a .ulg file."""
    return flights_from_log(read_ulog_log(path, data), data)
