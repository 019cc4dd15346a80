"""`gpquad physics mixer|thrust|drag|deadreckon`: the thesis's identification commands."""

from __future__ import annotations

import json
import time
from pathlib import Path


def _fmt(x, spec=".3f"):
    return "-" if x is None else format(x, spec)


def mixer_markdown(results: list[dict], skipped: list[str], path: str) -> str:
    lines = [f"# Mixer model vs logged motor commands: {path}", ""]
    for r in results:
        alt_key = "without_airmode" if r["airmode_feature"] else "with_airmode"
        main = "with airmode" if r["airmode_feature"] else "without airmode"
        alt = "without airmode" if r["airmode_feature"] else "with airmode"
        lines += [
            f"## Log {r['index']} ({r['armed_frames']} armed frames, {r['duration_s']:.1f} s)",
            "",
            f"Low end {r['low']:.2f} ({r['low_from']}), high {r['high']:.0f}; "
            f"yaw_motors_reversed = {r['yaw_reversed']} ({r['yaw_reversed_from']}); "
            f"thrust_linear = {r['thrust_linear']:g} % ({r['thrust_linear_from']}); "
            f"saturated {100 * r['saturated_fraction']:.1f} % of armed frames in "
            f"{r['saturated_stretches']} stretches.",
            "",
            f"| motor | RMSE {main} | R^2 {main} | RMSE unsaturated | bias | "
            f"RMSE {alt} | R^2 {alt} |",
            "|---|---|---|---|---|---|---|",
        ]
        for k, (m, o) in enumerate(zip(r["motors"], r[alt_key]["motors"])):
            lines.append(
                f"| {k} | {_fmt(m['rmse'], '.1f')} | {_fmt(m['r2'], '.4f')} | "
                f"{_fmt(m['rmse_unsaturated'], '.1f')} | {_fmt(m['bias'], '.1f')} | "
                f"{_fmt(o['rmse'], '.1f')} | {_fmt(o['r2'], '.4f')} |"
            )
        lines.append("")
    if skipped:
        lines += ["## Skipped logs", ""] + [f"- {s}" for s in skipped] + [""]
    return "\n".join(lines)


def _cmd_mixer(args) -> int:
    from gpquad.physics.mixer_check import check_file
    from gpquad.physics.runfolder import default_out, plain, write_run

    started = time.time()
    path = Path(args.log)
    results, skipped = check_file(
        path,
        args.log_index,
        args.throttle,
        args.yaw_reversed,
        args.allow_truncated,
        args.thrust_linear,
    )
    out = Path(args.out) if args.out else default_out("mixer", path.stem)
    out.mkdir(parents=True, exist_ok=True)
    if not args.no_figures:
        from gpquad.physics.plots import motors_figure

        for r in results:
            motors_figure(
                r["_series"], f"{path.name} log {r['index']}", out / f"motors_log{r['index']}.png"
            )
    summary = {
        "file": str(path),
        "throttle_source": args.throttle,
        "logs": results,
        "skipped": skipped,
    }
    md = mixer_markdown(results, skipped, str(path))
    write_run(
        out,
        "mixer",
        summary,
        md,
        config={
            "log": str(path),
            "log_index": args.log_index,
            "throttle": args.throttle,
            "yaw_reversed": args.yaw_reversed,
            "thrust_linear": args.thrust_linear,
            "allow_truncated": args.allow_truncated,
        },
        seed=None,
        started=started,
    )
    for s in skipped:
        print(f"skipped: {s}")
    if args.json:
        print(json.dumps(plain(summary)))
    else:
        print(md)
        print(f"Run folder: {out}")
    return 0


def _cmd_fit(args) -> int:
    from gpquad.physics.commands import run_command
    from gpquad.physics.runfolder import plain

    out, summary = run_command(
        args.kind, args.config, args.out, seed=args.seed, progress=not args.json, summary=True
    )
    if args.json:
        print(json.dumps(plain(summary)))
    else:
        print(f"Run folder: {out}")
    return 0


def register(subparsers) -> None:
    """Add `physics` (mixer, thrust, drag, deadreckon) to gpquad's command line."""
    phys = subparsers.add_parser(
        "physics",
        help="Betaflight mixer, thrust/drag regressions, dead reckoning (racing-drone thesis)",
    )
    sub = phys.add_subparsers(dest="physics_command", required=True)
    mx = sub.add_parser("mixer", help="predicted vs logged motor commands of a blackbox log")
    mx.add_argument("log", help="Betaflight .bbl/.BFL file")
    mx.add_argument("--log-index", type=int, help="only this log (1-based)")
    mx.add_argument("--json", action="store_true", help="last line: one JSON object")
    mx.add_argument(
        "--throttle",
        choices=["setpoint", "rccommand"],
        default="setpoint",
        help="mixer throttle (setpoint[3]) or stick throttle (rcCommand[3])",
    )
    mx.add_argument(
        "--yaw-reversed",
        choices=["auto", "yes", "no"],
        default="auto",
        help="yaw_motors_reversed (4.2 logs do not record it; auto fits both)",
    )
    mx.add_argument(
        "--thrust-linear",
        default="0",
        help="thrust_linear percent (default 0, Betaflight 4.2's default; 4.2 logs "
        "do not record it; auto fits 0..40 per log)",
    )
    mx.add_argument(
        "--allow-truncated",
        action="store_true",
        help="use the frames before a truncated or corrupt tail",
    )
    mx.add_argument("--no-figures", action="store_true")
    mx.add_argument("--out", help="run folder (default results/physics-mixer-<log>-<time>)")
    mx.set_defaults(func=_cmd_mixer)
    for kind, text in (
        ("thrust", "standard (eq. 5) and refined (eq. 19) thrust regressions"),
        ("drag", "drag regression (eq. 18)"),
        ("deadreckon", "dead-reckoning position with four acceleration models (Table III)"),
    ):
        p = sub.add_parser(kind, help=text)
        p.add_argument(
            "config",
            help="TOML (experiments/physics_*.toml): [data] files and "
            "[vehicle] for a log, or [truth] for rotorpy flights",
        )
        p.add_argument(
            "--json",
            action="store_true",
            help="print one JSON object of the coefficients (SI units) instead",
        )
        p.add_argument("--seed", type=int, help="override the config's seed")
        p.add_argument("--out", help="run folder (default results/physics-<kind>-<time>)")
        p.set_defaults(func=_cmd_fit, kind=kind)
