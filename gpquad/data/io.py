"""Load the flights an experiment config names, whatever their format.

READERS maps a `data.format` name to a function (path, DataConfig) -> list[Flight]
(a log may hold several in-flight segments). With no files, the reference
simulator's flight is used.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from pathlib import Path

from gpquad._lazy import imported
from gpquad.data.dataset import Dataset, build_dataset
from gpquad.data.flight import Flight
from gpquad.data.formats import FORMATS
from gpquad.errors import GpquadError
from gpquad.study.config import Config, DataConfig

READERS: dict[str, Callable[[Path, DataConfig], list[Flight]]] = {}


def register_reader(name: str, reader: Callable[[Path, DataConfig], list[Flight]]) -> None:
    """Make a log format available to `data.format`."""
    READERS[name] = reader
    FORMATS.add(name)


def _lazy_reader(module: str, name: str) -> Callable[[Path, DataConfig], list[Flight]]:
    """The reader `name` of gpquad.data.`module`, imported when a log is first read: a run
    imports only its own format's reader (and the libraries it needs)."""

    def read(path: Path, data: DataConfig) -> list[Flight]:
        return imported(f"gpquad.data.{module}", name)(path, data)

    read.__name__ = read.__qualname__ = name
    read.__doc__ = f"gpquad.data.{module}.{name}, imported on first use."
    return read


def _register_log_readers() -> None:
    """gpquad's generic flight files (one flight per file; an export of `gpquad data export`
    gives one per segment), PX4 (ulog2csv folders, .ulg), Betaflight blackbox and resampled
    tables (gpquad.data)."""
    for name, module, function in (
        ("generic", "generic", "read_generic"),
        ("px4-csv", "px4", "read_px4_csv"),
        ("ulog", "ulog", "read_ulog"),
        ("betaflight", "betaflight", "read_betaflight"),
        ("table", "table", "read_table_log"),
        ("ardupilot", "ardupilot", "read_ardupilot"),
    ):
        READERS.setdefault(name, _lazy_reader(module, function))


_register_log_readers()


def _is_generic_file(path: Path) -> bool:
    """True for a CSV/Parquet already in gpquad's generic format (what `gpquad run` reads)."""
    import numpy as np
    import pandas as pd

    from gpquad.data.flight import DT_TOLERANCE
    from gpquad.engine.variables import QUAT_COLUMNS, RATE_COLUMNS

    try:
        if path.suffix.lower() == ".csv":
            frame = pd.read_csv(path, nrows=2000)
        else:
            frame = pd.read_parquet(path)
    except Exception:  # unreadable here: let the table reader report it properly
        return False
    if not {"t", *QUAT_COLUMNS, *RATE_COLUMNS} <= set(frame.columns) or len(frame) < 3:
        return False
    steps = np.diff(pd.to_numeric(frame["t"], errors="coerce").to_numpy(dtype=float))
    dt = np.median(steps)
    return bool(dt > 0 and np.all(np.abs(steps - dt) <= DT_TOLERANCE * dt))


def guess_format(path: Path, allow_generic: bool = True) -> str:
    """Format name from a path: folder -> px4-csv, .ulg, .bbl/.bfl; .csv/.parquet -> generic
    when already uniform with the generic columns (as `gpquad run` reads it; only if
    allow_generic), else table."""
    if path.is_dir():
        return "px4-csv"
    suffix = path.suffix.lower()
    if suffix == ".ulg":
        return "ulog"
    if suffix in (".bbl", ".bfl", ".txt"):
        return "betaflight"
    if suffix == ".bin":
        return "ardupilot"
    if suffix in (".csv", ".parquet", ".pq"):
        return "generic" if allow_generic and _is_generic_file(path) else "table"
    raise GpquadError(
        f"cannot tell the log format from '{suffix}'; give --format (px4-csv, "
        "ulog, betaflight, ardupilot, table, generic)",
        source=str(path),
        field="--format",
    )


def _read_file(cfg: Config, reader, path: Path) -> list[Flight]:
    """The flights of one file, refused (one line) when its inputs never change: every
    reader gets the excitation check the generic reader has (a log flown with constant
    set-points identifies nothing about them)."""
    import numpy as np

    flights = reader(path, cfg.data)
    for f in flights:
        f.meta["file"] = str(path)
    inputs = np.vstack([f.inputs for f in flights]) if flights else np.zeros((0, 0))
    if inputs.size and float(np.max(np.ptp(inputs, axis=0))) == 0.0:
        names = list(flights[0].input_names)
        raise GpquadError(
            f"the inputs {names} never change in any in-flight segment: nothing "
            "to identify their effect from; check data.inputs or give a log "
            "flown with stick inputs",
            source=str(path),
            field="data.inputs",
        )
    return flights


