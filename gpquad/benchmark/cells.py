"""One benchmark cell: fit a method on a scenario with a seed, fly and score it, save it.

A cell's result is written atomically to `cells/<scenario>/<method>/seed<k>.json` when
it is done; a cell whose file exists is finished and is never recomputed (resume).
Timings and memory are kept under "cost" so that the compared content excludes them.
"""

from __future__ import annotations

import hashlib
import json
import threading
import time
from pathlib import Path

import numpy as np

from gpquad.benchmark import evaluate, peers
from gpquad.benchmark.rollout import fly
from gpquad.engine.variables import TARGET_NAMES
from gpquad.study.store import write_json


def settings_fingerprint(settings) -> str:
    """16 hex digits of the SHA-256 of `settings` as sorted JSON (a cell's settings, a
    cell's equations)."""
    return hashlib.sha256(json.dumps(settings, sort_keys=True).encode()).hexdigest()[:16]


METHODS = ("gpquad",) + peers.PEERS


def cell_path(out: Path, scenario: str, method: str, seed: int) -> Path:
    return Path(out) / "cells" / scenario / method / f"seed{seed}.json"


def load_cell(path: Path, fingerprint: str | None = None) -> dict | None:
    """A finished cell, or None (missing, damaged, or made with other method settings than
    `fingerprint`: it is recomputed)."""
    try:
        cell = json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(cell, dict) or (
        fingerprint is not None and cell.get("fingerprint") != fingerprint
    ):
        return None
    return cell


def recovery_gpquad(model, scenario) -> dict | None:
    if not scenario.truth:
        return None
    from gpquad.models.analysis import compare_to_truth

    out = {}
    for target in TARGET_NAMES:
        if target in scenario.truth and target in model.equations:
            with np.errstate(all="ignore"):  # protected division evaluated by numpy
                found = compare_to_truth(
                    model.equations[target], scenario.truth[target], scenario.fit
                )
            out[target] = bool(found["passed"])
    return out


def _fit(method: str, scenario, seed: int, engine, fit_jobs: int = 1):
    """(simulate(starts, steps) on the test data, fit time, record) of a fitted method;
    a scenario with groups is fitted per group, and each window flies its group's model."""
    if not scenario.groups:
        return _fit_one(method, scenario, seed, engine, fit_jobs)
    fitted = {
        g: _fit_one(method, sub, seed, engine, fit_jobs) for g, sub in scenario.groups.items()
    }
    simulate = grouped_simulate(scenario, {g: f[0] for g, f in fitted.items()})
    keys = (
        "equations",
        "equations_raw_inputs",
        "n_parameters",
        "joint_fit",
        "scheme",
        "fit_profile_s",
    )
    record = {
        k: {g: f[2][k] for g, f in fitted.items()}
        for k in keys
        if k in next(iter(fitted.values()))[2]
    }
    record["settings"] = next(iter(fitted.values()))[2]["settings"]
    record["recovery"] = None
    record["fitted_per"] = list(scenario.groups)
    return simulate, sum(f[1] for f in fitted.values()), record


def grouped_simulate(scenario, simulators: dict):
    """simulate(starts, steps) on scenario.test of per-group simulators, each flying the
    windows of its group's test flights (their starts in the group's own test data)."""
    offsets = scenario.group_offsets()

    def simulate(starts, steps):
        starts = np.asarray(starts, dtype=np.int64)
        out = np.empty((len(starts), steps + 1, 9))
        for g, (a, b) in offsets.items():
            mask = (starts >= a) & (starts < b)
            if mask.any():
                out[mask] = simulators[g](starts[mask] - a, steps)
        return out

    return simulate


