"""Baseline configs: frozen dataclasses read from TOML as strictly as gpquad.config.

Unknown keys and wrong types are one-line GpquadErrors naming the file and the field.
Sections are fields whose type is itself a dataclass.
"""

from __future__ import annotations

import dataclasses
import sys
import typing
from pathlib import Path

from gpquad.config import _coerce
from gpquad.errors import GpquadError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


def build(cls, table: dict, source: str, prefix: str = ""):
    """Instantiate dataclass `cls` from a TOML table, checking keys and types."""
    hints = typing.get_type_hints(cls)
    names = [f.name for f in dataclasses.fields(cls)]
    kwargs = {}
    for key, value in table.items():
        where = f"{prefix}{key}"
        if key not in names:
            raise GpquadError(f"unknown key; allowed keys here are {names}", source=source,
                              field=where)
        tp = hints[key]
        if dataclasses.is_dataclass(tp):
            if not isinstance(value, dict):
                raise GpquadError("expected a [section] table", source=source, field=where)
            kwargs[key] = build(tp, value, source, f"{where}.")
        else:
            kwargs[key] = _coerce(value, tp, source, where)
    return cls(**kwargs)


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
