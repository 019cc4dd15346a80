"""`gpquad data check PATH`: what a log holds, whether it can be identified from, and a plot.

Prints the signals found (rows, rate, time span, NaN rows, gaps), which state variables are
measured, the in-flight segments, and the integration-check table; writes a quick-look PNG of
states and inputs. Exits non-zero with a one-line reason when the data cannot be used.
"""

from __future__ import annotations

import dataclasses
import sys
import warnings
from pathlib import Path

import numpy as np

from gpquad._lazy import imported
from gpquad.errors import GpquadError

#: Formats whose readers give a LogTable (signals, segments) before the pipeline.
_LOG_READERS = {
    "px4-csv": ("gpquad.data.px4", "read_px4_folder_log"),
    "ulog": ("gpquad.data.ulog", "read_ulog_log"),
    "table": ("gpquad.data.table", "table_log"),
    "ardupilot": ("gpquad.data.ardupilot", "ardupilot_log_table"),
}


def _log_tables(path: Path, fmt: str, data) -> list:
    if fmt == "betaflight":
        from gpquad.data.betaflight import read_betaflight_logs

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            tables, skipped = read_betaflight_logs(path, data)
        for s in skipped:
            warnings.warn(s, stacklevel=2)  # grouped by kind (gpquad.cli.commands.WarningLines)
        return tables
    module, name = _LOG_READERS[fmt]
    return [imported(module, name)(path, data)]


def describe_log(log) -> str:
    """Signals, measured states and in-flight time of a LogTable, as text."""
    from gpquad.data.pipeline import is_measured

    t = log.table["t"].to_numpy()
    lines = [
        f"log {log.name}: {t[-1] - t[0]:.1f} s ({t[0]:.2f}..{t[-1]:.2f} s on the log clock),"
        f" resampled to {log.rate_hz:g} Hz; {(~log.valid).sum()} samples in gaps; "
        f"{log.in_flight.sum() / log.rate_hz:.1f} s in flight",
        f"  {'signal':<24} {'rows':>7} {'rate Hz':>8} {'span s':>17} {'NaN rows':>8} {'gaps':>5}",
    ]
    seen = set()
    for s in log.streams:
        key = (s["stream"], s["rows"], s["start_s"])
        if key in seen:
            continue
        seen.add(key)
        lines.append(
            f"  {s['stream']:<24} {s['rows']:>7} {s['rate_hz']:>8.1f} "
            f"{s['start_s']:>8.2f}..{s['stop_s']:<8.2f} {s['nan_rows']:>8} "
            f"{s['gaps']:>5}{'' if s['required'] else '  (optional)'}"
        )
    groups: dict[str, list[str]] = {}
    for k, v in log.measured.items():
        groups.setdefault(v, []).append(k)
    for label, real in (("real signals", True), ("NOT measured", False)):
        parts = [f"{', '.join(ks)}: {v}" for v, ks in groups.items() if is_measured(v) == real]
        if parts:
            lines.append(f"  {label}: " + "; ".join(parts))
    lines.append(
        f"  inputs: {', '.join(log.input_names)}; other columns: "
        f"{', '.join(c for c in log.table.columns if c not in ('t', *log.input_names))}"
    )
    if log.levels:
        from gpquad.data.levels import describe_levels

        used = ", ".join(f"{n} = {c}" for n, c in log.input_columns.items())
        lines.append(f"  input levels (data.inputs; used: {log.input_level}: {used}):")
        lines.extend(describe_levels(log.levels, log.input_level, log.units))
    lines.extend(f"  note: {n}" for n in log.notes)
    return "\n".join(lines)


def describe_flights(flights) -> str:
    lines = [
        f"in-flight segments after the pipeline: {len(flights)}, "
        f"{sum(len(f) for f in flights)} samples at {1 / flights[0].dt:.4g} Hz "
        f"({sum(len(f) for f in flights) * flights[0].dt:.1f} s)"
    ]
    for f in flights:
        lines.append(f"  {f.name:<32} {f.t[0]:>8.2f}..{f.t[-1]:<8.2f} s  {len(f):>6} samples")
    steps = flights[0].meta.get("pipeline")
    if steps:
        lines.append("  pipeline: " + "; ".join(steps))
    return "\n".join(lines)


def _status(flight, state: str) -> str:
    """ "" for a measured state, else a short note for the legend: not measured, derived."""
    from gpquad.data.pipeline import is_measured

    description = flight.meta.get("measured", {}).get(state)
    if description is None or is_measured(description):
        return ""
    return "derived" if description.startswith("derived") else "not measured"


