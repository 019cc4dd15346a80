"""TOML tables to frozen dataclasses: types checked, unknown keys refused, one-line errors
naming the file and the dotted field (used by every config of gpquad)."""

from __future__ import annotations

import dataclasses
import sys
import types
import typing
from pathlib import Path

from gpquad.errors import GpquadError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


def read_toml(path) -> tuple[dict, str]:
    """(table, source) of a TOML file, with one-line errors for missing or invalid files."""
    path = Path(path)
    if not path.is_file():
        raise GpquadError("config file not found", source=str(path))
    try:
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as exc:
        raise GpquadError(
            f"not UTF-8 text (byte {exc.start + 1} is 0x{exc.object[exc.start]:02x});"
            " a TOML file is UTF-8: save it as UTF-8",
            source=str(path),
        ) from None
    except OSError as exc:
        raise GpquadError(f"cannot read ({exc.strerror})", source=str(path)) from None
    try:
        return tomllib.loads(text), str(path)
    except tomllib.TOMLDecodeError as exc:
        raise GpquadError(f"not valid TOML ({exc})", source=str(path)) from None


def _type_name(tp) -> str:
    return getattr(tp, "__name__", str(tp)).replace("typing.", "")


def _coerce(value, tp, source: str, where: str):
    """Check `value` against the annotation `tp`; return it in the dataclass's form."""
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)

    def bad():
        return GpquadError(
            f"expected {_type_name(tp)}, got {type(value).__name__} {value!r}",
            source=source,
            field=where,
        )

    if origin in (typing.Union, types.UnionType):
        for arg in args:
            try:
                return _coerce(value, arg, source, where)
            except GpquadError:
                continue
        raise bad()
    if tp is type(None):
        if value is None:
            return None
        raise bad()
    if tp is bool:
        if isinstance(value, bool):
            return value
        raise bad()
    if tp is int:
        if isinstance(value, int) and not isinstance(value, bool):
            return value
        raise bad()
    if tp is float:
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return float(value)
        raise bad()
    if tp is str:
        if isinstance(value, str):
            return value
        raise bad()
    if origin is tuple:
        if not isinstance(value, (list, tuple)):
            raise bad()
        return tuple(_coerce(v, args[0], source, f"{where}[{i}]") for i, v in enumerate(value))
    if origin is dict:
        if not isinstance(value, dict):
            raise bad()
        return {str(k): _coerce(v, args[1], source, f"{where}.{k}") for k, v in value.items()}
    raise bad()  # pragma: no cover


def build_dataclass(cls, table: dict, source: str, prefix: str = ""):
    """Instantiate dataclass `cls` from a TOML table; nested dataclass fields are [sections].

    Unknown keys and wrong types raise GpquadError naming `source` and the dotted field.
    Fields with metadata {"toml": False} cannot be set from TOML.
    """
    hints = typing.get_type_hints(cls)
    names = [f.name for f in dataclasses.fields(cls) if f.metadata.get("toml", True)]
    kwargs = {}
    for key, value in table.items():
        where = f"{prefix}{key}"
        if key not in names:
            import difflib

            close = difflib.get_close_matches(key, names, n=1)
            hint = f"did you mean '{close[0]}'? " if close else ""
            raise GpquadError(
                f"unknown key; {hint}allowed keys here are {names}", source=source, field=where
            )
        tp = hints[key]
        if dataclasses.is_dataclass(tp):
            if not isinstance(value, dict):
                raise GpquadError("expected a [section] table", source=source, field=where)
            kwargs[key] = build_dataclass(tp, value, source, f"{where}.")
        else:
            kwargs[key] = _coerce(value, tp, source, where)
    return cls(**kwargs)
