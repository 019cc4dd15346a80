"""gpquad as a benchmark method: the package's default engine (the recommended one, defined
in gpquad.study.config, not read from any file) and one fit per seed through the one fit
path (gpquad.study.fit), all six equations."""

from __future__ import annotations

import dataclasses

from gpquad.engine.variables import TARGET_NAMES
from gpquad.study.config import Config

#: Where the benchmark's gpquad settings come from, recorded with every result.
ENGINE_SOURCE = "gpquad.study.config defaults (the recommended engine)"


def engine_config(seed: int, base: Config | None = None) -> Config:
    """The engine's config with the given seed: `base`'s [evolution] and [vehicle] (default:
    the package defaults), every target identified."""
    base = Config() if base is None else base
    evolution = dataclasses.replace(base.evolution, targets=TARGET_NAMES)
    return dataclasses.replace(base, seed=int(seed), name="benchmark", evolution=evolution)


def load_engine(path=None) -> tuple[Config, str]:
    """(config, where it came from): the package defaults, or the [evolution] and [vehicle]
    of the TOML file at `path` (`gpquad benchmark --engine`)."""
    if path is None:
        return Config(), ENGINE_SOURCE
    from gpquad.study.config import load_config

    return load_config(path, quiet=True), str(path)


def fit_gpquad(dataset, cfg: Config, jobs: int = 1, seconds: dict | None = None):
    """Identify the six equations on the training ranges of `dataset`: a DiscoveredModel
    (on `jobs` cores, gpquad.study.workers; the same equations for any value); `seconds`
    receives the fit's profile (gpquad.study.fit.fit_dataset)."""
    from gpquad.study.fit import fit_dataset

    return fit_dataset(dataset, cfg, jobs=jobs, seconds=seconds)
