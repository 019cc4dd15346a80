"""The Python API: read a log, fit a model, load a run folder.

    >>> import gpquad
    >>> flights = gpquad.read_log("flight.ulg")              # doctest: +SKIP
    >>> model = gpquad.fit(flights, seed=1)                  # doctest: +SKIP
    >>> print(model)                                         # doctest: +SKIP

Every fit goes through the one fit path of `gpquad run` (gpquad.study.fit).
"""

from __future__ import annotations

import dataclasses
import difflib
from collections.abc import Sequence
from pathlib import Path

import pandas as pd

from gpquad.data.flight import Flight, flights_of
from gpquad.errors import GpquadError
from gpquad.model import Model
from gpquad.study.config import (
    Config,
    DataConfig,
    EvolutionConfig,
    VehicleConfig,
    config_from_dict,
    load_config,
)
from gpquad.study.presets import PRESETS

#: Config sections an override of gpquad.fit may name a field of, in the order searched.
_SECTIONS = (("evolution", EvolutionConfig), ("data", DataConfig), ("vehicle", VehicleConfig))


def _config(config) -> Config:
    """A Config from None (the defaults), a preset name, a TOML path or a Config."""
    if config is None:
        return Config()
    if isinstance(config, Config):
        return config
    if isinstance(config, str) and config in PRESETS:
        return config_from_dict({"preset": config}, f"preset {config}")
    if isinstance(config, (str, Path)):
        return load_config(config)
    raise GpquadError(
        f"config must be None, a preset name {sorted(PRESETS)}, a TOML path or a "
        f"gpquad Config, got {type(config).__name__}",
        field="config",
    )


def _with_overrides(cfg: Config, seed: int | None, overrides: dict) -> Config:
    """cfg with `seed` and field overrides (targets=["p_dot"], iterations=2, trim="mean"),
    each placed in the section that has the field, validated like a config file."""
    table = cfg.to_dict()
    if seed is not None:
        table["seed"] = seed
    for key, value in overrides.items():
        section = next(
            (name for name, cls in _SECTIONS if key in {f.name for f in dataclasses.fields(cls)}),
            None,
        )
        if section is None:
            known = [f.name for _, cls in _SECTIONS for f in dataclasses.fields(cls)]
            close = difflib.get_close_matches(key, known, n=1)
            hint = f"; did you mean '{close[0]}'?" if close else ""
            raise GpquadError(f"unknown setting '{key}'{hint}", field=key)
        table[section][key] = list(value) if isinstance(value, tuple) else value
    return config_from_dict(table, "gpquad.fit", cfg.base_dir)


def read_log(path, *, format: str | None = None, config=None, **data) -> list[Flight]:
    """Read a flight log into in-flight segments, through gpquad's log pipeline.

    Parameters
    ----------
    path : str or Path
        A PX4 ULog (.ulg) or ulog2csv folder, a Betaflight blackbox log (.bbl, .bfl, .txt),
        an ArduPilot DataFlash log (.bin), or a CSV/Parquet table.
    format : str, optional
        The log format ("ulog", "px4-csv", "betaflight", "ardupilot", "table", "generic");
        default: from the path.
    config : Config, str or Path, optional
        A config whose [data] table sets the pipeline (default: gpquad's defaults).
    **data
        [data] fields to override, e.g. ``inputs="rates"``, ``segment="armed"``.

    Returns
    -------
    list of Flight
        One per in-flight segment, NED/FRD, uniformly sampled.
    """
    from gpquad.data.io import guess_format, read_log_file

    cfg = _config(config)
    path = Path(path)
    if not path.exists():
        raise GpquadError("no such file or folder", source=str(path))
    fmt = (
        format or (cfg.data.format if cfg.data.format != "generic" else None) or guess_format(path)
    )
    cfg = _with_overrides(cfg, None, {**data, "format": fmt, "files": [str(path.resolve())]})
    return read_log_file(path, cfg.data, fmt)


def _flights_and_config(data, cfg: Config):
    """(flights or None, config, source): DataFrames and Flights as flights; log paths go
    into the config's data.files (read by the fit, as `gpquad run` reads them)."""
    items = list(data) if isinstance(data, (list, tuple)) else [data]
    if not items:
        raise GpquadError("no flight data given", field="data")
    if all(isinstance(d, (str, Path)) for d in items):
        from gpquad.data.io import guess_format

        paths = [str(Path(d).resolve()) for d in items]
        fmt = cfg.data.format if cfg.data.format != "generic" else guess_format(Path(paths[0]))
        return None, _with_overrides(cfg, None, {"files": paths, "format": fmt}), paths[0]
    inputs = cfg.data.inputs
    if isinstance(inputs, str):
        raise GpquadError(
            f"input level '{inputs}' is for log readers; a DataFrame needs a "
            "list of input column names: inputs=[...]",
            field="inputs",
        )
    flights = flights_of(items, inputs, cfg.data.frame, cfg.data.columns)
    return flights, cfg, "DataFrame"


