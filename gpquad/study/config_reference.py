"""The configuration reference (docs/configuration.md), generated from the config dataclasses:
every key with its default, its value in the paper preset where that differs, and the comment
the source gives it. A test keeps the page equal to what this module writes."""

from __future__ import annotations

import ast
import dataclasses
import inspect

from gpquad.study import config as config_module
from gpquad.study.config import Config, config_from_dict

#: The sections, in page order: (TOML table, dataclass).
SECTIONS = (
    ("", Config),
    ("data", config_module.DataConfig),
    ("vehicle", config_module.VehicleConfig),
    ("evolution", config_module.EvolutionConfig),
    ("evolution.gp", config_module.GPConfig),
    ("simulator", config_module.SimulatorConfig),
    ("sweep", config_module.SweepConfig),
    ("output", config_module.OutputConfig),
)


def field_comments(cls) -> dict[str, str]:
    """{field: its comment}: the comment on the field's line, else the comment lines just
    above it."""
    source = inspect.getsource(config_module)
    lines = source.splitlines()
    tree = ast.parse(source)
    node = next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == cls.__name__)
    out = {}
    for item in node.body:
        if not isinstance(item, ast.AnnAssign):
            continue
        if not isinstance(item.target, ast.Name):
            continue
        name = item.target.id
        line = lines[(item.end_lineno or item.lineno) - 1]
        if "#" in line.split("=", 1)[-1]:
            out[name] = line.split("#", 1)[1].strip()
            continue
        above: list[str] = []
        k = item.lineno - 2
        while k >= 0 and lines[k].strip().startswith("#"):
            above.insert(0, lines[k].strip().lstrip("#").strip())
            k -= 1
        out[name] = " ".join(above)
    return out


def _value(v) -> str:
    if isinstance(v, tuple):
        v = list(v)
    if isinstance(v, str):
        return f'"{v}"'
    if isinstance(v, bool):
        return str(v).lower()
    return str(v).replace("'", '"')


def _get(cfg, section: str):
    obj = cfg
    for part in filter(None, section.split(".")):
        obj = getattr(obj, part)
    return obj


def markdown() -> str:
    """The page."""
    default, paper = Config(), config_from_dict({"preset": "paper"})
    out = [
        "# Configuration reference",
        "",
        "Every key of a config file (TOML), its default, and its value under "
        '`preset = "paper"` where that differs (the paper\'s method, '
        "`gpquad.study.presets`). A config sets only what differs from the defaults; "
        "`gpquad.fit(..., key=value)` takes the [evolution], [data] and [vehicle] keys by "
        "name. Keys of older versions are migrated with a note or refused in one line "
        "(`gpquad.study.config_migrate`). This page is generated from "
        "`gpquad/study/config.py` (`gpquad.study.config_reference`).",
        "",
    ]
    for section, cls in SECTIONS:
        comments = field_comments(cls)
        out += [
            f"## [{section}]" if section else "## Top level",
            "",
            "| key | default | paper | meaning |",
            "|---|---|---|---|",
        ]
        for f in dataclasses.fields(cls):
            if (
                not f.metadata.get("toml", True)
                or dataclasses.is_dataclass(f.type)
                or f.name in ("data", "simulator", "vehicle", "evolution", "output", "sweep", "gp")
            ):
                continue
            d = getattr(_get(default, section), f.name)
            p = getattr(_get(paper, section), f.name)
            shown = "" if p == d else f"`{_value(p)}`"
            meaning = comments.get(f.name, "").replace("|", "\\|")
            out.append(f"| `{f.name}` | `{_value(d)}` | {shown} | {meaning} |")
        out.append("")
    return "\n".join(out)
