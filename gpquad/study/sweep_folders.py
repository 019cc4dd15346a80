"""The layout of a sweep folder: its grid of runs, their folders and the config fingerprint.

    DIR/sweep.json                      seed, config fingerprint, grid, provenance
    DIR/config.json                     the config
    DIR/runs/<target>/rep<k>/           one run: checkpoint.bin, history.csv,
                                        status.json (live), result.json (when finished)
    DIR/model.json, DIR/models/ ...     full models (gpquad.study.assemble)

Shared by the sweep (which writes the runs), the assembly (which reads them) and the live
progress (which polls them), so that none of them imports another.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

from gpquad.study.config import Config


@dataclass(frozen=True)
class RunKey:
    """One cell of the grid."""

    target: str
    repetition: int

    @property
    def name(self) -> str:
        return f"{self.target}/rep{self.repetition:03d}"


def grid(cfg: Config, runs: int | None = None) -> list[RunKey]:
    """Every (target, repetition), target-major."""
    n = cfg.sweep.runs if runs is None else runs
    return [RunKey(t, k) for t in cfg.evolution.targets for k in range(n)]


def run_dir(out: Path, key: RunKey) -> Path:
    return Path(out) / "runs" / key.target / f"rep{key.repetition:03d}"


def fingerprint(cfg: Config) -> str:
    """Hash of everything a run's result depends on (seed, data, simulator, evolution)."""
    d = cfg.to_dict()
    relevant = {k: d[k] for k in ("seed", "data", "simulator", "evolution")}
    relevant["data_paths"] = [str(p) for p in cfg.data_paths()]
    relevant["evolution"].pop("targets")  # adding targets to a sweep keeps earlier runs valid
    blob = json.dumps(relevant, sort_keys=True, default=str).encode()
    return hashlib.sha256(blob).hexdigest()[:16]
