"""gpquad command line: run, simulate, export, fly, bench; data, baseline, compare, sweep..."""

from __future__ import annotations

import argparse
import errno
import json
import os
import sys
from pathlib import Path

from gpquad.cli.exports import cmd_export, cmd_fly
from gpquad.cli.parsing import EXAMPLES, Parser, Version, WarningLines, add_examples
from gpquad.errors import GpquadError


def _import_plotting() -> None:
    import gpquad.report.plotting  # noqa: F401


def _cmd_run(args) -> int:
    from gpquad.study import workers
    from gpquad.study.config import load_config, override

    cfg = override(
        load_config(args.config),
        files=args.data,
        targets=args.target,
        iterations=args.iterations,
        seed=args.seed,
        out=None,
    )
    if args.jobs is not None and args.jobs < 1:
        raise GpquadError(f"must be >= 1, got {args.jobs}", field="--jobs")
    jobs = workers.default_jobs() if args.jobs is None else args.jobs
    n_targets = len(cfg.evolution.targets)
    from gpquad.study.runner import default_run_dir, run_experiment

    pooled = jobs > 1 and n_targets > 1
    if pooled:  # they warm up while the rest loads
        workers.start(workers.processes(jobs, n_targets))
    run_dir = Path(args.out) if args.out else default_run_dir(cfg)

    def load_plotting() -> None:  # in a thread, on a core the searches leave idle
        import threading

        threading.Thread(target=_import_plotting, daemon=True).start()

    if not args.no_figures and not pooled:  # the searches run in this process, one at a time
        load_plotting()
    figures: list[Path] = []

    def searched(folder) -> None:
        workers.release()  # they exit while the model is finished

    def draw(model, dataset) -> None:
        from gpquad.report.builder import make_run_report

        figures.extend(make_run_report(run_dir, formats=("png",), dataset=dataset))

    try:
        model = run_experiment(
            cfg,
            run_dir,
            progress=not args.quiet,
            jobs=jobs,
            after=None if args.no_figures else draw,
            searched=searched,
            idle=load_plotting if pooled and not args.no_figures else None,
        )
    except KeyboardInterrupt:
        return 130
    finally:  # on an error (bad data, say) no waiting for the workers' warm-up at exit
        workers.release(kill=True)
    print(
        "\nDiscovered equations (inputs minus trim):"
        if any(model.trim.values())
        else "\nDiscovered equations:"
    )
    print(model)
    if any(model.trim.values()):
        print("\nThe same in the log's raw inputs:")
        print(model.text(raw=True))
    if figures:
        print(f"\nFigures: {', '.join(str(f) for f in figures)}")
    print(f"\nRun folder: {run_dir}")
    return 0


def _cmd_simulate(args) -> int:
    from gpquad.data.flight import write_flight_file
    from gpquad.data.simulator import simulate
    from gpquad.study.config import load_config

    cfg = load_config(args.config) if args.config else None
    if cfg is None:
        from gpquad.study.config import Config

        cfg = Config()
    flight = simulate(cfg.simulator, cfg.data.inputs)
    path = write_flight_file(flight, args.out)
    print(f"wrote {len(flight)} samples at {1 / flight.dt:.4g} Hz to {path}")
    return 0


