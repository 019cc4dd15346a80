"""Load the flights an experiment config names, whatever their format.

READERS maps a `data.format` name to a function (path, DataConfig) -> list[Flight]
(a log may hold several in-flight segments). With no files, the reference
simulator's flight is used.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from pathlib import Path

from gpquad.config import Config, DataConfig
from gpquad.data.dataset import Dataset, build_dataset
from gpquad.data.flight import Flight
from gpquad.errors import GpquadError


def _read_generic(path: Path, data: DataConfig) -> list[Flight]:
    """One flight per file; an export of `gpquad data export` gives one per segment."""
    from gpquad.data.export import read_generic

    return read_generic(path, data)


READERS: dict[str, Callable[[Path, DataConfig], list[Flight]]] = {"generic": _read_generic}


def register_reader(name: str, reader: Callable[[Path, DataConfig], list[Flight]]) -> None:
    """Make a log format available to `data.format`."""
    READERS[name] = reader


def _register_log_readers() -> None:
    """PX4 (ulog2csv folders, .ulg), Betaflight blackbox and resampled tables (gpquad.data)."""
    from gpquad.data.ardupilot import read_ardupilot
    from gpquad.data.betaflight import read_betaflight
    from gpquad.data.px4 import read_px4_csv
    from gpquad.data.table import read_table_log
    from gpquad.data.ulog import read_ulog

    for name, reader in (("px4-csv", read_px4_csv), ("ulog", read_ulog),
                         ("betaflight", read_betaflight), ("table", read_table_log),
                         ("ardupilot", read_ardupilot)):
        READERS.setdefault(name, reader)


_register_log_readers()


def _read_file(cfg: Config, reader, path: Path) -> list[Flight]:
    flights = reader(path, cfg.data)
    for f in flights:
        f.meta["file"] = str(path)
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
        from gpquad.simulator import simulate

        return [simulate(cfg.simulator, cfg.data.inputs)]
    reader = READERS.get(cfg.data.format)
    if reader is None:
        raise GpquadError(f"unknown format '{cfg.data.format}'; known: {sorted(READERS)}",
                          source=str(cfg.data.files[0]), field="data.format")
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
    check = None
    if cfg.data.files and cfg.data.check_before_run:
        from gpquad.data.integration_check import screen_segments

        flights, dropped, check = screen_segments(
            flights, cfg.data.check_steps, cfg.data.check_max_rse,
            source=str(cfg.data.files[0]), field="data.check_before_run")
        for note in dropped:
            warnings.warn(note, stacklevel=2)
    held = {str(p) for p in held_out_paths(cfg)}
    if held and not any(f.meta.get("file") in held for f in flights):
        raise GpquadError("no usable segment of the held-out files is left for validation",
                          source=str(cfg.data.files[0]), field="data.validation")
    dataset = build_dataset(flights, validation_fraction=cfg.data.validation_fraction,
                            trim=cfg.data.trim, trim_values=cfg.data.trim_values,
                            held_out=[f.meta.get("file") in held for f in flights]
                            if held else None)
    if check is not None:
        dataset.integration_check = check.to_dict()
    return dataset
