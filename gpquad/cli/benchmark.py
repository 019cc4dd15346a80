"""`gpquad benchmark`: the head-to-head identification benchmark from the command line.

    gpquad benchmark [SCENARIO ... | CONFIG.toml] [--peers zero,ols,sindy,operon] [--seeds N]
                     [--out DIR] [--jobs J] [--horizons 1,7,30] [--skip-gpquad]
    gpquad benchmark --report --out DIR [SCENARIO ...]

Writes DIR/benchmark.md (tables), DIR/results.json (aggregate, settings, provenance),
DIR/figures/<scenario>.png and DIR/cells/ (one file per finished cell; rerunning the same
command resumes), DIR/fidelity/ (each cell's equations flown by RK4, 8 steps per sample;
`--report` recomputes them from the stored cells of any benchmark folder, fitting nothing).
Every bad argument is one line and exit code 2, before any long work.
"""

from __future__ import annotations

from pathlib import Path

from gpquad.errors import GpquadError


def parse_list(text: str, field: str) -> list[str]:
    items = [x.strip() for x in text.split(",") if x.strip()]
    if not items:
        raise GpquadError("give a comma-separated list", field=field)
    return items


def parse_horizons(text: str) -> list[float]:
    try:
        values = [float(x) for x in parse_list(text, "--horizons")]
    except ValueError:
        raise GpquadError(
            f"'{text}' is not a list of seconds such as 1,7,30", field="--horizons"
        ) from None
    if min(values) <= 0:
        raise GpquadError("horizons must be > 0 s", field="--horizons")
    return values


def check_arguments(args) -> tuple[list[str], list[str], list[float]]:
    """Scenario names, peers and horizons, or a GpquadError naming the bad argument."""
    from gpquad.benchmark.peers import PEERS
    from gpquad.benchmark.scenarios import SCENARIOS

    names = list(args.scenarios) or list(SCENARIOS)
    for name in names:
        if name.endswith(".toml"):
            if not Path(name).is_file():
                raise GpquadError("config file not found", source=name)
            from gpquad.study.config import load_config

            load_config(name)  # a bad config fails here, before any work
        elif name not in SCENARIOS:
            raise GpquadError(
                f"unknown scenario '{name}'; choose from {list(SCENARIOS)} or give a config .toml",
                field="scenario",
            )
    if len(set(names)) != len(names):
        raise GpquadError("a scenario is named twice", field="scenario")
    peer_names = parse_list(args.peers, "--peers")
    bad = [p for p in peer_names if p not in PEERS]
    if bad:
        raise GpquadError(f"unknown peer {bad[0]!r}; choose from {list(PEERS)}", field="--peers")
    if args.seeds < 1:
        raise GpquadError("must be >= 1", field="--seeds")
    if args.jobs < 1:
        raise GpquadError("must be >= 1", field="--jobs")
    return names, peer_names, parse_horizons(args.horizons)


