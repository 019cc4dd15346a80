"""Baseline run folders: the same layout as GP runs (model.json, run.json, config.json).

model.json: {"kind": "baseline", "method", "model", "parameters", "equations" (sympy
strings with the fitted values), plus what is needed to fly the model}; no timings, so
the same config and seed give the same file. run.json: provenance, results, timings and
"scoring_data" (flight files of the folder that `gpquad compare` scores on).
"""

from __future__ import annotations

import time
from pathlib import Path

from gpquad.data.flight import Flight, write_flight_file
from gpquad.study.store import provenance, write_json


def write_flights(run_dir: Path, flights: list[Flight], validation_fraction: float) -> dict:
    """Write scoring flights as Parquet under flights/; returns run.json's scoring_data."""
    files = []
    for f in flights:
        rel = Path("flights") / f"{f.name}.parquet"
        write_flight_file(f, run_dir / rel)
        files.append(str(rel))
    return {
        "files": files,
        "inputs": list(flights[0].input_names),
        "validation_fraction": validation_fraction,
    }


def write_run(run_dir: Path, model: dict, config: dict, results: dict, started: float) -> None:
    """Write model.json, config.json and run.json (with provenance) atomically."""
    run_dir.mkdir(parents=True, exist_ok=True)
    write_json(run_dir / "model.json", {"kind": "baseline", **model})
    write_json(run_dir / "config.json", config)
    info = {
        "seed": config.get("seed"),
        "config": config,
        **results,
        "started": time.strftime("%Y-%m-%dT%H:%M:%S%z", time.localtime(started)),
        "finished": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "wall_time_s": time.time() - started,
        **provenance(),
    }
    write_json(run_dir / "run.json", info)
