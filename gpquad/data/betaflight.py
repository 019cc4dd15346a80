"""Betaflight blackbox logs, .bbl / .BFL (format "betaflight"), decoded with orangebox 0.4.0.

A file holds one log per arming; every log is read (or only `data.log_index`, 1-based). A log
that cannot be decoded is skipped with a warning; a log whose clock jumps back or stops (a
damaged stretch) is split there. Signals and units:

- time: us -> s. gyroADC[0..2]: deg/s -> rad/s. accSmooth[0..2]: counts -> m/s^2 with the
  header's acc_1G. Betaflight's sensor axes are x forward, y left, z up (a resting
  accelerometer reads +1 g on z), i.e. FLU: they are turned into FRD (q and r change sign).
- rcCommand[0..2] (roll, pitch, yaw sticks, +-500) -> /500, the default u_R, u_P, u_Y;
  rcCommand[3] (throttle, 1000..2000 us) -> (x - 1000) / 1000, the default u_T. Sticks keep
  Betaflight's signs.
- setpoint[0..2] deg/s -> rad/s, turned into FRD like the gyro (p_sp, q_sp, r_sp: the
  set-points of p, q, r), setpoint[3] / 1000;
  axisP/I/D/F (PID terms, raw); motor[0..3] DShot -> (x - motorOutput[0]) /
  (motorOutput[1] - motorOutput[0]); vbatLatest in 0.01 V -> V. The header fields are kept in
  the log table's notes (firmware, looptime, motor protocol limits, rates).
- Betaflight logs no attitude and no velocity: the attitude is integrated from the gyro with
  the engine's integrator (starting level-corrected from the accelerometer's gravity at each
  segment start; it drifts), and u, v, w are reported as not measured (zero).
"""

from __future__ import annotations

import logging
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

from gpquad.data.flight import MAX_PLAUSIBLE_RATE, Flight, flip_body
from gpquad.data.levels import paper_names, resolve_inputs
from gpquad.data.pipeline import LogTable, flights_from_log
from gpquad.data.plausibility import runs
from gpquad.data.streams import Stream, in_flight_mask, resample
from gpquad.engine.kernels.integrator import body_accelerations, integrate
from gpquad.engine.kernels.quaternion import quat_from_euler
from gpquad.errors import GpquadError

G = 9.80665
HEADER_KEYS = (
    "Firmware revision",
    "Craft name",
    "looptime",
    "P interval",
    "motorOutput",
    "minthrottle",
    "maxthrottle",
    "acc_1G",
    "rates",
    "rc_rates",
    "gyro_lowpass_hz",
)


def _open(path: Path):
    from gpquad.extras import require

    Parser = require("orangebox", "reading Betaflight blackbox logs").Parser

    if not path.is_file():
        raise GpquadError("file not found", source=str(path))
    logging.getLogger("orangebox").setLevel(logging.ERROR)
    try:
        parser = Parser.load(str(path))
        count = parser.reader.log_count
    except Exception as exc:
        raise GpquadError(
            f"not a readable Betaflight blackbox log ({type(exc).__name__}: {exc})",
            source=str(path),
        ) from None
    if count < 1:
        raise GpquadError("no blackbox log in the file", source=str(path))
    return parser, count


def read_frames(path, index: int) -> tuple[pd.DataFrame, dict, str | None]:
    """Main frames of log `index` (1-based) as a numeric table, the header dict, and why the
    decoding stopped early (None when the log ended normally): a truncated or corrupt tail
    keeps the frames decoded before it."""
    parser, count = _open(Path(path))
    if not 1 <= index <= count:
        raise GpquadError(
            f"log {index} does not exist; the file has {count}",
            source=str(path),
            field="data.log_index",
        )
    parser.set_log_index(index)
    names = list(parser.field_names)
    rows, stop = [], None
    frames = parser.frames()
    while True:
        try:
            fr = next(frames)
        except StopIteration:
            break
        except Exception as exc:  # truncated or corrupt data: keep what was decoded
            stop = f"decoding stopped after {len(rows)} frames ({type(exc).__name__}: {exc})"
            break
        rows.append(fr.data[: len(names)])
    table = pd.DataFrame(rows, columns=names).apply(pd.to_numeric, errors="coerce")
    return table, dict(parser.headers), stop


def _column(df: pd.DataFrame, name: str, source: str) -> np.ndarray:
    if name not in df.columns:
        raise GpquadError(f"missing field '{name}' in the blackbox log", source=source, field=name)
    return df[name].to_numpy(dtype=float)


def _pieces(t: np.ndarray, max_gap_s: float) -> list[tuple[int, int]]:
    """[start, stop) row ranges between backward jumps, repeats and gaps of the clock."""
    steps = np.diff(t)
    cuts = np.flatnonzero((steps <= 0) | (steps > max_gap_s) | ~np.isfinite(steps)) + 1
    edges = np.concatenate([[0], cuts, [len(t)]])
    return [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:], strict=False) if b - a > 1]


