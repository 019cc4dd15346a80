"""Sub-commands `gpquad baseline ga-gradient|ga|pem CONFIG --out DIR` and `gpquad compare`."""

from __future__ import annotations

import time
from pathlib import Path

from gpquad.errors import GpquadError

METHODS = ("ga-gradient", "ga", "pem")


def _cmd_baseline(args) -> int:
    out = (
        Path(args.out)
        if args.out
        else Path("results") / (f"baseline-{args.method}-{time.strftime('%Y%m%d-%H%M%S')}")
    )
    if args.method == "pem":
        from gpquad.baselines.pem_config import load_pem_config
        from gpquad.baselines.pem_run import run_pem_baseline

        run_pem_baseline(load_pem_config(args.config), out)
    else:
        from gpquad.baselines.ga_config import load_ga_config
        from gpquad.baselines.ga_run import run_ga_baseline

        run_ga_baseline(load_ga_config(args.config), args.method, out, study=not args.no_study)
    print(f"Run folder: {out}")
    return 0


def _cmd_compare(args) -> int:
    import csv

    from gpquad.models.scoring import compare, format_table
    from gpquad.study.store import atomic_write_text

    rows = compare(args.runs, args.horizon, data_from=args.data_from)
    table = format_table(rows)
    print(table, end="")
    out = Path(args.out)
    atomic_write_text(out.with_suffix(".md"), table)
    fields = list(dict.fromkeys(k for r in rows for k in r))
    import io

    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=fields)
    writer.writeheader()
    writer.writerows(rows)
    atomic_write_text(out.with_suffix(".csv"), buf.getvalue())
    print(f"saved {out.with_suffix('.md')} and {out.with_suffix('.csv')}")
    unscored = [r for r in rows if r.get("note")]
    if unscored:
        first = unscored[0]
        raise GpquadError(
            f"{len(unscored)} of {len(rows)} runs could not be scored on common "
            f"data ({Path(first['run']).name}: {first['note']}); compare runs "
            "made on the same flights and inputs, or give --data-from",
            field="compare",
        )
    return 0


def register(subparsers) -> None:
    """Add `baseline` and `compare` to gpquad's command line."""
    b = subparsers.add_parser("baseline", help="fit a parametric baseline (GA or PEM)")
    b.add_argument("method", choices=METHODS)
    b.add_argument("config", help="baseline TOML (experiments/baseline_*.toml)")
    b.add_argument("--out", help="run folder (default results/baseline-<method>-<time>)")
    b.add_argument(
        "--no-study", action="store_true", help="GA: skip the 20-seed convergence comparison"
    )
    b.set_defaults(func=_cmd_baseline)

    c = subparsers.add_parser("compare", help="score run folders (GP or baseline) in one table")
    c.add_argument("runs", nargs="+", help="run folders")
    c.add_argument("--horizon", type=int, default=100, help="window length, samples")
    c.add_argument("--data-from", help="run folder whose scoring data to use (default: first)")
    c.add_argument("--out", default="comparison", help="table path stem (.md and .csv)")
    c.set_defaults(func=_cmd_compare)
