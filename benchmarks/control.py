"""Transfer of the evolved PID (issue 12's measurements), run niced:

    PYTHONPATH=. nice -n 5 python benchmarks/control.py --model results/qs --seeds 5
    PYTHONPATH=. nice -n 5 python benchmarks/control.py --model results/px4-rates \
        --replace a_z=results/px4-rates-az3 --seeds 1 --courses 5 \
        --config experiments/control_px4.toml

For each seed: `gpquad control pid MODEL --seed S --courses C` (evolution on the model, then
the test courses on the model and, for a simulator-identified model, on the truth plant, three
repetitions each). Prints one row per seed and whether it meets the criterion: truth RMSE
<= 1.5 x the model's and truth completion >= 90 % (model-only runs: no flight diverged).
Writes the rows to OUT/control_benchmark.json.

--replace TARGET=RUN_DIR flies a model whose TARGET equation comes from another run on the
same data (written to OUT/<model>-composed/ first), e.g. the PX4 model's a_z from a longer
a_z-only run: the 4-iteration run found no thrust term, so the PID could not fly it.
"""

from __future__ import annotations

import argparse
import json
import shutil
import time
from pathlib import Path

from gpquad.control.config import load_control_config
from gpquad.control.pid_run import run_pid


def compose(base: Path, replace: list[str], out: Path) -> Path:
    """A copy of run folder `base` whose model.json takes TARGET from RUN_DIR's model.json."""
    out.mkdir(parents=True, exist_ok=True)
    shutil.copy(base / "config.json", out / "config.json")
    model = json.loads((base / "model.json").read_text())
    sources = {}
    for item in replace:
        target, _, other = item.partition("=")
        other_model = json.loads((Path(other) / "model.json").read_text())
        if other_model["input_names"] != model["input_names"]:
            raise SystemExit(f"{other}: different inputs")
        model["targets"][target] = other_model["targets"][target]
        sources[target] = str(other)
    model["composed_from"] = {"base": str(base), "replaced": sources}
    (out / "model.json").write_text(json.dumps(model, indent=1))
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", required=True, help="run folder of `gpquad run`")
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--courses", type=int, default=1)
    ap.add_argument("--config", help="control TOML")
    ap.add_argument("--out", default="results/control-benchmark")
    ap.add_argument("--replace", action="append", default=[], help="TARGET=RUN_DIR")
    args = ap.parse_args()
    cfg = load_control_config(args.config)
    out = Path(args.out) / Path(args.model).name
    if args.replace:
        args.model = str(
            compose(
                Path(args.model), args.replace, Path(args.out) / f"{Path(args.model).name}-composed"
            )
        )
    rows = []
    for seed in range(1, args.seeds + 1):
        t0 = time.perf_counter()
        s = run_pid(
            args.model,
            cfg,
            out / f"seed{seed}",
            courses=args.courses,
            seed=seed,
            say=lambda *a: None,
        )
        if s["truth_rmse_m"] is not None:
            ok = s["truth_rmse_m"] <= 1.5 * s["model_rmse_m"] and s["completion"] >= 0.9
        else:
            ok = s["model_diverged"] == 0
        rows.append({**s, "pass": bool(ok), "wall_time_s": time.perf_counter() - t0})
        truth = (
            ""
            if s["truth_rmse_m"] is None
            else f"truth RMSE {s['truth_rmse_m']:.3f} m ({s['rmse_ratio']:.2f}x), "
            f"completion {s['completion']:.1%}; "
        )
        print(
            f"seed {seed}: model RMSE {s['model_rmse_m']:.3f} m, model completion "
            f"{s['model_completion']:.1%}, diverged {s['model_diverged']}; {truth}"
            f"{'pass' if ok else 'FAIL'} ({rows[-1]['wall_time_s']:.0f} s)",
            flush=True,
        )
    out.mkdir(parents=True, exist_ok=True)
    (out / "control_benchmark.json").write_text(json.dumps(rows, indent=1))
    print(f"{sum(r['pass'] for r in rows)}/{len(rows)} seeds pass")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
