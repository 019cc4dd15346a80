"""Command line: `gpquad score` and `gpquad data export` (picked up by gpquad.cli.commands)."""

from __future__ import annotations

import json

from gpquad.data.score import INTEGRATORS, PARTS, format_score, score_log


def _cmd_score(args) -> int:
    import sys
    from pathlib import Path

    result = score_log(
        args.run,
        args.data,
        args.horizon_s,
        args.format,
        args.part,
        check=not args.no_check,
        integrator=args.integrator,
    )
    if json.loads((Path(args.run) / "model.json").read_text()).get("interrupted") is True:
        print(
            f"gpquad: warning: {args.run}: the run was interrupted; these are the equations "
            "found so far (the same `gpquad run` command resumes it)",
            file=sys.stderr,
        )
    print(json.dumps(result) if args.json else format_score(result))
    return 0


def register(subparsers) -> None:
    """Add `gpquad score`."""
    p = subparsers.add_parser("score", help="RSE of a run's equations flown over a flight log")
    p.add_argument("run", help="run folder")
    p.add_argument(
        "--data",
        required=True,
        help="log: ulog2csv folder, .ulg, .bbl, .bin, .csv/.parquet (an export or generic file)",
    )
    p.add_argument("--format", help="log format (default: from the path)")
    p.add_argument("--horizon-s", type=float, default=7.0, help="window length, s (default 7)")
    p.add_argument(
        "--part",
        default="auto",
        choices=PARTS,
        help="all windows, or the held-out part (auto: the held-out part of a log "
        "the run trained on, else all)",
    )
    p.add_argument(
        "--integrator",
        default="own",
        choices=INTEGRATORS,
        help="own: the run's scheme; rk4: also the equations flown by RK4 with 8 "
        "steps per sample, the continuous-time RSE beside the run's own",
    )
    p.add_argument("--json", action="store_true", help="one JSON object")
    p.add_argument(
        "--no-check", action="store_true", help="score segments that fail the integration check too"
    )
    p.set_defaults(func=_cmd_score)


def _cmd_export(args) -> int:
    from gpquad.data.export import export_flights, write_export

    flights, dropped = export_flights(args.path, args.format, args.config)
    for d in dropped:
        print(f"warning: {d}")
    out = write_export(flights, args.out)
    print(
        f"wrote {len(flights)} segment(s), {sum(len(f) for f in flights)} samples, inputs "
        f"{', '.join(flights[0].input_names)}, to {out}"
    )
    return 0


def register_export(sub) -> None:
    """Add `gpquad data export` to the `data` sub-commands."""
    p = sub.add_parser("export", help="engine-ready data after the pipeline, as CSV/Parquet")
    p.add_argument("path", help="log: ulog2csv folder, .ulg, .bbl/.BFL, .bin, .csv/.parquet")
    p.add_argument("--out", required=True, help="output .csv or .parquet")
    p.add_argument("--format", help="log format (default: from the path)")
    p.add_argument("--config", help="experiment TOML whose [data] settings to use")
    p.set_defaults(func=_cmd_export)
