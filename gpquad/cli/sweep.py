"""Command line: gpquad sweep | report (picked up by gpquad.cli.commands's extension hook)."""

from __future__ import annotations

import sys
from pathlib import Path


def _cmd_sweep(args) -> int:
    from gpquad.study.config import load_config, override
    from gpquad.study.progress import SweepProgress
    from gpquad.study.sweep import default_out, run_sweep

    cfg = override(
        load_config(args.config), targets=args.target, iterations=args.iterations, seed=args.seed
    )
    out = Path(args.out) if args.out else default_out(cfg)
    mode = "jsonl" if args.jsonl else "quiet" if args.quiet else "live"
    if not cfg.output.progress and mode == "live":
        mode = "quiet"
    try:
        result = run_sweep(
            cfg,
            out,
            runs=args.runs,
            jobs=args.jobs,
            backend=args.backend,
            address=args.address,
            progress=SweepProgress(mode),
            assemble=not args.no_assemble,
        )
    except KeyboardInterrupt:
        print(
            f"\ngpquad: interrupted; finished runs and checkpoints are in {out}; the same "
            "command resumes the sweep",
            file=sys.stderr,
        )
        return 130
    if mode != "jsonl":
        print(
            f"sweep folder: {out}"
            + (f"\nbest full model: {result['model']}" if result["model"] else "")
        )
    return 0


def _cmd_report(args) -> int:
    from gpquad.report.builder import make_report

    written = make_report(
        Path(args.folder), reassemble=args.reassemble, formats=tuple(args.format or ("png", "pdf"))
    )
    for path in written:
        print(path)
    return 0


def register(subparsers) -> None:
    """Add the `sweep` and `report` sub-commands."""
    sw = subparsers.add_parser(
        "sweep",
        help="identify every equation N times in parallel (resumable), then assemble full models",
    )
    sw.add_argument("config", help="experiment TOML file ([sweep] section)")
    sw.add_argument("--runs", type=int, help="repetitions per equation (default sweep.runs)")
    sw.add_argument("--jobs", type=int, default=1, help="parallel runs (default 1)")
    sw.add_argument(
        "--backend",
        choices=["loky", "dask"],
        default="loky",
        help="joblib backend: loky (one machine) or dask (a Dask cluster)",
    )
    sw.add_argument(
        "--address",
        help="Dask scheduler address (with --backend dask; default: "
        "a LocalCluster of --jobs workers on 127.0.0.1); --out must then be on a "
        "filesystem the workers share",
    )
    sw.add_argument(
        "--out",
        help="sweep folder (default output.dir/<name>-sweep-seed<S>); "
        "the same command again resumes it",
    )
    sw.add_argument("--target", action="append", help="target equation (repeatable)")
    sw.add_argument("--iterations", type=int, help="coevolution iterations per run")
    sw.add_argument("--seed", type=int, help="master seed")
    sw.add_argument("--no-assemble", action="store_true", help="runs only, no full models")
    mode = sw.add_mutually_exclusive_group()
    mode.add_argument("--quiet", action="store_true", help="warnings and the summary only")
    mode.add_argument("--jsonl", action="store_true", help="one JSON object per event on stdout")
    sw.set_defaults(func=_cmd_sweep)

    rep = subparsers.add_parser("report", help="figures and tables of a finished sweep or run")
    rep.add_argument("folder", help="a sweep or run folder")
    rep.add_argument(
        "--reassemble", action="store_true", help="rebuild the full models before plotting"
    )
    rep.add_argument(
        "--format",
        action="append",
        choices=["png", "pdf"],
        help="figure formats (default png and pdf)",
    )
    rep.set_defaults(func=_cmd_report)
