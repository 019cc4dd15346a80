"""Sub-commands `gpquad control pid RUN_DIR` and `gpquad control lq PEM_RUN_DIR`."""

from __future__ import annotations

import json
import time
from pathlib import Path


def _out_dir(args, kind: str) -> Path:
    if args.out:
        return Path(args.out)
    return Path("results") / f"control-{kind}-{time.strftime('%Y%m%d-%H%M%S')}"


def _cmd_pid(args) -> int:
    from gpquad.control.config import load_control_config
    from gpquad.control.pid_run import run_pid

    cfg = load_control_config(args.config)
    out = _out_dir(args, "pid")
    say = (lambda *a, **k: None) if args.json else print
    summary = run_pid(
        args.run,
        cfg,
        out,
        courses=args.courses,
        seed=args.seed,
        say=say,
        figures=not args.no_figures,
    )
    if args.json:
        print(json.dumps(summary))
    else:
        print(_pid_text(summary))
        print(f"Run folder: {out}")
    return 0


def _pid_text(s: dict) -> str:
    lines = [
        f"model: position RMSE from the course {s['model_rmse_m']:.3f} m, completion "
        f"{s['model_completion']:.1%}, diverged flights {s['model_diverged']}"
    ]
    if s["truth_rmse_m"] is not None:
        lines.append(
            f"truth plant: position RMSE {s['truth_rmse_m']:.3f} m "
            f"({s['rmse_ratio']:.2f} x the model's), completion {s['completion']:.1%}"
        )
    return "\n".join(lines)


def _cmd_lq(args) -> int:
    from gpquad.control.config import load_control_config
    from gpquad.control.lq_run import run_lq

    cfg = load_control_config(args.config)
    out = _out_dir(args, "lq")
    say = (lambda *a, **k: None) if args.json else print
    summary = run_lq(args.run, cfg, out, say=say, figures=not args.no_figures)
    if args.json:
        print(json.dumps(summary))
    else:
        print(f"Run folder: {out}")
    return 0


def register(subparsers) -> None:
    """Add `control pid` and `control lq` to gpquad's command line."""
    c = subparsers.add_parser("control", help="fly identified models in closed loop (PID, LQ)")
    sub = c.add_subparsers(dest="control_command", required=True)
    pid = sub.add_parser(
        "pid",
        help="evolve PID waypoint gains on a discovered model "
        "(CMA-ES) and fly them on the model and the truth plant",
    )
    pid.add_argument("run", help="run folder of `gpquad run`")
    pid.add_argument("--courses", type=int, default=1, help="test courses (default 1)")
    pid.add_argument("--seed", type=int, help="seed (default: the config's, 1)")
    pid.add_argument("--config", help="control TOML (experiments/control_*.toml)")
    pid.add_argument("--out", help="output folder (default results/control-pid-<time>)")
    pid.add_argument("--json", action="store_true", help="print only the JSON summary")
    pid.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    pid.set_defaults(func=_cmd_pid)
    lq = sub.add_parser("lq", help="LQ acceleration tracker on a PEM body-centric model")
    lq.add_argument("run", help="run folder of `gpquad baseline pem`")
    lq.add_argument("--config", help="control TOML (experiments/control_*.toml)")
    lq.add_argument("--out", help="output folder (default results/control-lq-<time>)")
    lq.add_argument("--json", action="store_true", help="print only the JSON summary")
    lq.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    lq.set_defaults(func=_cmd_lq)
