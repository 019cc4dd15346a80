"""Load the flights an experiment config names, whatever their format.

READERS maps a `data.format` name to a function (path, DataConfig) -> list[Flight]
(a log may hold several in-flight segments). With no files, the reference
simulator's flight is used.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from gpquad.config import Config, DataConfig
from gpquad.data.dataset import Dataset, build_dataset
from gpquad.data.flight import Flight, read_flight_file
from gpquad.errors import GpquadError


def _read_generic(path: Path, data: DataConfig) -> list[Flight]:
    return [read_flight_file(path, data.inputs, data.frame, data.columns)]


READERS: dict[str, Callable[[Path, DataConfig], list[Flight]]] = {"generic": _read_generic}


def register_reader(name: str, reader: Callable[[Path, DataConfig], list[Flight]]) -> None:
    """Make a log format available to `data.format`."""
    READERS[name] = reader


def _register_log_readers() -> None:
    """PX4 (ulog2csv folders, .ulg), Betaflight blackbox and resampled tables (gpquad.data)."""
    from gpquad.data.betaflight import read_betaflight
    from gpquad.data.px4 import read_px4_csv
    from gpquad.data.table import read_table_log
    from gpquad.data.ulog import read_ulog

    for name, reader in (("px4-csv", read_px4_csv), ("ulog", read_ulog),
                         ("betaflight", read_betaflight), ("table", read_table_log)):
        READERS.setdefault(name, reader)


_register_log_readers()


def load_flights(cfg: Config) -> list[Flight]:
    """Every in-flight segment of every configured file (or the simulator's flight)."""
    if not cfg.data.files:
        from gpquad.simulator import simulate

        return [simulate(cfg.simulator, cfg.data.inputs)]
    reader = READERS.get(cfg.data.format)
    if reader is None:
        raise GpquadError(f"unknown format '{cfg.data.format}'; known: {sorted(READERS)}",
                          source=str(cfg.data.files[0]), field="data.format")
    flights: list[Flight] = []
    for path in cfg.data_paths():
        flights.extend(reader(path, cfg.data))
    return flights


def load_dataset(cfg: Config) -> Dataset:
    """Flights of the config, concatenated and split as the engine needs them."""
    flights = load_flights(cfg)
    check = None
    if cfg.data.files and cfg.data.check_before_run:
        from gpquad.data.integration_check import integration_check

        check = integration_check(flights, cfg.data.check_steps, cfg.data.check_max_rse)
        if not check.passed:
            raise GpquadError(f"{check.failure()}; run `gpquad data check` for the table, or set "
                              "data.check_before_run = false", source=str(cfg.data.files[0]),
                              field="data.check_before_run")
    dataset = build_dataset(flights, validation_fraction=cfg.data.validation_fraction,
                            trim=cfg.data.trim, trim_values=cfg.data.trim_values)
    if check is not None:
        dataset.integration_check = check.to_dict()
    return dataset