def held_out_paths(cfg: Config) -> list[Path]:
    """Files held out whole for validation (`data.validation` as a list), resolved."""
    if isinstance(cfg.data.validation, str):
        return []
    return [(Path(cfg.base_dir) / f).resolve() for f in cfg.data.validation]


def load_flights(cfg: Config) -> list[Flight]:
    """Every in-flight segment of every configured file (or the simulator's flight), then
    those of the files held out for validation that `data.files` does not list."""
    if not cfg.data.files:
        from gpquad.data.simulator import simulate

        return [simulate(cfg.simulator, cfg.data.inputs)]
    reader = READERS.get(cfg.data.format)
    if reader is None:
        raise GpquadError(
            f"unknown format '{cfg.data.format}'; known: {sorted(READERS)}",
            source=str(cfg.data.files[0]),
            field="data.format",
        )
    paths = cfg.data_paths()
    paths += [p for p in held_out_paths(cfg) if p not in paths]
    flights: list[Flight] = []
    for path in paths:
        flights.extend(_read_file(cfg, reader, path))
    return flights


def load_dataset(cfg: Config) -> Dataset:
    """Flights of the config, screened by the integration check, concatenated and split.

    A segment that fails the integration check is dropped with a warning; the data is
    refused only when no segment passes.
    """
    flights = load_flights(cfg)
    source = str(cfg.data.files[0]) if cfg.data.files else None
    return dataset_of(flights, cfg, source)


def dataset_of(flights: list[Flight], cfg: Config, source: str | None) -> Dataset:
    """`flights` screened by the integration check (unless they are the simulator's:
    source None), concatenated and split as the config says."""
    check = None
    if source is not None and cfg.data.check_before_run:
        from gpquad.data.integration_check import screen_segments

        flights, dropped, check = screen_segments(
            flights,
            cfg.data.check_steps,
            cfg.data.check_max_rse,
            source=source,
            field="data.check_before_run",
        )
        for note in dropped:
            warnings.warn(note, stacklevel=2)
    held = {str(p) for p in held_out_paths(cfg)}
    if held and not any(f.meta.get("file") in held for f in flights):
        raise GpquadError(
            "no usable segment of the held-out files is left for validation",
            source=source,
            field="data.validation",
        )
    dataset = build_dataset(
        flights,
        validation_fraction=cfg.data.validation_fraction,
        trim=cfg.data.trim,
        trim_values=cfg.data.trim_values,
        held_out=[f.meta.get("file") in held for f in flights] if held else None,
    )
    if check is not None:
        dataset.integration_check = check.to_dict()
    return dataset


def resolve_log(path, fmt: str | None, config=None):
    """(path, config, data settings) for a command that reads one log (`data check`, `data
    export`): the format from --format, else the config's (unless it is the default
    "generic"), else the path; the settings are validated before any reading."""
    import dataclasses

    from gpquad.study.config import Config, load_config, validate

    path = Path(path)
    if not path.exists():
        raise GpquadError("no such file or folder", source=str(path))
    if not (path.is_file() or path.is_dir()):
        raise GpquadError(
            "not a regular file or folder (a pipe or a device); give the log file", source=str(path)
        )
    cfg = load_config(config) if config else Config()
    fmt = (
        fmt
        or (cfg.data.format if config and cfg.data.format != "generic" else None)
        or guess_format(path)
    )
    data = dataclasses.replace(cfg.data, format=fmt, files=(str(path),))
    validate(dataclasses.replace(cfg, data=data), "command line")
    return path, cfg, data


def read_log_file(path, data: DataConfig, fmt: str | None = None) -> list[Flight]:
    """The in-flight segments of one log, read with `data`'s pipeline settings; the format
    from `fmt`, else data.format unless it is the default "generic", else the path."""
    path = Path(path)
    if not path.exists():
        raise GpquadError("no such file or folder", source=str(path))
    fmt = fmt or (data.format if data.format != "generic" else None) or guess_format(path)
    reader = READERS.get(fmt)
    if reader is None:
        raise GpquadError(
            f"unknown format '{fmt}'; known: {sorted(READERS)}", source=str(path), field="format"
        )
    flights = reader(path, data)
    for f in flights:
        f.meta["file"] = str(path)
    return flights