def _overlapping(pieces: list[tuple[int, int]], t: np.ndarray) -> list[int]:
    """Pieces whose time span overlaps a longer piece's: one clock cannot run twice, so the
    shorter is garbage decoded from damaged bytes."""
    kept: list[tuple[float, float]] = []
    bad = []
    for k in sorted(range(len(pieces)), key=lambda k: -(pieces[k][1] - pieces[k][0])):
        a, b = pieces[k]
        lo, hi = t[a], t[b - 1]
        if any(lo < k_hi and k_lo < hi for k_lo, k_hi in kept):
            bad.append(k)
        else:
            kept.append((lo, hi))
    return sorted(bad)


def _gyro_attitude(table: pd.DataFrame, valid: np.ndarray, dt: float) -> np.ndarray:
    """Quaternions (N, 4) integrated from the gyro per valid run, levelled by the accelerometer."""
    rates = table[["p", "q", "r"]].to_numpy(dtype=float)
    acc = table[["ax", "ay", "az"]].to_numpy(dtype=float)
    quat = np.tile([1.0, 0.0, 0.0, 0.0], (len(table), 1))
    for a, b in runs(valid):
        if b - a < 2:
            continue
        f = acc[a : min(b, a + 25)].mean(axis=0)  # specific force in FRD: -g on z when level
        phi = np.arctan2(-f[1], -f[2])
        theta = np.arctan2(f[0], np.hypot(f[1], f[2]))
        q0 = np.array(quat_from_euler(phi, theta, 0.0))
        w = np.ascontiguousarray(rates[a:b])
        alpha = body_accelerations(np.zeros((b - a, 3)), w, dt)
        q, _, _, _ = integrate(q0, np.zeros(3), w[0].copy(), np.zeros(3), alpha, dt)
        quat[a:b] = q
    return quat


def _log_table(df: pd.DataFrame, headers: dict, data, source: str, name: str) -> LogTable:
    t = _column(df, "time", source) * 1e-6
    gyro = np.column_stack([_column(df, f"gyroADC[{i}]", source) for i in range(3)])
    peak = np.nanmax(np.abs(gyro)) if gyro.size else 0.0
    if np.deg2rad(peak) > MAX_PLAUSIBLE_RATE:
        raise GpquadError(
            f"gyro reaches {peak:.0f} deg/s: not a plausible gyro in deg/s",
            source=source,
            field="gyroADC[0]",
        )
    one_g = float(headers.get("acc_1G", 2048) or 2048)
    acc = np.column_stack([_column(df, f"accSmooth[{i}]", source) for i in range(3)]) * G / one_g
    rc = np.column_stack([_column(df, f"rcCommand[{i}]", source) for i in range(4)])
    sticks = np.column_stack([rc[:, :3] / 500.0, (rc[:, 3] - 1000.0) / 1000.0])
    streams = [
        Stream("gyroADC", t, flip_body(np.deg2rad(gyro)), ("p", "q", "r"), "state", source, "time"),
        Stream("accSmooth", t, flip_body(acc), ("ax", "ay", "az"), "state", source, "time"),
        Stream(
            "rcCommand",
            t,
            sticks,
            ("roll_stick", "pitch_stick", "yaw_stick", "throttle"),
            "hold",
            source,
            "time",
        ),
    ]
    extra = {}
    if all(f"setpoint[{i}]" in df for i in range(4)):
        sp = np.column_stack([df[f"setpoint[{i}]"].to_numpy(float) for i in range(4)])
        # rate set-points in FRD, like the gyro they command (Betaflight's PID compares them
        # in its own FLU axes)
        extra["setpoint"] = (
            np.column_stack([flip_body(np.deg2rad(sp[:, :3])), sp[:, 3] / 1000.0]),
            ("p_sp", "q_sp", "r_sp", "throttle_sp"),
        )
    lo, hi = (headers.get("motorOutput") or [0, 2047])[:2]
    motors = [c for c in (f"motor[{i}]" for i in range(8)) if c in df]
    if motors:
        extra["motor"] = (
            (df[motors].to_numpy(float) - lo) / (hi - lo),
            tuple(f"motor_{i}" for i in range(len(motors))),
        )
    pid = [c for c in df.columns if c.startswith(("axisP", "axisI", "axisD", "axisF"))]
    if pid:
        extra["pid"] = (df[pid].to_numpy(float), tuple(pid))
    if "vbatLatest" in df:
        extra["vbat"] = (df[["vbatLatest"]].to_numpy(float) / 100.0, ("vbat",))
    available = [c for st in streams for c in st.columns] + [
        c for _, cs in extra.values() for c in cs
    ]
    supported = {"sticks": paper_names("pitch_stick", "roll_stick", "yaw_stick", "throttle")}
    if "setpoint" in extra:
        supported["rates"] = paper_names("q_sp", "p_sp", "r_sp", "throttle_sp")
    if "motor" in extra and len(extra["motor"][1]) >= 4:
        supported["motors"] = {m: m for m in extra["motor"][1][:4]}
    inputs, chosen = resolve_inputs(data, supported, available, source)
    for key, (values, cols) in extra.items():
        used = bool(set(cols) & set(inputs.values()))  # an input: NaN rows are gaps
        if not used:
            values = np.where(np.isfinite(values), values, 0.0)
        streams.append(Stream(key, t, values, cols, "hold", source, "time", required=used))
    table, valid, info = resample(streams, data.resample_hz, data.max_gap_s)
    dt = 1.0 / data.resample_hz
    quat = _gyro_attitude(table, valid, dt)
    for i, c in enumerate(("qw", "qx", "qy", "qz")):
        table[c] = quat[:, i]
    for c in ("vx", "vy", "vz"):
        table[c] = 0.0
    for n_in, col in inputs.items():
        table[n_in] = table[col]
    tt = table["t"].to_numpy()
    armed = np.ones(len(tt), dtype=bool)  # a blackbox log records one arming
    mask = in_flight_mask(tt, armed, table["throttle"].to_numpy(), data, source)
    measured = {a: "measured (gyroADC)" for a in ("p", "q", "r")}
    measured.update(
        {
            a: "derived (integrated from the gyro, levelled once by the accelerometer; drifts)"
            for a in ("phi", "theta", "psi")
        }
    )
    measured.update({a: "not measured (Betaflight logs no velocity; zero)" for a in "uvw"})
    notes = [f"header {k}: {headers[k]}" for k in HEADER_KEYS if k in headers]
    return LogTable(
        name=name,
        source=source,
        table=table,
        valid=valid,
        in_flight=mask,
        rate_hz=data.resample_hz,
        input_names=tuple(inputs),
        measured=measured,
        streams=info,
        notes=notes,
        levels=supported,
        input_level=chosen,
        input_columns=inputs,
    )