def write_report(out: Path, info: dict) -> dict:
    """Aggregate the cells into results.json and benchmark.md, and draw the figures."""
    from gpquad.benchmark import fidelity, fidelity_table, loop_gains, table
    from gpquad.benchmark.figures import scenario_figure
    from gpquad.benchmark.paired import paired, paired_markdown
    from gpquad.benchmark.runner import collect
    from gpquad.study.store import atomic_write_text, write_json

    found = collect(out, info)
    agg = table.aggregate(found)
    figures = {k: v for k, v in info.items() if k == "figures"}
    summary = {k: v for k, v in info.items() if k not in ("figures",)}
    pairs = paired(found)
    fid = fidelity_table.aggregate(fidelity.load(out, found))
    gains = loop_gains.benchmark_gains(info, found)
    write_json(
        out / "results.json",
        {
            "results": agg,
            "paired": pairs,
            "fidelity": fid,
            "loop_gains": gains,
            "benchmark": summary,
        },
    )
    head = [
        f"gpquad benchmark, git {info['git_revision']}, engine settings from "
        f"{info['engine_config']}; gpquad and operon: mean over seeds "
        f"{info['seeds'].get('gpquad')} (min-max); zero, ols, sindy are deterministic.",
        "",
    ]
    if info["skipped_scenarios"] or info["skipped_peers"]:
        head += [f"Skipped: {why}" for why in info["skipped_scenarios"].values()]
        head += [f"Skipped peer {p}: {why}" for p, why in info["skipped_peers"].items()]
        head.append("")
    head += ["## Summary", "", table.summary_markdown(agg)]
    if pairs:
        head += [
            "## Where a peer diverged: gpquad on the windows the peer flew",
            "",
            paired_markdown(pairs),
        ]
    if fid:
        head += [
            "## Fidelity: the printed equations flown by RK4, 8 steps per sample",
            "",
            *(
                [f"Flown again by git {info['fidelity_git_revision']} (`--report`).", ""]
                if info.get("fidelity_git_revision")
                else []
            ),
            fidelity_table.markdown(fid),
        ]
    if gains:
        head += [
            "## Loop gains implied by the roll and pitch equations (rotorpy angle mode)",
            "",
            "Linearised at hover (docs/guide.md, gpquad.benchmark.loop_gains); in brackets "
            "the controller's gain and the relative error.",
            "",
            loop_gains.markdown(gains),
        ]
    profile = table.profile_markdown(found)
    if profile:
        head += [
            "## Where gpquad's fit time went (mean over seeds)",
            "",
            "searches: each equation's search, summed (they run side by side, one per "
            "process); the finishing steps run after them, each its wall time.",
            "",
            profile,
        ]
    phases = table.phase_markdown(found)
    if phases:
        head += [
            "The searches' phases, each summed over a fit's searches:",
            "",
            phases,
        ]
    head += ["## Per state", "", table.markdown(agg)]
    atomic_write_text(out / "benchmark.md", "\n".join(head))
    for name in info["scenarios"]:
        scenario_figure(name, figures["figures"].get(name), found, out)
    return agg


def _cmd_benchmark(args) -> int:
    from gpquad.benchmark.runner import run_benchmark

    out = Path(args.out)
    if args.report:
        from gpquad.benchmark.runner import report_benchmark

        info = report_benchmark(out, [n for n in args.scenarios])
        write_report(out, info)
        print((out / "benchmark.md").read_text())
        return 0
    names, peer_names, horizons = check_arguments(args)
    info = run_benchmark(
        names,
        peer_names,
        args.seeds,
        out,
        jobs=args.jobs,
        horizons_s=horizons,
        with_gpquad=not args.skip_gpquad,
        engine=args.engine,
    )
    write_report(out, info)
    print((out / "benchmark.md").read_text())
    print(
        f"tables: {out / 'benchmark.md'}; JSON: {out / 'results.json'}; figures: {out / 'figures'}"
    )
    return 0


def register(subparsers) -> None:
    b = subparsers.add_parser(
        "benchmark",
        help="head-to-head identification benchmark: gpquad "
        "against peers, flown and scored the same way (resumable)",
    )
    b.add_argument(
        "scenarios",
        nargs="*",
        help="scenario names or an experiment .toml (default: every scenario)",
    )
    b.add_argument(
        "--peers",
        default="zero,ols,sindy,operon",
        help="comma-separated peers (default zero,ols,sindy,operon)",
    )
    b.add_argument("--seeds", type=int, default=3, help="gpquad and operon seeds 1..N (default 3)")
    b.add_argument(
        "--out",
        default="results/benchmark",
        help="benchmark folder (default results/benchmark); the same command resumes",
    )
    b.add_argument("--jobs", type=int, default=1, help="parallel cells (default 1)")
    b.add_argument(
        "--engine",
        default=None,
        metavar="CONFIG",
        help="a TOML config whose [evolution] and [vehicle] gpquad uses (default: "
        "gpquad's defaults, the recommended engine)",
    )
    b.add_argument("--horizons", default="1,7,30", help="prediction horizons in s (default 1,7,30)")
    b.add_argument(
        "--skip-gpquad",
        action="store_true",
        help="run the peers only (gpquad's finished cells in --out are still reported)",
    )
    b.add_argument(
        "--report",
        action="store_true",
        help="fit nothing: re-read the finished cells of --out (any gpquad version), fly "
        "their printed equations for the fidelity column and rewrite the report "
        "(scenarios: only these of the folder's)",
    )
    b.set_defaults(func=_cmd_benchmark)
