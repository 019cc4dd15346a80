"""gpquad as a benchmark method: its engine settings and one fit per seed.

The engine settings come from ONE place: the [evolution] table of
`experiments/recommended.toml` when that file exists, else `experiments/quickstart.toml`.
Which file was used is recorded with every result.
"""

from __future__ import annotations

import sys
from pathlib import Path

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

from gpquad.errors import GpquadError
from gpquad.study.config import Config, config_from_dict

ENGINE_FILES = ("recommended.toml", "quickstart.toml")


def engine_source(experiments_dir: Path) -> Path:
    """The config file whose [evolution] table sets gpquad's benchmark settings."""
    for name in ENGINE_FILES:
        path = Path(experiments_dir) / name
        if path.is_file():
            return path
    raise GpquadError(f"neither of {list(ENGINE_FILES)} exists; the benchmark takes gpquad's "
                      "settings from one of them", source=str(experiments_dir))


def engine_config(experiments_dir: Path, seed: int) -> tuple[Config, str]:
    """Config with the engine file's [evolution] table and the given seed; and its path."""
    path = engine_source(experiments_dir)
    try:
        table = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise GpquadError(f"not valid TOML ({exc})", source=str(path)) from None
    evolution = dict(table.get("evolution", {}))
    evolution.pop("targets", None)  # the benchmark identifies all six equations
    cfg = config_from_dict({"seed": int(seed), "name": "benchmark", "evolution": evolution},
                           str(path))
    return cfg, str(path)


def fit_gpquad(dataset, cfg: Config):
    """Identify the six equations on the training ranges of `dataset`: a DiscoveredModel."""
    from gpquad.engine.variables import TARGET_NAMES
    from gpquad.models.equations import DiscoveredModel
    from gpquad.models.finish import finish_model
    from gpquad.study.runner import identify

    equations = {t: identify(dataset, t, cfg)[0] for t in TARGET_NAMES}
    model = DiscoveredModel(equations, dataset.input_names, dataset.trim, dataset.dt, cfg.seed,
                            cfg.to_dict())
    return finish_model(model, dataset, cfg.evolution)