def _fit_one(method: str, scenario, seed: int, engine, fit_jobs: int = 1):
    test = scenario.test
    if method == "gpquad":
        from gpquad.benchmark.engine import engine_config, fit_gpquad

        cfg = engine_config(seed, engine)
        t0 = time.perf_counter()
        profile: dict = {}
        model = fit_gpquad(scenario.fit, cfg, fit_jobs, profile)
        fit_time = time.perf_counter() - t0
        record = {
            "equations": {t: e.text() for t, e in model.equations.items()},
            "equations_raw_inputs": {t: e.text(raw=True) for t, e in model.equations.items()},
            "settings": {
                "evolution": cfg.to_dict()["evolution"],
                "vehicle": cfg.to_dict()["vehicle"],
            },
            # the finished model's own scheme: a stiff loop raises its steps per sample
            "scheme": {"integrator": model.integrator, "substeps": model.substeps},
            "recovery": recovery_gpquad(model, scenario),
            "joint_fit": model.joint_fit,
            "n_parameters": model.n_parameters,
            # where the fit's time went: each search's own seconds, each finishing step's
            "fit_profile_s": profile,
        }
        return (lambda starts, steps: model.simulate(test, starts, steps)), fit_time, record
    peer, fit_time = peers.fit_peer(method, scenario.fit, seed)
    record = {
        "equations": peer.equations,
        "settings": peer.settings,
        "n_parameters": peer.n_parameters,
        "recovery": peers.recovery(peer, scenario) if scenario.truth else None,
    }
    return (lambda starts, steps: fly(peer.predict, test.arrays, starts, steps)), fit_time, record


def run_cell(
    scenario,
    method: str,
    seed: int,
    out: Path,
    engine,
    horizons_s,
    fingerprint: str | None = None,
    fit_jobs: int = 1,
) -> dict:
    """Fit, fly and score one cell and save it atomically; returns the cell record."""
    cpu0 = time.process_time()
    with PeakRss() as memory:
        simulate, fit_time, record = _fit(method, scenario, seed, engine, fit_jobs)
        t0 = time.perf_counter()
        metrics = evaluate.score(simulate, scenario.test, scenario.measured, horizons_s)
        trace = evaluate.figure_trace(simulate, scenario.test)
        score_time = time.perf_counter() - t0
    cell = {
        "scenario": scenario.name,
        "method": method,
        "seed": int(seed),
        "fingerprint": fingerprint,
        "version": peers.package_version(method) if method != "gpquad" else None,
        "metrics": metrics,
        **record,
        "figure": trace,
        "cost": {
            "fit_time_s": fit_time,
            "score_time_s": score_time,
            "cpu_time_s": time.process_time() - cpu0,
            "peak_memory_mb": memory.peak_mb,
        },
    }
    write_json(cell_path(out, scenario.name, method, seed), _clean(cell))
    return cell


class PeakRss:
    """Peak resident memory of this process (MB, interpreter included) while in the block.
    Unlike tracemalloc it costs nothing and sees native allocations (numba, operon's C++).

    On Linux the kernel keeps the peak (VmHWM in /proc/self/status): it is reset to the
    current size on entry (writing 5 to /proc/self/clear_refs) and read on exit, with no
    thread, so that a fit inside the block may still fork its search workers
    (gpquad.study.workers.fork_context). The reset is the process's: blocks do not nest.
    Where the peak cannot be reset, a thread samples VmRSS every 50 ms; elsewhere the
    process's lifetime peak (getrusage). The search workers' memory is not counted."""

    STATUS, CLEAR = "/proc/self/status", "/proc/self/clear_refs"

    @classmethod
    def reset(cls) -> bool:
        """Reset the kernel's peak of this process to its current size; False where it
        cannot (not Linux, a kernel before 4.0, a /proc that refuses the write)."""
        try:
            with open(cls.CLEAR, "w") as fh:
                fh.write("5")
        except OSError:
            return False
        return True

    def __enter__(self):
        self._thread = None
        self.peak_mb = self._read("VmRSS:")
        if not self.reset():
            self._stop = threading.Event()
            self._thread = threading.Thread(target=self._watch, daemon=True)
            self._thread.start()
        return self

    def _watch(self):
        while not self._stop.wait(0.05):
            self.peak_mb = max(self.peak_mb, self._read("VmRSS:"))

    def __exit__(self, *exc):
        if self._thread is not None:
            self._stop.set()
            self._thread.join()
            self.peak_mb = max(self.peak_mb, self._read("VmRSS:"))
        else:
            self.peak_mb = max(self.peak_mb, self._read("VmHWM:"))

    @classmethod
    def _read(cls, field: str) -> float:
        try:
            with open(cls.STATUS) as fh:
                for line in fh:
                    if line.startswith(field):
                        return int(line.split()[1]) / 1024
        except OSError:
            pass
        import resource

        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _clean(obj):
    """JSON-safe: NaN and inf become null."""
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if isinstance(obj, (float, np.floating)):
        return float(obj) if np.isfinite(obj) else None
    if isinstance(obj, np.integer):
        return int(obj)
    return obj
