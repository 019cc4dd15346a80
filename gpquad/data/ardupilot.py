"""ArduPilot DataFlash `.bin` logs (format "ardupilot"), read by gpquad.data.dataflash.

Signals (ArduPilot conventions: NED/FRD, TimeUS in microseconds):

- attitude: the EKF quaternion (XKQ core 0, or NKQ1) Q1..Q4 = (w, x, y, z) body to NED;
  without one, ATT Roll/Pitch/Yaw (deg);
- body rates: IMU GyrX..GyrZ (rad/s, first IMU), else RATE R, P, Y (deg/s);
- velocity: the EKF's NED velocity XKF1 (core 0) or NKF1 VN, VE, VD (m/s);
- inputs by level (gpquad.data.levels): "rates" = RATE RDes, PDes, YDes (deg/s -> rad/s,
  columns p_sp, q_sp, r_sp) with CTUN ThO (thrust_out, 0..1); "torque" = RATE ROut, POut,
  YOut with ThO; "sticks" = RCIN channels RCMAP_ROLL/PITCH/YAW/THROTTLE, (PWM - 1500) / 500;
  "motors" = RCOU C1..C4, (PWM - MOT_PWM_MIN) / (MOT_PWM_MAX - MOT_PWM_MIN) (1000..2000 when
  unset);
- arming from EV events (10 armed, 11 disarmed); in flight: armed and ThO above
  `data.thrust_threshold`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gpquad.data.dataflash import DataFlashLog
from gpquad.data.flight import Flight
from gpquad.data.levels import check_input_rates, paper_names, resolve_inputs
from gpquad.data.pipeline import LogTable, flights_from_log
from gpquad.data.plausibility import check_rate_peak, check_rate_units
from gpquad.data.resets import reset_mask
from gpquad.data.streams import Stream, in_flight_mask, resample
from gpquad.engine.kernels.quaternion import quat_from_euler
from gpquad.errors import GpquadError

ARMED, DISARMED = 10, 11
UNITS = {"p_sp": " (rad/s)", "q_sp": " (rad/s)", "r_sp": " (rad/s)"}


def _first(log: DataFlashLog, names) -> tuple[str, dict] | tuple[None, dict]:
    for name in names:
        d = log.get(name)
        if d:
            if "C" in d:  # EKF core / instance: keep the first
                keep = d["C"] == d["C"].min()
                d = {k: v[keep] for k, v in d.items()}
            if "I" in d:
                keep = d["I"] == d["I"].min()
                d = {k: v[keep] for k, v in d.items()}
            return name, d
    return None, {}


def seconds(d: dict, name: str, source: str) -> np.ndarray:
    """A message's timestamps in seconds: TimeUS (microseconds), or TimeMS (milliseconds) of
    the older DataFlash logs (about 2015 and before); one line naming the message when it
    has neither."""
    if "TimeUS" in d:
        return np.asarray(d["TimeUS"], dtype=float) * 1e-6
    if "TimeMS" in d:
        return np.asarray(d["TimeMS"], dtype=float) * 1e-3
    raise GpquadError(
        f"message {name} has no timestamp (neither TimeUS nor TimeMS)",
        source=source,
        field=f"{name}.TimeUS",
    )


def _stream(log, name, d, fields, columns, kind, scale=1.0, offset=0.0, required=True):
    t = seconds(d, name, str(log.path))
    missing = [f for f in fields if f not in d]
    if missing:
        raise GpquadError(
            f"message {name} has no field '{missing[0]}'",
            source=str(log.path),
            field=f"{name}.{missing[0]}",
        )
    values = (np.column_stack([np.asarray(d[f], dtype=float) for f in fields]) - offset) * scale
    return Stream(name, t, values, tuple(columns), kind, str(log.path), f"{name}.TimeUS", required)


def _armed_stream(log, ev) -> Stream | None:
    """Held arming state from EV events; before the first one, the opposite of it."""
    if not ev:
        return None
    ids = np.asarray(ev["Id"], dtype=int)
    keep = np.isin(ids, (ARMED, DISARMED))
    if not keep.any():
        return None
    t = seconds(ev, "EV", str(log.path))[keep]
    state = (ids[keep] == ARMED).astype(float)
    t = np.concatenate([[0.0], t])
    state = np.concatenate([[1.0 - state[0]], state])
    return Stream("EV", t, state[:, None], ("armed",), "hold", str(log.path), "EV.TimeUS", False)


def ardupilot_log_table(path, data) -> LogTable:
    """A DataFlash log on one clock (see the module docstring)."""
    log = DataFlashLog(path)
    src = str(log.path)
    measured = {}
    q_name, q = _first(log, ("XKQ", "NKQ1"))
    if q_name:
        streams = [
            _stream(log, q_name, q, ("Q1", "Q2", "Q3", "Q4"), ("qw", "qx", "qy", "qz"), "quat")
        ]
        measured.update({a: f"measured (EKF quaternion {q_name})" for a in ("phi", "theta", "psi")})
    else:
        _, att = _first(log, ("ATT",))
        if not att:
            raise GpquadError(
                "no attitude: neither XKQ, NKQ1 nor ATT messages", source=src, field="ATT"
            )
        eul = np.radians(np.column_stack([att["Roll"], att["Pitch"], att["Yaw"]]))
        quat = np.array([quat_from_euler(*e) for e in eul])
        streams = [
            Stream(
                "ATT",
                seconds(att, "ATT", src),
                quat,
                ("qw", "qx", "qy", "qz"),
                "quat",
                src,
                "ATT.TimeUS",
            )
        ]
        measured.update({a: "measured (ATT Euler angles)" for a in ("phi", "theta", "psi")})
    g_name, gyro = _first(log, ("IMU",))
    if g_name and "GyrX" in gyro:
        fields, rates = (
            ("GyrX", "GyrY", "GyrZ"),
            _stream(log, g_name, gyro, ("GyrX", "GyrY", "GyrZ"), ("p", "q", "r"), "state"),
        )
    else:
        g_name, gyro = _first(log, ("RATE",))
        if not g_name:
            raise GpquadError(
                "no body rates: neither IMU nor RATE messages", source=src, field="IMU"
            )
        fields = ("R", "P", "Y")
        rates = _stream(log, g_name, gyro, fields, ("p", "q", "r"), "state", np.pi / 180)
    check_rate_peak(rates.values, src, fields)
    streams.append(rates)
    measured.update({a: f"measured (gyro, {g_name})" for a in ("p", "q", "r")})
    v_name, vel = _first(log, ("XKF1", "NKF1"))
    if not v_name:
        raise GpquadError("no velocity: neither XKF1 nor NKF1 messages", source=src, field="XKF1")
    streams.append(_stream(log, v_name, vel, ("VN", "VE", "VD"), ("vx", "vy", "vz"), "state"))
    gps = log.get("GPS")
    how = "with GPS" if gps and np.max(gps.get("Status", [0])) >= 3 else "no GPS fix logged"
    measured.update({a: f"measured (EKF NED velocity {v_name}, {how})" for a in "uvw"})
    streams.extend(_input_streams(log))
    armed = _armed_stream(log, log.get("EV"))
    if armed is not None:
        streams.append(armed)
    columns = ["t"] + [c for s in streams for c in s.columns]
    supported = _levels(columns, log.params())
    inputs, chosen = resolve_inputs(data, supported, columns, src)
    for s in streams:
        s.required = s.required or bool(set(s.columns) & set(inputs.values()))
    table, valid, info = resample(streams, data.resample_hz, data.max_gap_s)
    check_rate_units(table, valid, src, fields)
    bad, notes = reset_mask(table, data.resample_hz, {}, data.max_attitude_step_deg)
    valid &= ~bad
    notes.extend(check_input_rates(info, inputs, {s.name: s.columns for s in streams}))
    if log.skipped:
        notes.append(f"skipped {log.skipped} bytes that are not whole records")
    for n_in, col in inputs.items():
        table[n_in] = table[col]
    t = table["t"].to_numpy()
    thrust = table["thrust_out"].to_numpy() if "thrust_out" in table.columns else None
    is_armed = table["armed"].to_numpy() > 0.5 if "armed" in table.columns else None
    mask = in_flight_mask(t, is_armed, thrust, data, src)
    return LogTable(
        name=log.path.stem,
        source=src,
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
        units=UNITS,
    )


def _input_streams(log) -> list[Stream]:
    out = []
    rate = log.get("RATE")
    if rate and all(f in rate for f in ("RDes", "PDes", "YDes", "ROut", "POut", "YOut")):
        out.append(
            _stream(
                log,
                "RATE",
                rate,
                ("RDes", "PDes", "YDes"),
                ("p_sp", "q_sp", "r_sp"),
                "hold",
                np.pi / 180,
                required=False,
            )
        )
        out.append(
            Stream(
                "RATE.Out",
                seconds(rate, "RATE", str(log.path)),
                np.column_stack([rate["ROut"], rate["POut"], rate["YOut"]]),
                ("roll_out", "pitch_out", "yaw_out"),
                "hold",
                str(log.path),
                "RATE.TimeUS",
                False,
            )
        )
    ctun = log.get("CTUN")
    if ctun and "ThO" in ctun:
        out.append(_stream(log, "CTUN", ctun, ("ThO",), ("thrust_out",), "hold", required=False))
    rcin = log.get("RCIN")
    if rcin:
        chans = [c for c in (f"C{i}" for i in range(1, 9)) if c in rcin]
        out.append(
            _stream(
                log,
                "RCIN",
                rcin,
                chans,
                tuple(f"rc_{i}" for i in range(len(chans))),
                "hold",
                1 / 500,
                1500.0,
                required=False,
            )
        )
    rcou = log.get("RCOU")
    if rcou and all(f"C{i}" in rcou for i in range(1, 5)):
        p = log.params()
        lo, hi = p.get("MOT_PWM_MIN", 0.0) or 1000.0, p.get("MOT_PWM_MAX", 0.0) or 2000.0
        out.append(
            _stream(
                log,
                "RCOU",
                rcou,
                ("C1", "C2", "C3", "C4"),
                tuple(f"motor_{i}" for i in range(4)),
                "hold",
                1 / (hi - lo),
                lo,
                required=False,
            )
        )
    return out


def _levels(columns, params) -> dict[str, dict[str, str]]:
    cols = set(columns)
    out = {}
    if {"p_sp", "q_sp", "r_sp", "thrust_out"} <= cols:
        out["rates"] = paper_names("q_sp", "p_sp", "r_sp", "thrust_out")
    if {"roll_out", "pitch_out", "yaw_out", "thrust_out"} <= cols:
        out["torque"] = paper_names("pitch_out", "roll_out", "yaw_out", "thrust_out")
    rc = [
        int(params.get(f"RCMAP_{k}", d))
        for k, d in (("PITCH", 2), ("ROLL", 1), ("YAW", 4), ("THROTTLE", 3))
    ]
    if all(f"rc_{m - 1}" in cols for m in rc):
        out["sticks"] = paper_names(*(f"rc_{m - 1}" for m in rc))
    if {f"motor_{i}" for i in range(4)} <= cols:
        out["motors"] = {f"motor_{i}": f"motor_{i}" for i in range(4)}
    return out


def read_ardupilot(path, data) -> list[Flight]:
    """Reader for format "ardupilot": in-flight segments of a DataFlash .bin log."""
    return flights_from_log(ardupilot_log_table(Path(path), data), data)
