"""Transfer of the evolved PID (issue 12's measurements), run niced:

    PYTHONPATH=. nice -n 5 python benchmarks/control.py --model results/qs --seeds 5
    PYTHONPATH=. nice -n 5 python benchmarks/control.py --model results/px4-rates \
        --seeds 1 --courses 5

For each seed: `gpquad control pid MODEL --seed S --courses C` (evolution on the model, then
the test courses on the model and, for a simulator-identified model, on the truth plant, three
repetitions each). Prints one row per seed and whether it meets the criterion: truth RMSE
<= 1.5 x the model's and truth completion >= 90 % (model-only runs: no divergence and model
completion >= 90 %). Writes the rows to OUT/control_benchmark.json.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from gpquad.control.config import load_control_config
from gpquad.control.pid_run import run_pid


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", required=True, help="run folder of `gpquad run`")
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--courses", type=int, default=1)
    ap.add_argument("--config", help="control TOML")
    ap.add_argument("--out", default="results/control-benchmark")
    args = ap.parse_args()
    cfg = load_control_config(args.config)
    out = Path(args.out) / Path(args.model).name
    rows = []
    for seed in range(1, args.seeds + 1):
        t0 = time.perf_counter()
        s = run_pid(args.model, cfg, out / f"seed{seed}", courses=args.courses, seed=seed,
                    say=lambda *a: None)
        if s["truth_rmse_m"] is not None:
            ok = s["truth_rmse_m"] <= 1.5 * s["model_rmse_m"] and s["completion"] >= 0.9
        else:
            ok = s["model_diverged"] == 0 and s["model_completion"] >= 0.9
        rows.append({**s, "pass": bool(ok), "wall_time_s": time.perf_counter() - t0})
        truth = ("" if s["truth_rmse_m"] is None else
                 f"truth RMSE {s['truth_rmse_m']:.3f} m ({s['rmse_ratio']:.2f}x), "
                 f"completion {s['completion']:.1%}; ")
        print(f"seed {seed}: model RMSE {s['model_rmse_m']:.3f} m, model completion "
              f"{s['model_completion']:.1%}, diverged {s['model_diverged']}; {truth}"
              f"{'pass' if ok else 'FAIL'} ({rows[-1]['wall_time_s']:.0f} s)", flush=True)
    out.mkdir(parents=True, exist_ok=True)
    (out / "control_benchmark.json").write_text(json.dumps(rows, indent=1))
    print(f"{sum(r['pass'] for r in rows)}/{len(rows)} seeds pass")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