def _is_thrust(name: str) -> bool:
    return name.endswith("_T") or "thrust" in name.lower() or name in ("throttle", "T")


def quick_look(flights, path: Path, title: str) -> Path:
    """PNG of attitude, heading, body velocity, rates and inputs of the flights against log
    time: psi unwrapped on its own axis; unmeasured or derived signals dashed grey and
    labelled so; thrust-like inputs apart from the others; units on every axis."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from gpquad.engine.kernels.quaternion import euler_array
    from gpquad.study.store import atomic_write_bytes

    fig, axes = plt.subplots(6, 1, figsize=(11, 12), sharex=True)
    panels = (
        (axes[0], ("phi", "theta"), "roll, pitch [deg]"),
        (axes[1], ("psi",), "heading psi, unwrapped [deg]"),
        (axes[2], ("u", "v", "w"), "body velocity [m/s]"),
        (axes[3], ("p", "q", "r"), "body rates [rad/s]"),
    )
    for k, f in enumerate(flights):
        eul = np.degrees(euler_array(np.ascontiguousarray(f.quat)))
        eul[:, 2] = np.degrees(np.unwrap(np.radians(eul[:, 2])))
        values = {
            "phi": eul[:, 0],
            "theta": eul[:, 1],
            "psi": eul[:, 2],
            **{s: f.vel[:, j] for j, s in enumerate("uvw")},
            **{s: f.rates[:, j] for j, s in enumerate("pqr")},
        }
        for ax, names, _ in panels:
            for j, name in enumerate(names):
                note = _status(f, name)
                style = (
                    dict(lw=0.7, color=f"C{j}") if not note else dict(lw=0.7, color="0.6", ls="--")
                )
                label = (f"{name} ({note})" if note else name) if k == 0 else None
                ax.plot(f.t, values[name], label=label, **style)
        for j, n in enumerate(f.input_names):
            ax = axes[5] if _is_thrust(n) else axes[4]
            ax.plot(f.t, f.inputs[:, j], lw=0.7, color=f"C{j}", label=n if k == 0 else None)
    for ax, _, label in panels:
        ax.set_ylabel(label, fontsize=8)
    axes[4].set_ylabel("attitude / rate inputs\n[input units]", fontsize=8)
    axes[5].set_ylabel("thrust input\n[input units]", fontsize=8)
    for ax in axes:
        if ax.get_legend_handles_labels()[0]:
            ax.legend(loc="upper right", fontsize=7, ncol=4)
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("log time [s]")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    import io

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    plt.close(fig)
    atomic_write_bytes(path, buf.getvalue())
    return path


def run_check(path, fmt: str | None = None, config=None, plot=None, out=print) -> int:
    """The `data check` command; returns 0 when the data is usable, raises GpquadError if not."""
    from gpquad.data.integration_check import integration_check, screen_segments
    from gpquad.data.io import READERS, resolve_log
    from gpquad.data.pipeline import flights_from_log

    path, cfg, data = resolve_log(path, fmt, config)
    fmt = data.format
    out(f"gpquad data check: {path} (format {fmt})")
    if fmt in _LOG_READERS or fmt == "betaflight":
        flights, errors = [], []
        for log in _log_tables(path, fmt, data):
            out(describe_log(log))
            try:
                flights.extend(flights_from_log(log, data))
            except GpquadError as exc:
                errors.append((len(log.table), exc))
                out(f"  no usable flight: {exc}")
        if not flights:  # the reason of the longest log, the one most likely meant to fly
            raise max(errors, key=lambda e: e[0])[1]
    elif fmt in READERS:
        flights = READERS[fmt](path, data)
    else:
        raise GpquadError(
            f"unknown format '{fmt}'; known: {sorted(READERS)}", source=str(path), field="--format"
        )
    out(describe_flights(flights))
    png = (
        Path(plot)
        if plot
        else Path(cfg.output.dir) / "checks" / f"{path.stem or path.name}_check.png"
    )
    try:
        kept, dropped, check = screen_segments(
            flights, data.check_steps, data.check_max_rse, source=str(path)
        )
    except GpquadError:  # nothing passes: the pooled table, the figure, the one-line reason
        out(integration_check(flights, data.check_steps, data.check_max_rse).table())
        quick_look(
            flights, png, f"{path.name}: {len(flights)} segment(s), integration check FAILED"
        )
        out(f"quick-look plot: {png}")
        raise
    out(check.table())
    if dropped:
        out(
            f"{len(kept)} segment(s) pass the integration check and are used; "
            f"{len(dropped)} dropped (listed after the verdict)"
        )
    quick_look(
        kept, png, f"{path.name}: {len(kept)} segment(s), {'PASS' if check.passed else 'FAIL'}"
    )
    out(f"quick-look plot: {png}")
    return 0


def _cmd_check(args) -> int:
    return run_check(args.path, args.format, args.config, args.plot)


def register(subparsers) -> None:
    """Add `gpquad data check`."""
    data = subparsers.add_parser("data", help="inspect and check flight logs")
    sub = data.add_subparsers(dest="data_command", required=True)
    check = sub.add_parser("check", help="signals, segments, integration check, quick-look PNG")
    check.add_argument("path", help="log: ulog2csv folder, .ulg, .bbl/.BFL, .csv/.parquet")
    check.add_argument(
        "--format", help="px4-csv | ulog | betaflight | table | generic (default: from the path)"
    )
    check.add_argument("--config", help="experiment TOML whose [data] settings to use")
    check.add_argument(
        "--plot",
        help="quick-look PNG path (default "
        "results/checks/<name>_check.png; written also when the check fails)",
    )
    check.set_defaults(func=_cmd_check)
    _register_align(sub)
    from gpquad.cli.score import register_export

    register_export(sub)


def run_align(
    path_a,
    path_b,
    signals=("p", "q", "r"),
    fmt_a=None,
    fmt_b=None,
    config=None,
    max_lag_s=None,
    out=print,
) -> int:
    """The `data align` command: clock offset of log B relative to log A, and residual RMSE."""
    from gpquad.data.align import estimate_offset
    from gpquad.data.io import guess_format
    from gpquad.study.config import Config, load_config

    cfg = load_config(config) if config else Config()
    columns = []
    for path, fmt in ((Path(path_a), fmt_a), (Path(path_b), fmt_b)):
        if not path.exists():
            raise GpquadError("no such file or folder", source=str(path))
        fmt = fmt or guess_format(path, allow_generic=False)
        if fmt not in _LOG_READERS and fmt != "betaflight":
            raise GpquadError(
                f"alignment reads px4-csv, ulog, betaflight or table logs, not '{fmt}'",
                source=str(path),
                field="--format",
            )
        data = dataclasses.replace(cfg.data, format=fmt, segment="none")
        logs = _log_tables(path, fmt, data)
        log = max(logs, key=lambda lg: len(lg.table))
        missing = [s for s in signals if s not in log.table.columns]
        if missing:
            raise GpquadError(
                f"no signal {missing} in the log; choose --signal from "
                f"{sorted(c for c in log.table.columns if c != 't')}",
                source=str(path),
                field="--signal",
            )
        ok = log.valid
        columns.append((log.table["t"].to_numpy()[ok], log.table[list(signals)].to_numpy()[ok]))
    (ta, xa), (tb, xb) = columns
    res = estimate_offset(ta, xa, tb, xb, rate_hz=cfg.data.resample_hz, max_lag_s=max_lag_s)
    out(
        f"clock offset (B - A): {res.offset_s:+.4f} s; correlation {res.correlation:.3f}; "
        f"residual RMSE of {', '.join(signals)}: {res.rmse:.4g}; overlap {res.overlap_s:.1f} s"
    )
    if not res.correlation >= WEAK_CORRELATION:
        print(
            f"gpquad: warning: correlation {res.correlation:.2f} is below "
            f"{WEAK_CORRELATION}: the offset is not reliable; choose a --signal that both logs "
            "excite, or a longer overlap",
            file=sys.stderr,
        )
    return 0


WEAK_CORRELATION = 0.5  # below it the correlation peak does not identify an offset


def _cmd_align(args) -> int:
    return run_align(
        args.log_a,
        args.log_b,
        tuple(args.signal.split(",")),
        args.format_a,
        args.format_b,
        args.config,
        args.max_lag,
    )


def _register_align(sub) -> None:
    align = sub.add_parser("align", help="clock offset of two logs by cross-correlation")
    align.add_argument("log_a", help="reference log (its clock is kept)")
    align.add_argument("log_b", help="log on another clock")
    align.add_argument(
        "--signal", default="p,q,r", help="shared signals, comma-separated columns (default p,q,r)"
    )
    align.add_argument("--format-a", help="format of log A (default: from the path)")
    align.add_argument("--format-b", help="format of log B (default: from the path)")
    align.add_argument("--config", help="experiment TOML whose [data] settings to use")
    align.add_argument("--max-lag", type=float, help="largest offset searched (s)")
    align.set_defaults(func=_cmd_align)
