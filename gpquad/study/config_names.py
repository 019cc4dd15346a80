"""Config checks of seeds, names and lists whose mistakes would otherwise pass silently:
a seed numpy cannot take, a target or flight given twice, an input named like a sympy
constant or function (model.json's equations are sympy-parsable strings)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from gpquad.errors import GpquadError

if TYPE_CHECKING:
    from gpquad.study.config import Config


def validate_names(cfg: Config, source: str) -> None:
    """Seeds, names and lists whose mistakes would otherwise pass silently."""
    if not 0 <= cfg.seed < 2**63:
        raise GpquadError(
            f"seed {cfg.seed} is out of range; give an integer in [0, 2^63)",
            source=source,
            field="seed",
        )
    targets = cfg.evolution.targets
    if len(set(targets)) != len(targets):
        raise GpquadError(
            f"a target is listed twice in {list(targets)}; give each once",
            source=source,
            field="evolution.targets",
        )
    files = [str(Path(cfg.base_dir, f).resolve()) for f in cfg.data.files]
    twice = sorted({f for f in files if files.count(f) > 1})
    if twice:
        raise GpquadError(
            f"{twice[0]} is given twice; give each flight once", source=source, field="data.files"
        )
    for name in cfg.data.inputs if not isinstance(cfg.data.inputs, str) else ():
        reason = reserved_name(name)
        if reason:
            raise GpquadError(
                f"input name '{name}' {reason}; rename it (e.g. 'u_{name}') with [data.columns]",
                source=source,
                field="data.inputs",
            )


def reserved_name(name: str) -> str | None:
    """Why `name` cannot name a variable of an exported equation, or None if it can.

    model.json stores sympy-parsable strings: a name that sympy reads as a constant or a
    function (E, I, N, S, pi, beta, ...) or a Python keyword (lambda) would change their meaning.
    """
    import keyword

    import sympy

    if not name.isidentifier():
        return "is not an identifier (letters, digits and _)"
    if keyword.iskeyword(name):
        return "is a Python keyword"
    if hasattr(sympy, name) or name in ("oo", "zoo", "nan"):
        return "is a sympy name (a constant or function when the equations are read back)"
    return None
