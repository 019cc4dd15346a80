"""A/B comparison of engine settings on known-truth and real-log scenarios (not a test).

    nice -n 5 python benchmarks/ab_engine.py --scenario rigid-body --seeds 1 2 3 \\
        --variant base: --variant nm:constant_fit=nelder-mead [--json out.json]

A variant is NAME:FIELD=VALUE,FIELD=VALUE (EvolutionConfig fields; values parsed as TOML).
For every scenario, seed and variant all six equations are identified (same seeds for
every variant) and scored:

- exact: gpquad.models.analysis.compare_to_truth with terms >= 1 % of the target's RMS, the truth's
  delays and every coefficient within 2 % (simulated scenarios only);
- RSE of u, v, w, p, q, r of the full six-equation model flown from recorded states at
  1, 7 and 30 s (gpquad.models.scoring) on HELD-OUT data: a second simulator flight (simulator
  seed + 1000, never seen in training) for simulated scenarios, the last 30 % of the log
  for px4-s250 (only p, q, r, w are measured there; the mean is over those);
- diverged windows (non-finite RSE) and wall time.

Scenarios: median-noisy, median, rigid-body, rigid-body-noisy, px4-s250.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time

import numpy as np
import tomllib

from gpquad.data.io import load_dataset
from gpquad.errors import GpquadError
from gpquad.models.analysis import compare_to_truth
from gpquad.models.equations import DiscoveredModel
from gpquad.models.scoring import SCORED_STATES, score_model
from gpquad.study.config import Config, load_config, validate
from gpquad.study.search import identify

NOISE = {"attitude": 0.005, "velocity": 0.02, "rates": 0.01}
SCENARIOS = {
    "median": ("experiments/quickstart.toml", False),
    "median-noisy": ("experiments/quickstart.toml", True),
    "rigid-body": ("experiments/rigid_body.toml", False),
    "rigid-body-noisy": ("experiments/rigid_body.toml", True),
    "px4-s250": ("experiments/px4_s250.toml", False),
}
HORIZONS_S = (1.0, 7.0, 30.0)


def parse_variant(text: str) -> tuple[str, dict]:
    name, _, rest = text.partition(":")
    fields = {}
    for item in filter(None, rest.split(",")):
        key, _, value = item.partition("=")
        fields[key.strip()] = tomllib.loads(f"v = {value.strip()}")["v"] if value.strip() else ""
    return name, fields


def scenario_config(scenario: str, base: str | None) -> Config:
    path, noisy = SCENARIOS[scenario]
    cfg = load_config(base or path) if scenario != "px4-s250" else load_config(path)
    if scenario.startswith("rigid") and base:
        # keep the rigid-body truth, take the engine settings of `base`
        cfg = dataclasses.replace(
            load_config(path),
            evolution=dataclasses.replace(
                load_config(base).evolution, targets=cfg.evolution.targets
            ),
        )
    if noisy:
        cfg = dataclasses.replace(
            cfg, simulator=dataclasses.replace(cfg.simulator, measurement_noise=dict(NOISE))
        )
    if scenario == "px4-s250":
        cfg = dataclasses.replace(cfg, data=dataclasses.replace(cfg.data, validation_fraction=0.3))
        if base:
            cfg = dataclasses.replace(
                cfg,
                evolution=dataclasses.replace(
                    load_config(base).evolution, targets=cfg.evolution.targets
                ),
            )
    return validate(cfg, scenario)


def heldout_dataset(cfg: Config, scenario: str):
    """Scoring data with raw inputs: a new simulator flight, or the log's last 30 %."""
    data = dataclasses.replace(cfg.data, trim="none")
    if scenario == "px4-s250":
        return load_dataset(dataclasses.replace(cfg, data=data))
    sim = dataclasses.replace(cfg.simulator, seed=cfg.simulator.seed + 1000)
    data = dataclasses.replace(data, validation_fraction=0.9)
    return load_dataset(dataclasses.replace(cfg, data=data, simulator=sim))


