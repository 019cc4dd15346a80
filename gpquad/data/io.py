"""Load the flights an experiment config names, whatever their format.

READERS maps a `data.format` name to a function (path, DataConfig) -> list[Flight]
(a log may hold several in-flight segments). With no files, the reference
simulator's flight is used.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

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


def load_flights(cfg: Config) -> list[Flight]:
    """Every in-flight segment of every configured file (or the simulator's flight)."""
    if not cfg.data.files:
        from gpquad.simulator import simulate

        return [simulate(cfg.simulator, cfg.data.inputs)]
    reader = READERS.get(cfg.data.format)
    if reader is None:
        raise GpquadError(f"unknown format '{cfg.data.format}'; known: {sorted(READERS)}",
                          field="data.format")
    flights: list[Flight] = []
    for path in cfg.data_paths():
        flights.extend(reader(path, cfg.data))
    return flights


def load_dataset(cfg: Config) -> Dataset:
    """Flights of the config, concatenated and split as the engine needs them."""
    return build_dataset(load_flights(cfg), validation_fraction=cfg.data.validation_fraction,
                         trim=cfg.data.trim, trim_values=cfg.data.trim_values)
