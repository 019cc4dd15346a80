"""Run folders of the physics commands: run.json (seed, config, versions, git revision, wall
time), a JSON result, a Markdown table, figures. The JSON result holds no timings."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from gpquad.study.store import (
    atomic_write_text,
    checked_name,
    package_versions,
    provenance,
    write_json,
)

EXTRA_PACKAGES = ("orangebox", "statsmodels", "rotorpy")


def default_out(kind: str, name: str) -> Path:
    return Path("results") / f"physics-{kind}-{checked_name(name)}-{time.strftime('%Y%m%d-%H%M%S')}"


def _plain(obj):
    """JSON-safe copy: numpy scalars and arrays to Python, private keys dropped."""
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items() if not str(k).startswith("_")}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _plain(obj.tolist())
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    return obj


def versions() -> dict:
    from importlib import metadata

    out = package_versions()
    for name in EXTRA_PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


def write_run(
    out: Path,
    kind: str,
    result: dict,
    markdown: str,
    *,
    config: dict | None,
    seed: int | None,
    started: float,
) -> Path:
    """Write result.json, result.md and run.json into `out`; return `out`."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / f"{kind}.json", _plain(result))
    atomic_write_text(out / f"{kind}.md", markdown)
    prov = provenance()
    prov["versions"] = versions()
    write_json(
        out / "run.json",
        _plain(
            {
                "command": f"physics {kind}",
                "seed": seed,
                "config": config,
                **prov,
                "wall_time_s": time.time() - started,
            }
        ),
    )
    return out


def plain(obj):
    return _plain(obj)