def read_betaflight_logs(path, data) -> tuple[list[LogTable], list[str]]:
    """Every decodable log (or `data.log_index`) of a file as LogTables, plus warnings."""
    path = Path(path)
    _, count = _open(path)
    indices = [data.log_index] if data.log_index else list(range(1, count + 1))
    tables, skipped = [], []
    for index in indices:
        source = f"{path} (log {index} of {count})"
        try:
            df, headers, stop = read_frames(path, index)
            if stop:
                skipped.append(
                    f"{source}: truncated or corrupt, {stop}; the frames before are used"
                )
        except GpquadError:
            raise
        except Exception as exc:  # a damaged log inside the file
            skipped.append(f"{source}: skipped, cannot be decoded ({type(exc).__name__}: {exc})")
            continue
        if "time" not in df or len(df) < 2:
            skipped.append(f"{source}: skipped, {len(df)} frames")
            continue
        t = df["time"].to_numpy(dtype=float) * 1e-6
        pieces = _pieces(t, data.max_gap_s)
        if len(pieces) > 1:
            skipped.append(f"{source}: clock jumps or gaps, split into {len(pieces)} pieces")
        tiny = [k for k, (a, b) in enumerate(pieces) if len(pieces) > 1 and t[b - 1] - t[a] < 1.0]
        if tiny:
            skipped.append(f"{source}: {len(tiny)} piece(s) shorter than 1 s dropped")
        for k in _overlapping(pieces, t):
            if k not in tiny:
                a, b = pieces[k]
                skipped.append(
                    f"{source}: piece {k} ({t[a]:.2f}..{t[b - 1]:.2f} s) overlaps "
                    "a longer piece of the same log in time: damaged frames, dropped"
                )
                tiny.append(k)
        for k, (a, b) in enumerate(pieces):
            if k in tiny:
                continue
            name = f"{path.stem}.log{index}" + (f".{k}" if len(pieces) > 1 else "")
            try:
                tables.append(_log_table(df.iloc[a:b], headers, data, source, name))
            except GpquadError as exc:
                if data.log_index or "missing field" in str(exc) or "deg/s" in str(exc):
                    raise
                skipped.append(f"{source}: piece {k} skipped ({exc})")
    for w in skipped:
        warnings.warn(w, stacklevel=2)
    if not tables:
        raise GpquadError(
            f"no decodable log among {len(indices)} ({'; '.join(skipped[:3])})", source=str(path)
        )
    return tables, skipped


def read_betaflight(path, data) -> list[Flight]:
    """Reader for format "betaflight": in-flight segments of every log in the file."""
    tables, _ = read_betaflight_logs(path, data)
    flights, errors = [], []
    for log in tables:
        try:
            flights.extend(flights_from_log(log, data))
        except GpquadError as exc:
            errors.append((len(log.table), str(exc)))
    if not flights:  # the reason of the longest log
        raise GpquadError(
            f"no usable flight in any of {len(tables)} log(s); longest: {max(errors)[1]}",
            source=str(path),
            field="data.segment",
        )
    return flights
