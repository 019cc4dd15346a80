"""Run the benchmark grid: scenarios x methods x seeds, resumable, in parallel (joblib).

gpquad and operon are fitted with seeds 1..N; zero, OLS and SINDy are deterministic and
are fitted once (seed 0). Each cell is saved when done (`gpquad.benchmark.cells`); a
rerun with the same --out skips finished cells whose method settings are unchanged (each
cell records a fingerprint of its method's settings: gpquad's engine config, version and
a hash of its sources, a peer's settings and package version), so changing the engine
recomputes only gpquad's cells. Cells do not depend on each other or on the order they
finish, so --jobs 2 gives the same table as --jobs 1.
"""

from __future__ import annotations

import hashlib
import json
import os
import sys
import time
from pathlib import Path

from gpquad.benchmark import cells, peers, scenarios
from gpquad.benchmark.engine import load_engine
from gpquad.benchmark.rollout import MAX_LAG
from gpquad.errors import GpquadError
from gpquad.study.store import provenance, write_json


def available_peers(requested) -> tuple[list[str], dict[str, str]]:
    """Requested peers that are installed, and {peer: why skipped} for the others."""
    ok, skipped = [], {}
    for name in requested:
        if peers.package_version(name) is None:
            skipped[name] = (
                f'{peers.PEER_PACKAGES[name]} is not installed (pip install -e ".[peers]")'
            )
        else:
            ok.append(name)
    return ok, skipped


def seeds_of(method: str, n_seeds: int) -> list[int]:
    return [0] if method in peers.DETERMINISTIC else list(range(1, n_seeds + 1))


def source_hash() -> str:
    """Hash of the gpquad sources that a gpquad cell's result depends on (engine, data,
    models, study): a changed engine recomputes gpquad's cells, whatever the version says."""
    root = Path(__file__).resolve().parents[1]
    digest = hashlib.sha256()
    for package in ("engine", "data", "models", "study", "benchmark/engine.py"):
        for path in (
            sorted((root / package).rglob("*.py"))
            if (root / package).is_dir()
            else [root / package]
        ):
            digest.update(path.relative_to(root).as_posix().encode())
            digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


def method_settings(method: str, engine) -> dict:
    """What a method's cells depend on besides the scenario and seed (`engine`: gpquad's
    Config)."""
    if method == "gpquad":
        from gpquad._version import __version__
        from gpquad.benchmark.engine import engine_config

        # the parsed settings, not a file's text: a comment does not recompute the cells
        used = engine_config(0, engine).to_dict()
        return {
            "engine": used["evolution"],
            "vehicle": used["vehicle"],
            "gpquad": __version__,
            "sources": source_hash(),
        }
    return {
        "settings": peers.PEER_SETTINGS.get(method),
        "version": peers.package_version(method),
        "max_lag": MAX_LAG,
    }


def check_folder(out: Path, settings: dict) -> None:
    """Refuse a folder that holds a benchmark scored another way (resume needs the same
    horizons); changed method settings only recompute that method's cells."""
    path = out / "benchmark.json"
    if path.is_file():
        try:
            saved = json.loads(path.read_text()).get("fingerprint")
        except ValueError:
            saved = None  # damaged: rewritten below; the cells carry their own fingerprints
        if saved is not None and saved != cells.settings_fingerprint(settings):
            raise GpquadError(
                "the folder holds a benchmark scored at other horizons; give another --out",
                source=str(out),
                field="--out",
            )