def run_one(cfg: Config, scenario: str, seed: int, fields: dict, dataset, heldout) -> dict:
    ev = dataclasses.replace(cfg.evolution, **fields)
    cfg = validate(dataclasses.replace(cfg, evolution=ev, seed=seed), scenario)
    t0 = time.perf_counter()
    eqs, exact, rows = {}, {}, {}
    for target in ev.targets:
        eq, _ = identify(dataset, target, cfg)
        eqs[target] = eq
        rows[target] = eq.text()
        if scenario != "px4-s250":
            report = compare_to_truth(
                eq, cfg.simulator.equations[target], dataset, rel_tol=0.02, threshold=0.01
            )
            exact[target] = bool(report["passed"])
    wall = time.perf_counter() - t0
    model = DiscoveredModel(eqs, dataset.input_names, dataset.trim, dataset.dt, seed, {})
    max_delay = cfg.evolution.max_delay
    scored = ("p", "q", "r", "w") if scenario == "px4-s250" else SCORED_STATES
    rse = {}
    for h in HORIZONS_S:
        steps = int(round(h / dataset.dt))
        try:
            score = score_model(model, heldout, steps, model.trim, max_delay)
        except GpquadError:
            continue
        rse[str(h)] = {s: score.rse[s] for s in scored}
    return {
        "scenario": scenario,
        "seed": seed,
        "wall_s": wall,
        "exact": exact,
        "n_exact": sum(exact.values()),
        "equations": rows,
        "rse": rse,
        "mean_rse": {h: float(np.mean(list(v.values()))) for h, v in rse.items()},
        "diverged": any(not np.isfinite(x) for v in rse.values() for x in v.values()),
    }


def summarise(results: list[dict]) -> str:
    lines = [
        "| scenario | variant | exact (per seed) | mean RSE 1 s | 7 s | 30 s | diverged | wall s |",
        "|---|---|---|---|---|---|---|---|",
    ]
    keys = sorted(
        {(r["scenario"], r["variant"]) for r in results},
        key=lambda k: (k[0], [r["variant"] for r in results].index(k[1])),
    )
    for scen, var in keys:
        rs = [r for r in results if r["scenario"] == scen and r["variant"] == var]
        exact = "/".join(str(r["n_exact"]) for r in rs) if rs[0]["exact"] else "-"
        cells = []
        for h in HORIZONS_S:
            vals = np.array([r["mean_rse"].get(str(h), np.nan) for r in rs])
            cells.append(f"{np.mean(vals):.3g} [{np.min(vals):.3g}, {np.max(vals):.3g}]")
        div = sum(r["diverged"] for r in rs)
        wall = np.mean([r["wall_s"] for r in rs])
        lines.append(
            f"| {scen} | {var} | {exact} | "
            + " | ".join(cells)
            + f" | {div}/{len(rs)} | {wall:.0f} |"
        )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--scenario", action="append", required=True, choices=sorted(SCENARIOS))
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--variant", action="append", default=None)
    parser.add_argument(
        "--base",
        default=None,
        help="engine settings from this config (default: the scenario's own)",
    )
    parser.add_argument("--json", default=None, help="write every result to this file")
    args = parser.parse_args()
    variants = [parse_variant(v) for v in (args.variant or ["base:"])]
    results = []
    for scenario in args.scenario:
        cfg = scenario_config(scenario, args.base)
        dataset = load_dataset(cfg)
        heldout = heldout_dataset(cfg, scenario)
        for seed in args.seeds:
            for name, fields in variants:
                r = run_one(cfg, scenario, seed, fields, dataset, heldout)
                r["variant"] = name
                results.append(r)
                print(
                    f"{scenario} {name} seed {seed}: exact {r['n_exact']} "
                    f"{[t for t, ok in r['exact'].items() if not ok]} mean RSE "
                    + " ".join(f"{h}s={v:.3g}" for h, v in r["mean_rse"].items())
                    + f" ({r['wall_s']:.0f} s)",
                    flush=True,
                )
                for text in r["equations"].values():
                    print(f"    {text}", flush=True)
    print(summarise(results))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(results, fh, indent=1)


if __name__ == "__main__":
    main()
