"""Pass rate of known-equation recovery over seeds (not a test: it takes minutes).

    python benchmarks/recovery.py [--config experiments/quickstart.toml] [--seeds 10]

Runs each configured target with seeds 1..N on the config's simulated flight and
checks structure, delays and coefficients (5 %) against the simulator's equations.
"""

import argparse
import json
import time

from gpquad.data.io import load_dataset
from gpquad.models.analysis import compare_to_truth
from gpquad.study.config import load_config, override
from gpquad.study.search import identify


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--config", default="experiments/quickstart.toml")
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    cfg = load_config(args.config)
    dataset = load_dataset(cfg)
    summary = {}
    for target in cfg.evolution.targets:
        passed, times = 0, []
        for seed in range(1, args.seeds + 1):
            t0 = time.perf_counter()
            eq, _ = identify(dataset, target, override(cfg, targets=[target], seed=seed))
            times.append(time.perf_counter() - t0)
            report = compare_to_truth(eq, cfg.simulator.equations[target], dataset)
            passed += report["passed"]
            if not args.json:
                print(
                    f"{target} seed {seed:2d}: {'pass' if report['passed'] else 'FAIL'}  "
                    f"{eq.text()}  ({times[-1]:.1f} s)",
                    flush=True,
                )
        summary[target] = {
            "passed": passed,
            "seeds": args.seeds,
            "mean_time_s": sum(times) / len(times),
        }
    print(
        json.dumps(summary)
        if args.json
        else "\n".join(
            f"{t}: {s['passed']}/{s['seeds']} seeds recovered, {s['mean_time_s']:.1f} s per run"
            for t, s in summary.items()
        )
    )


if __name__ == "__main__":
    main()