def run_benchmark(
    names,
    peer_names,
    n_seeds: int,
    out,
    jobs: int = 1,
    horizons_s=(1, 7, 30),
    log=print,
    engine=None,
    with_gpquad: bool = True,
) -> dict:
    """Run every missing cell; returns the summary (also written to benchmark.json).

    engine: a TOML config whose [evolution] and [vehicle] gpquad uses (default: the
    package's defaults, the recommended engine). with_gpquad=False runs the peers only
    (gpquad's cells already in the folder are still reported).
    """
    out = Path(out)
    engine_cfg, engine_source = load_engine(engine)
    settings = {"horizons_s": list(horizons_s)}
    check_folder(out, settings)
    use_peers, skipped_peers = available_peers(peer_names)
    for p, why in skipped_peers.items():
        log(f"gpquad benchmark: skipping peer {p}: {why}")
    methods = ["gpquad"] + use_peers  # reported
    run_methods = methods if with_gpquad else use_peers
    if not run_methods:
        raise GpquadError("nothing to run: no gpquad and no installed peer", field="--peers")
    built, skipped, made_from = {}, {}, {}
    for name in names:
        t0 = time.perf_counter()
        try:
            sc = scenarios.build_scenario(name, out / "flights")
        except scenarios.Skipped as exc:
            skipped[name] = str(exc)
            log(f"gpquad benchmark: skipping scenario {exc}")
            continue
        if sc.name in built:
            raise GpquadError(
                f"two scenarios are named {sc.name}; rename a config file", field="scenario"
            )
        built[sc.name] = sc
        made_from[sc.name] = str(name)
        log(
            f"gpquad benchmark: scenario {sc.name}: {sc.fit.summary()['train_samples']} training "
            f"and {sc.test.summary()['validation_samples']} test samples "
            f"({time.perf_counter() - t0:.1f} s to build)"
        )
    # a cell is reused only if made with the same method settings on the same flights
    fingerprints = {
        n: {
            m: cells.settings_fingerprint(
                {"method": method_settings(m, engine_cfg), "scenario": sc.source}
            )
            for m in methods
        }
        for n, sc in built.items()
    }
    todo = [(sc, m, s) for sc in built.values() for m in run_methods for s in seeds_of(m, n_seeds)]
    missing = [
        (sc, m, s)
        for sc, m, s in todo
        if cells.load_cell(cells.cell_path(out, sc.name, m, s), fingerprints[sc.name][m]) is None
    ]
    from gpquad.benchmark.evaluate import figure_data

    info = {
        "fingerprint": cells.settings_fingerprint(settings),
        "settings": settings,
        "scenarios": {n: sc.source for n, sc in built.items()},
        "scenario_arguments": made_from,
        "skipped_scenarios": skipped,
        "skipped_peers": skipped_peers,
        "methods": methods,
        "seeds": {m: seeds_of(m, n_seeds) for m in methods},
        "method_settings": {m: method_settings(m, engine_cfg) for m in methods},
        "fingerprints": fingerprints,
        "peer_versions": {p: peers.package_version(p) for p in use_peers},
        "engine_config": engine_source,
        "figures": {n: figure_data(sc.test) for n, sc in built.items()},
        **provenance(),
    }
    write_json(out / "benchmark.json", info)
    log(
        f"gpquad benchmark: {len(todo) - len(missing)} of {len(todo)} cells done earlier; "
        f"running {len(missing)} with {jobs} job(s); results in {out}"
    )
    t0 = time.perf_counter()
    if missing:
        from joblib import Parallel, delayed

        missing = run_order(missing, jobs)
        parallel = Parallel(n_jobs=jobs, backend="loky", return_as="generator_unordered")
        # the cores a cell's gpquad fit may use for its six searches (same equations)
        fit_jobs = max(1, (os.cpu_count() or 1) // jobs)
        for cell in parallel(
            delayed(cells.run_cell)(
                sc, m, s, out, engine_cfg, horizons_s, fingerprints[sc.name][m], fit_jobs
            )
            for sc, m, s in missing
        ):
            log(done_line(cell, time.perf_counter() - t0))
    info.update(
        wall_time_s=time.perf_counter() - t0,
        jobs=jobs,
        finished=time.strftime("%Y-%m-%dT%H:%M:%S%z"),
    )
    write_json(out / "benchmark.json", info)
    from gpquad.benchmark import fidelity

    fidelity.update(out, collect(out, info), built, horizons_s, log)
    return info


#: The methods by their cells' usual length, longest first.
BY_LENGTH = {"gpquad": 0, "operon": 1, "sindy": 2, "ols": 3, "zero": 4}


def run_order(missing: list, jobs: int) -> list:
    """The (scenario, method, seed) cells in the order they are started. One at a time
    (jobs 1), each scenario's cells back to back: a machine that changes speed during a run
    of half an hour then changes every method's fit time of a scenario alike
    (docs/decisions/2026-12-04-whole-benchmark.md). In parallel, the longest cells first, so
    that the last ones running side by side are short."""
    if jobs == 1:
        return sorted(missing, key=lambda c: (c[0].name, BY_LENGTH.get(c[1], 9), c[2]))
    return sorted(missing, key=lambda c: (BY_LENGTH.get(c[1], 9), c[0].name, c[2]))


def done_line(cell: dict, elapsed: float) -> str:
    """The progress line of a finished cell: its mean RSE at 7 s (else 1 s) and, when some
    of those windows diverged, how many (the mean leaves them out), and its fit time."""
    h = next((k for k in ("7s", "1s") if cell["metrics"].get(k, {}).get("mean") is not None), None)
    shown = f"mean RSE {h} {cell['metrics'][h]['mean']:.4g}" if h else "no score"
    if h and cell["metrics"][h].get("diverged"):
        m = cell["metrics"][h]
        shown += f" ({m['diverged']} of {m['windows']} windows diverged, left out)"
    return (
        f"  done {cell['scenario']:<20} {cell['method']:<7} seed {cell['seed']}: "
        f"{shown}, fit {cell['cost']['fit_time_s']:.1f} s ({elapsed:.0f} s elapsed)"
    )


def report_benchmark(out, names=(), log=print) -> dict:
    """Re-evaluate a finished benchmark folder without fitting: its cells (as their
    benchmark.json lists them, with the fingerprints they were made with) are flown again
    for the fidelity column (gpquad.benchmark.fidelity); returns benchmark.json's content.
    names: only these of its scenarios (default: all)."""
    from gpquad.benchmark import fidelity

    out = Path(out)
    path = out / "benchmark.json"
    try:
        info = json.loads(path.read_text())
        listed = dict(info["scenarios"])
        horizons_s = info["settings"]["horizons_s"]
    except (OSError, ValueError, KeyError, TypeError):
        raise GpquadError(
            "no finished benchmark here (benchmark.json missing or damaged); give the "
            "--out of a `gpquad benchmark` run",
            source=str(path),
            field="--out",
        ) from None
    unknown = [n for n in names if n not in listed]
    if unknown:
        raise GpquadError(
            f"scenario {unknown[0]!r} is not in this benchmark; it has {list(listed)}",
            source=str(path),
            field="scenario",
        )
    built = {}
    for name in names or listed:
        # the argument that built it (a user's TOML path); older folders: the name
        target = str((info.get("scenario_arguments") or {}).get(name, name))
        if target not in scenarios.SCENARIOS and not target.endswith(".toml"):
            log(f"gpquad benchmark: skipping scenario {name}: cannot rebuild its flights")
            continue
        try:
            built[name] = scenarios.build_scenario(target, out / "flights")
        except scenarios.Skipped as exc:
            log(f"gpquad benchmark: skipping scenario {exc}")
    info["scenarios"] = {n: listed[n] for n in built}
    info["fidelity_git_revision"] = provenance().get("git_revision")
    fidelity.update(out, collect(out, info), built, horizons_s, log)
    return info


def collect(out, info: dict) -> list[dict]:
    """Every finished cell of the benchmark in `out`, in a fixed order."""
    found = []
    for name in info["scenarios"]:
        for m in info["methods"]:
            for s in info["seeds"][m]:
                cell = cells.load_cell(
                    cells.cell_path(Path(out), name, m, s), info["fingerprints"][name][m]
                )
                if cell is not None:
                    found.append(cell)
                else:
                    print(
                        f"gpquad benchmark: warning: cell {name}/{m}/seed{s} missing",
                        file=sys.stderr,
                    )
    return found
