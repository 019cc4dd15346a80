"""A/B of the full-model steps on the same identified equations (not a test).

    nice -n 5 python benchmarks/ab_finish.py rotorpy-angle rotorpy-angle-noisy --seeds 1 2 3 \\
        --out results/ab-finish --jobs 2 [--engine max_depth=7] [--variants all] \\
        [--peers results/benchmark]

The six per-equation searches are the expensive part of a benchmark cell; the steps after
them (stability repair, front selection, joint refit: gpquad.models.finish) take seconds.
This script identifies each scenario's equations once per seed (per vehicle for the
rotorpy scenarios) with the engine settings of experiments/recommended.toml (plus
`--engine` overrides), keeps the six equations with their fronts in
OUT/raw/<scenario>/<group>/seed<S>.json (a second run reuses them), then applies every
variant asked for (--variants, of VARIANTS) to the same equations and scores each as the
benchmark does
(gpquad.benchmark.evaluate.score on the scenario's held-out test flights; each window flies
its vehicle's model). With `--peers DIR`, a benchmark folder holding the scenarios' peer
cells, each variant is also scored on the windows a diverging peer flew
(gpquad.benchmark.paired). Results: OUT/ab_finish.json and a Markdown table on stdout.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import numpy as np
import tomllib
from joblib import Parallel, delayed

from gpquad.benchmark import evaluate
from gpquad.benchmark.cells import cell_path, load_cell, recovery_gpquad
from gpquad.benchmark.engine import engine_config, fit_gpquad
from gpquad.benchmark.paired import paired
from gpquad.benchmark.scenarios import build_scenario
from gpquad.models.equations import DiscoveredModel
from gpquad.models.finish import finish_model

HORIZONS_S = (1.0, 7.0, 30.0)
#: Finishing variants: EvolutionConfig fields set on top of the engine's.
RATE_REFINE = {"p_dot": 20, "q_dot": 20, "r_dot": 20}
VARIANTS = {
    "none": {"finish": ()},
    "repair+joint": {"finish": ("symmetrize", "repair", "joint_fit")},
    "refine+repair+joint": {
        "finish": ("symmetrize", "refine", "repair", "joint_fit"),
        "refine_terms": RATE_REFINE,
    },
}


def parse_fields(items) -> dict:
    out = {}
    for item in items or []:
        key, _, value = item.partition("=")
        out[key.strip()] = tomllib.loads(f"v = {value.strip()}")["v"]
    return out


def raw_model(sub, name: str, group: str, seed: int, engine: dict, out: Path):
    """The six identified equations before any full-model step (cached)."""
    path = out / "raw" / name / group / f"seed{seed}.json"
    if path.exists():
        return DiscoveredModel.from_dict(json.loads(path.read_text()))
    cfg = engine_config(seed)
    ev = dataclasses.replace(cfg.evolution, **engine, **VARIANTS["none"])  # no full-model step
    t0 = time.perf_counter()
    model = fit_gpquad(sub.fit, dataclasses.replace(cfg, evolution=ev))
    path.parent.mkdir(parents=True, exist_ok=True)
    record = model.to_dict()
    record["fit_time_s"] = time.perf_counter() - t0
    path.write_text(json.dumps(record))
    return model


def run_seed(name: str, seed: int, engine: dict, out: Path, variants) -> list[dict]:
    scenario = build_scenario(name, out / "flights")
    groups = scenario.groups or {"all": scenario}
    offsets = scenario.group_offsets() if scenario.groups else {"all": (0, scenario.test.n_samples)}
    raws = {g: raw_model(sub, name, g, seed, engine, out) for g, sub in groups.items()}
    cfg = engine_config(seed)
    rows = []
    for variant in variants:
        ev = dataclasses.replace(cfg.evolution, **engine, **VARIANTS[variant])
        t0 = time.perf_counter()
        models = {g: finish_model(raws[g], groups[g].fit, ev, cfg.vehicle) for g in groups}
        finish_s = time.perf_counter() - t0

        def simulate(starts, steps, models=models):
            starts = np.asarray(starts, dtype=np.int64)
            pred = np.empty((len(starts), steps + 1, 9))
            for g, (a, b) in offsets.items():
                mask = (starts >= a) & (starts < b)
                if mask.any():
                    pred[mask] = models[g].simulate(groups[g].test, starts[mask] - a, steps)
            return pred

        metrics = evaluate.score(simulate, scenario.test, scenario.measured, HORIZONS_S)
        swaps = {
            g: [
                s["target"] + ":" + s.get("why", "diverged")
                for s in (m.stability or {}).get("swaps", [])
            ]
            for g, m in models.items()
        }
        exact = (recovery_gpquad(models["all"], scenario) if "all" in models else None) or {}
        rows.append(
            {
                "scenario": name,
                "seed": seed,
                "variant": variant,
                "metrics": metrics,
                "exact": sum(exact.values()) if exact else None,
                "swaps": swaps,
                "finish_s": finish_s,
                "equations": {
                    g: {t: e.text() for t, e in m.equations.items()} for g, m in models.items()
                },
            }
        )
    return rows


def table(rows: list[dict], variants) -> str:
    lines = [
        "| scenario | variant | 1 s | 7 s | 30 s | diverged | exact per seed | "
        "swaps (seed: group target) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name in dict.fromkeys(r["scenario"] for r in rows):
        for variant in variants:
            rs = [r for r in rows if r["scenario"] == name and r["variant"] == variant]
            cells = []
            for h in HORIZONS_S:
                vals = np.array([r["metrics"][f"{h:g}s"]["mean"] or np.nan for r in rs])
                cells.append(f"{np.mean(vals):.3g} ({np.min(vals):.3g}-{np.max(vals):.3g})")
            div = sum(r["metrics"][f"{h:g}s"]["diverged"] for r in rs for h in HORIZONS_S)
            swaps = "; ".join(
                f"{r['seed']}: " + ", ".join(f"{g} {s}" for g, ss in r["swaps"].items() for s in ss)
                for r in rs
                if any(r["swaps"].values())
            )
            exact = ", ".join(str(r["exact"]) for r in rs if r["exact"] is not None) or "-"
            lines.append(
                f"| {name} | {variant} | "
                + " | ".join(cells)
                + f" | {div} | {exact} | {swaps or '-'} |"
            )
    return "\n".join(lines)


def paired_table(rows: list[dict], peers_dir: Path, variants) -> str:
    lines = [
        "| scenario | variant | peer | horizon | peer RSE | gpquad RSE (min-max) |",
        "|---|---|---|---|---|---|",
    ]
    for name in dict.fromkeys(r["scenario"] for r in rows):
        peer_cells = [
            c for p in ("sindy", "ols") for c in [load_cell(cell_path(peers_dir, name, p, 0))] if c
        ]
        for variant in variants:
            ours = [
                {"scenario": name, "method": "gpquad", "seed": r["seed"], "metrics": r["metrics"]}
                for r in rows
                if r["scenario"] == name and r["variant"] == variant
            ]
            for p in paired(ours + peer_cells):
                g = p["gpquad_rse"]
                lines.append(
                    f"| {name} | {variant} | {p['peer']} | {p['horizon']} | "
                    f"{p['peer_rse']:.3g} | {g['mean']:.3g} ({g['min']:.3g}-"
                    f"{g['max']:.3g}) |"
                )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("scenarios", nargs="+")
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--engine", nargs="*", help="EvolutionConfig overrides FIELD=VALUE")
    parser.add_argument("--out", type=Path, default=Path("results/ab-finish"))
    parser.add_argument("--jobs", type=int, default=1)
    parser.add_argument("--peers", type=Path, help="benchmark folder with the peer cells")
    parser.add_argument(
        "--variants",
        default="none,repair+joint",
        help=f"comma-separated, or 'all' ({', '.join(VARIANTS)})",
    )
    args = parser.parse_args()
    variants = list(VARIANTS) if args.variants == "all" else args.variants.split(",")
    unknown = [v for v in variants if v not in VARIANTS]
    if unknown:
        parser.error(f"unknown variants {unknown}; choose from {list(VARIANTS)} or 'all'")
    engine = parse_fields(args.engine)
    args.out.mkdir(parents=True, exist_ok=True)
    for name in args.scenarios:  # build (and cache) the flights once, before the workers
        build_scenario(name, args.out / "flights")
    jobs = [(n, s) for n in args.scenarios for s in args.seeds]
    results = Parallel(n_jobs=args.jobs)(
        delayed(run_seed)(n, s, engine, args.out, variants) for n, s in jobs
    )
    rows = [r for rs in results for r in rs]
    (args.out / "ab_finish.json").write_text(
        json.dumps(
            {
                "engine_overrides": engine,
                "variants": {v: VARIANTS[v] for v in variants},
                "rows": rows,
            },
            default=float,
        )
    )
    print(table(rows, variants))
    if args.peers:
        print()
        print(paired_table(rows, args.peers, variants))


if __name__ == "__main__":
    sys.exit(main())
