"""Baseline configs: frozen dataclasses read from TOML as strictly as gpquad.study.config.

Unknown keys and wrong types are one-line GpquadErrors naming the file and the field.
Sections are fields whose type is itself a dataclass.
"""

from __future__ import annotations

import dataclasses

from gpquad.errors import GpquadError
from gpquad.study.config_tables import build_dataclass, read_toml

__all__ = ["build", "read_toml", "require", "to_dict"]


#: The project's one TOML-to-dataclass builder (strict keys and types).
build = build_dataclass


def to_dict(cfg) -> dict:
    """JSON-ready dict of a config dataclass."""
    return dataclasses.asdict(cfg)


def require(cond: bool, message: str, source: str, field: str) -> None:
    if not cond:
        raise GpquadError(message, source=source, field=field)
