"""Baseline configs: frozen dataclasses read from TOML as strictly as gpquad.study.config.

Unknown keys and wrong types are one-line GpquadErrors naming the file and the field.
Sections are fields whose type is itself a dataclass.
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

from gpquad.errors import GpquadError
from gpquad.study.config_tables import build_dataclass

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


#: The project's one TOML-to-dataclass builder (strict keys and types).
build = build_dataclass


def read_toml(path) -> tuple[dict, str]:
    """(table, source) of a TOML file, with one-line errors for missing or invalid files."""
    path = Path(path)
    if not path.is_file():
        raise GpquadError("config file not found", source=str(path))
    try:
        return tomllib.loads(path.read_text()), str(path)
    except tomllib.TOMLDecodeError as exc:
        raise GpquadError(f"not valid TOML ({exc})", source=str(path)) from None


def to_dict(cfg) -> dict:
    """JSON-ready dict of a config dataclass."""
    return dataclasses.asdict(cfg)


def require(cond: bool, message: str, source: str, field: str) -> None:
    if not cond:
        raise GpquadError(message, source=source, field=field)