def fit(
    data,
    config=None,
    *,
    seed: int | None = None,
    run_dir=None,
    progress: bool = False,
    jobs: int | None = None,
    **overrides,
) -> Model:
    """Discover one equation per body-frame acceleration from flight data.

    Parameters
    ----------
    data : DataFrame, Flight, str or Path, or a list of them
        Flights. A DataFrame has the generic columns: ``t`` (s), ``qw, qx, qy, qz``
        (body-to-world quaternion), ``u, v, w`` (body velocity, m/s) or ``vx, vy, vz``
        (world velocity), ``p, q, r`` (body rates, rad/s) and one column per input
        (default ``u_P, u_R, u_Y, u_T``; others with ``inputs=[...]``), NED/FRD unless
        ``frame="ENU/FLU"``. Paths are logs (see `read_log`).
    config : Config, str or Path, optional
        None for the defaults (the recommended engine), a preset name ("recommended",
        "paper"), a TOML file, or a Config.
    seed : int, optional
        The master seed (default: the config's). Same data, config and seed give the same
        equations, bit for bit.
    run_dir : str or Path, optional
        Write a run folder there (as `gpquad run` does); default: write nothing.
    progress : bool
        Print a progress line per iteration and step.
    jobs : int, optional
        Cores to use (default: every core this process may use). The equations are
        searched in up to this many processes, one per equation; a search with cores to
        spare (the last one running, or the only one) fits its final choice's candidates
        in threads on them, and the finishing steps use `jobs` threads. The equations are
        the same for any value. A fit into a `run_dir` searches in this process (its
        threads on every core) and checkpoints every iteration, unless `jobs` is given
        (then in worker processes, and only whole equations are checkpointed).
    **overrides
        Config fields by name, in [evolution], [data] or [vehicle]: ``targets=["p_dot"]``,
        ``iterations=2``, ``input_taps=1``, ``trim="mean"``, ``inputs=[...]``.

    Returns
    -------
    Model
        The equations, ready to print, score, simulate, fly and export.

    Raises
    ------
    GpquadError
        Bad data or settings, in one line naming the field, before any long work.
    """
    from gpquad._machine import warn_if_late
    from gpquad.data.io import dataset_of, load_dataset
    from gpquad.study.fit import fit_dataset
    from gpquad.study.runner import run_experiment
    from gpquad.study.search import Progress
    from gpquad.study.workers import default_jobs

    cfg = _with_overrides(_config(config), seed, overrides)
    warn_if_late()
    flights, cfg, source = _flights_and_config(data, cfg)
    dataset = load_dataset(cfg) if flights is None else dataset_of(flights, cfg, source)
    profile: dict = {}  # where the fit's time went (Model.profile)
    if run_dir is not None:
        if jobs is not None and jobs < 1:
            raise GpquadError(f"jobs must be >= 1, got {jobs}", field="jobs")
        found = run_experiment(
            cfg,
            run_dir,
            progress=progress,
            dataset=dataset,
            jobs=default_jobs() if jobs is None else jobs,
            seconds=profile,
            in_process=jobs is None,  # every iteration checkpointed
        )
    else:
        ev = cfg.evolution
        if jobs is not None and jobs < 1:
            raise GpquadError(f"jobs must be >= 1, got {jobs}", field="jobs")
        found = fit_dataset(
            dataset,
            cfg,
            Progress(progress, ev.iterations * len(ev.targets)),
            jobs=default_jobs() if jobs is None else jobs,
            seconds=profile,
        )
    return Model(found, cfg, profile)


def reference_flight(
    *, seed: int = 0, duration_s: float = 552.0, config=None, **simulator
) -> pd.DataFrame:
    """A flight of gpquad's reference simulator as a DataFrame of the generic columns.

    The simulator flies a known model (default: the dominant terms of the paper's median
    model, Table 1) at 25 Hz under a pilot-like stick signal, so that a fit can be checked
    against the truth.

    Parameters
    ----------
    seed : int
        The simulator's seed (stick signal, noise).
    duration_s : float
        Length of the flight (s).
    config : Config, str or Path, optional
        A config whose [simulator] table is used (default: gpquad's).
    **simulator
        [simulator] fields to override, e.g. ``equations={...}``,
        ``measurement_noise={"rates": 0.01}``.
    """
    from gpquad.data.simulator import simulate

    cfg = _config(config)
    table = cfg.to_dict()
    table["simulator"].update(seed=seed, duration_s=duration_s, **simulator)
    cfg = config_from_dict(table, "gpquad.reference_flight", cfg.base_dir)
    if isinstance(cfg.data.inputs, str):
        raise GpquadError("the simulator needs a list of input names", field="inputs")
    return simulate(cfg.simulator, cfg.data.inputs).to_frame()


def load(run_dir) -> Model:
    """The model of a run folder written by `gpquad run`, `gpquad sweep` or `fit(run_dir=)`.

    Parameters
    ----------
    run_dir : str or Path
        The folder (or its model.json).
    """
    from gpquad.models.equations import DiscoveredModel

    return Model(DiscoveredModel.load(run_dir))


__all__: Sequence[str] = ("fit", "load", "read_log", "reference_flight")