def _cmd_bench(args) -> int:
    from gpquad.engine.bench import format_report, run_benchmark

    result = run_benchmark(full=args.full)
    print(json.dumps(result) if args.json else format_report(result))
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(
        prog="gpquad",
        description="Discover multirotor acceleration equations from flight logs "
        "by coevolutionary genetic programming.",
        epilog=EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action=Version)
    sub = parser.add_subparsers(dest="command", parser_class=Parser)

    run = sub.add_parser(
        "run",
        help="identify equations from a config",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="examples:\n  gpquad run experiments/quickstart.toml\n"
        "  gpquad run my.toml --data a.ulg --data b.ulg --seed 2 --out res/ab\n"
        "  gpquad run my.toml --target p_dot --iterations 3   (a quick look)",
    )
    run.add_argument("config", help="experiment TOML file")
    run.add_argument(
        "--data", action="append", help="flight file (repeatable); replaces data.files"
    )
    run.add_argument(
        "--target", action="append", help="target equation (repeatable; default all six)"
    )
    run.add_argument("--iterations", type=int, help="coevolution iterations per target")
    run.add_argument("--seed", type=int, help="master seed")
    run.add_argument("--out", help="run folder (default results/<name>-seed<S>-<time>)")
    run.add_argument("--quiet", action="store_true", help="no progress lines")
    run.add_argument(
        "--jobs",
        type=int,
        help="cores to use: the equations are searched in up to this many processes, one "
        "per equation; a search with cores to spare fits its final choice's candidates in "
        "threads on them, and the finishing steps use this many threads (the same results "
        "for any value; default every core this process may use; 1, or a run of one "
        "equation, also checkpoints within an equation, every iteration)",
    )
    run.add_argument(
        "--no-figures",
        action="store_true",
        help="skip the report figures (convergence, prediction) in RUN/report/",
    )
    run.set_defaults(func=_cmd_run)

    sim = sub.add_parser("simulate", help="write the reference simulator's flight to a file")
    sim.add_argument("config", nargs="?", help="experiment TOML ([simulator] section)")
    sim.add_argument("--out", required=True, help="output .csv or .parquet")
    sim.set_defaults(func=_cmd_simulate)

    from gpquad.models.exports import FORMATS

    exp = sub.add_parser(
        "export",
        help="a run's model as text, LaTeX, sympy, python, C or casadi",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Every format states dt (delays are in samples of dt), the lags and the "
        "trim; python, c and casadi fly as `gpquad fly`.\nformats:\n"
        + "\n".join(f"  {f.name:9s}{f.about}" for f in FORMATS.values()),
        epilog="examples:\n  gpquad export results/run --format text\n"
        "  gpquad export results/run --format python --out model.py\n"
        "  gpquad export results/run --format c --out model.c   (writes model.c and model.h)\n"
        "  cc -std=c99 -O2 -c model.c",
    )
    exp.add_argument("run", help="run folder or model.json")
    exp.add_argument("--format", choices=list(FORMATS), default="text")
    exp.add_argument("--out", help="file to write (c: PATH.c and PATH.h); default: print")
    exp.add_argument(
        "--raw-inputs",
        action="store_true",
        help="text, latex, sympy: write equations in untrimmed inputs",
    )
    exp.set_defaults(func=cmd_export)

    fly = sub.add_parser("fly", help="fly a run's equations with given inputs")
    fly.add_argument("run", help="run folder or model.json")
    fly.add_argument("--inputs", required=True, help="CSV/Parquet with the input columns")
    fly.add_argument("--out", required=True, help="flight file to write (.csv or .parquet)")
    fly.add_argument("--initial", help="initial state phi,theta,psi,u,v,w,p,q,r (default 0)")
    fly.add_argument(
        "--trimmed", action="store_true", help="the inputs are already trim-subtracted"
    )
    fly.add_argument(
        "--zero-missing",
        action="store_true",
        help="fly targets the run has no equation for as zero acceleration",
    )
    fly.set_defaults(func=cmd_fly)

    bench = sub.add_parser("bench", help="fitness-kernel throughput and paper-scale timing")
    bench.add_argument("--json", action="store_true", help="one JSON object")
    bench.add_argument("--full", action="store_true", help="measure a whole 30-iteration run")
    bench.set_defaults(func=_cmd_bench)

    for register in _extensions():
        register(sub)
    add_examples(parser, [])
    return parser


def _extensions():
    """Sub-command groups contributed by other packages of gpquad (data, baselines, sweeps)."""
    registers = []
    for module, name in (
        ("gpquad.cli.data", "register"),
        ("gpquad.cli.baselines", "register"),
        ("gpquad.cli.sweep", "register"),
        ("gpquad.cli.score", "register"),
        ("gpquad.cli.control", "register"),
        ("gpquad.cli.physics", "register"),
        ("gpquad.cli.benchmark", "register"),
    ):
        try:
            mod = __import__(module, fromlist=[name])
        except ModuleNotFoundError as exc:
            if exc.name and module.startswith(exc.name):
                continue
            raise
        registers.append(getattr(mod, name))
    return registers


def entry() -> None:
    """The `gpquad` command: main(), then the interpreter's own exit sequence up to the
    teardown of the modules, which it skips (numba, matplotlib and pandas: about half a
    second). First, as at any exit, the thread-level exit callbacks (the process pools' shut
    down and their worker processes joined), then the atexit handlers (joblib's temporary
    folders); every file is closed by then."""
    import atexit
    import threading

    code = main()
    threading._shutdown()
    atexit._run_exitfuncs()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


def main(argv=None) -> int:
    import warnings

    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 0
    from gpquad._machine import warn_if_late

    warn_if_late()  # started by a process that loaded numpy first
    lines = WarningLines()
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        warnings.showwarning = lines.show
        try:
            return _run(args)
        finally:
            lines.summary()


def _run(args) -> int:
    try:
        return int(args.func(args) or 0)
    except GpquadError as exc:
        return _fail(str(exc))
    except KeyboardInterrupt:
        print("\ngpquad: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # The reader of our output went away (`gpquad ... | head`): stop quietly, as Unix
        # tools do, and keep Python from complaining when it flushes stdout at exit.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141
    except OSError as exc:
        if exc.errno == errno.ENOSPC:
            return _fail(
                f"{exc.filename or 'a file'}: no space left on the device; free some "
                "and run the same command again"
            )
        if exc.filename is None:
            raise
        return _fail(
            f"{exc.filename}: {exc.strerror or exc}; check the path and that it is a "
            "writable folder (or a readable file)"
        )


def _fail(message: str) -> int:
    """The one top-level error path: one line on stderr, exit code 2."""
    try:
        one_line = " ".join(message.split("\n"))  # a message quoting a file stays one line
        print(f"gpquad: error: {one_line}", file=sys.stderr)
    except BrokenPipeError:
        pass
    return 2


if __name__ == "__main__":
    sys.exit(main())
