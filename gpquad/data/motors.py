"""Motor speeds, accelerometer and position of a flight log: what the thrust and drag
regressions and dead reckoning of `gpquad physics` read (racing-drone thesis IV-V).

Every reader returns `MotorLog`s on one uniform clock, in NED/FRD and SI units:

- generic CSV/Parquet (format "generic"): `t`, `qw, qx, qy, qz`, optional `vx, vy, vz` (or
  `u, v, w`) and `x, y, z`, rotor speeds `rotor_1 .. rotor_4` (rad/s) or `erpm_1 .. erpm_4`
  (electrical RPM; `[vehicle] motor_pole_pairs` converts), and `acc_x, acc_y, acc_z` (body
  specific force, m/s^2); `[data.columns]` renames, `data.frame` declares NED/FRD or ENU/FLU;
  a `segment` column splits the file. The rows must be uniformly sampled; every row is in
  flight unless `data.segment = "range"` keeps `data.time_range` (s from the file's start).
- Betaflight 4.3+ (format "betaflight"): `eRPM[0..3]` (bidirectional DShot telemetry, logged
  as eRPM / 100) divided by the motor pole pairs (`[vehicle] motor_pole_pairs`, else the
  header's `motor_poles` / 2); accSmooth via the Betaflight reader. No velocity or position.
- PX4 (formats "px4-csv", "ulog"): `esc_status` `esc[i].esc_rpm` (mechanical RPM);
  `vehicle_acceleration` `xyz[0..2]`, else `sensor_combined` `accelerometer_m_s2[0..2]`;
  `vehicle_local_position` `x, y, z` (with `xy_valid`/`z_valid`).
- ArduPilot (format "ardupilot"): `ESC` `RPM` per `Instance`; `IMU` `AccX..AccZ` (first IMU);
  `XKF1`/`NKF1` `PN, PE, PD`.

For the log formats the attitude, velocity, arming and in-flight samples come from the
format's own reader (gpquad.data.px4, .betaflight, .ardupilot); the signals here are
interpolated onto its clock, and a gap longer than `data.max_gap_s` (or 2.5 sample periods)
makes the samples invalid. A signal the log does not hold is None, and `missing` says where
it would have been.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd

from gpquad.data.flight import (
    _column,
    _read_table,
    check_time,
    enu_flu_quat,
    flip_body,
    flip_world,
)
from gpquad.data.motor_log import (
    ACC_COLUMNS,
    ERPM_COLUMNS,
    POS_COLUMNS,
    ROTOR_COLUMNS,
    RPM_TO_RAD_S,
    MotorLog,
    erpm_to_rad_s,
    on_clock,
)
from gpquad.data.pipeline import LogTable, is_measured
from gpquad.engine.variables import BODY_VEL_COLUMNS, QUAT_COLUMNS, WORLD_VEL_COLUMNS
from gpquad.errors import GpquadError

FORMATS = ("generic", "betaflight", "px4-csv", "ulog", "ardupilot")


# ---- generic files -------------------------------------------------------------------------


def _optional(df, names, columns, source):
    if all(columns.get(c, c) in df.columns for c in names):
        return np.column_stack([_column(df, c, columns, source) for c in names])
    return None


def _generic_piece(df: pd.DataFrame, name: str, source: str, data, pole_pairs: int) -> MotorLog:
    columns = dict(data.columns)
    t = _column(df, "t", columns, source)
    check_time(t, source, columns.get("t", "t"))
    quat = np.column_stack([_column(df, c, columns, source) for c in QUAT_COLUMNS])
    norm = np.linalg.norm(quat, axis=1)
    if np.abs(norm - 1.0).max() > 1e-2:
        raise GpquadError(
            f"quaternion norm ranges {norm.min():.3f}..{norm.max():.3f}, not 1; "
            "give a unit quaternion (w, x, y, z)",
            source=source,
            field="qw",
        )
    quat = quat / norm[:, None]
    missing = {}
    rotor = _optional(df, ROTOR_COLUMNS, columns, source)
    if rotor is None:
        erpm = _optional(df, ERPM_COLUMNS, columns, source)
        if erpm is not None:
            if pole_pairs < 1:
                raise GpquadError(
                    "erpm_1..4 need the motor's pole pairs to give rad/s; set "
                    "[vehicle] motor_pole_pairs (14 magnets: 7)",
                    source=source,
                    field="vehicle.motor_pole_pairs",
                )
            rotor = erpm_to_rad_s(erpm, pole_pairs)
        else:
            missing["rotor"] = "columns rotor_1..rotor_4 (rad/s) or erpm_1..erpm_4"
    acc = _optional(df, ACC_COLUMNS, columns, source)
    if acc is None:
        missing["acc"] = "columns acc_x, acc_y, acc_z (body specific force, m/s^2)"
    body = _optional(df, BODY_VEL_COLUMNS, columns, source)
    world = None if body is not None else _optional(df, WORLD_VEL_COLUMNS, columns, source)
    if body is None and world is None:
        missing["vel"] = "columns vx, vy, vz (world) or u, v, w (body), m/s"
    pos = _optional(df, POS_COLUMNS, columns, source)
    if pos is None:
        missing["pos"] = "columns x, y, z (world position, m)"
    rates = _optional(df, ("p", "q", "r"), columns, source)
    if data.frame == "ENU/FLU":
        quat = enu_flu_quat(quat)
        body, acc, rates = (None if a is None else flip_body(a) for a in (body, acc, rates))
        world, pos = (None if a is None else flip_world(a) for a in (world, pos))
    elif data.frame != "NED/FRD":
        raise GpquadError(
            f"unknown frame '{data.frame}'; use NED/FRD or ENU/FLU",
            source=source,
            field="data.frame",
        )
    if body is not None:
        world = _rotate(quat, body)
    t = t - t[0]
    in_flight = np.ones(len(t), dtype=bool)
    if data.segment == "range":
        in_flight = (t >= data.time_range[0]) & (t <= data.time_range[1])
    return MotorLog(
        name=name,
        source=source,
        t=t,
        quat=quat,
        rotor=rotor,
        acc=acc,
        vel=world,
        pos=pos,
        rates=rates,
        valid=np.ones(len(t), dtype=bool),
        in_flight=in_flight,
        missing=missing,
    )


def _rotate(quat: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """Body vectors to the world frame with body-to-world quaternions (w, x, y, z)."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_quat(quat[:, [1, 2, 3, 0]]).apply(vectors)


def read_generic_motors(path, data, pole_pairs: int = 0) -> list[MotorLog]:
    path = Path(path)
    df = _read_table(path)
    if "segment" not in df.columns:
        return [_generic_piece(df, path.name, str(path), data, pole_pairs)]
    seg = pd.to_numeric(df["segment"], errors="coerce").to_numpy(float)
    if not np.isfinite(seg).all():
        raise GpquadError("NaN or non-numeric segment ids", source=str(path), field="segment")
    return [
        _generic_piece(
            df[seg == s].reset_index(drop=True),
            f"{path.name}#{int(s)}",
            f"{path} (segment {int(s)})",
            data,
            pole_pairs,
        )
        for s in dict.fromkeys(seg.tolist())
    ]


# ---- log formats: signals onto the reader's LogTable clock -----------------------------------


def _from_table(log: LogTable, extra: dict, missing: dict, data, notes=()) -> MotorLog:
    """A MotorLog from a reader's LogTable and extra signals {name: [(t, values)...]}: each
    (t, values) pair is interpolated on the table's clock and stacked as columns."""
    table = log.table
    grid = table["t"].to_numpy(dtype=float)
    valid = log.valid.copy()
    arrays = {}
    for key, parts in extra.items():
        cols = []
        for t, values in parts:
            v, covered = on_clock(grid, t, values, data.max_gap_s)
            cols.append(v)
            valid &= covered
        arrays[key] = np.column_stack(cols)
    quat = table[list(QUAT_COLUMNS)].to_numpy(dtype=float)
    vel = None
    if all(is_measured(log.measured.get(a, "not measured")) for a in "uvw"):
        if log.velocity_frame == "world":
            vel = table[list(WORLD_VEL_COLUMNS)].to_numpy(dtype=float)
        elif log.velocity_frame == "body":
            vel = _rotate(quat, table[list(BODY_VEL_COLUMNS)].to_numpy(dtype=float))
    else:
        missing["vel"] = (
            "a measured velocity ("
            + "; ".join(f"{a}: {log.measured.get(a, 'absent')}" for a in "uvw")
            + ")"
        )
    rates = table[["p", "q", "r"]].to_numpy(dtype=float) if "p" in table.columns else None
    acc = arrays.get("acc")
    if acc is None and all(c in table.columns for c in ("ax", "ay", "az")):
        acc = table[["ax", "ay", "az"]].to_numpy(dtype=float)
    return MotorLog(
        name=log.name,
        source=log.source,
        t=grid,
        quat=quat,
        rotor=arrays.get("rotor"),
        acc=acc,
        vel=vel,
        pos=arrays.get("pos"),
        rates=rates,
        valid=valid,
        in_flight=log.in_flight.copy(),
        missing={k: v for k, v in missing.items() if not (k == "acc" and acc is not None)},
        notes=list(log.notes) + list(notes),
    )


def _px4(tp, data, name: str) -> MotorLog:
    from gpquad.data.px4 import px4_log_table

    log = px4_log_table(tp, data, name)
    extra, missing = {}, {}
    esc = tp.get("esc_status") if tp.has("esc_status") else None
    rpm_cols = [f"esc[{i}].esc_rpm" for i in range(4)]
    if esc is not None and all(c in esc.columns for c in rpm_cols):
        t = tp.time("esc_status")
        extra["rotor"] = [
            (
                t,
                np.abs(np.column_stack([tp.column("esc_status", c) for c in rpm_cols]))
                * RPM_TO_RAD_S,
            )
        ]
    else:
        missing["rotor"] = "topic esc_status esc[0..3].esc_rpm, from ESC telemetry"
    for topic, fields in (
        ("vehicle_acceleration", [f"xyz[{i}]" for i in range(3)]),
        ("sensor_combined", [f"accelerometer_m_s2[{i}]" for i in range(3)]),
    ):
        if tp.has(topic) and all(f in tp.get(topic).columns for f in fields):
            extra["acc"] = [
                (tp.time(topic), np.column_stack([tp.column(topic, f) for f in fields]))
            ]
            break
    else:
        missing["acc"] = (
            "topic vehicle_acceleration xyz[0..2] or sensor_combined accelerometer_m_s2[0..2]"
        )
    lp = tp.get("vehicle_local_position")
    if all(c in lp.columns for c in POS_COLUMNS):
        pos = np.column_stack([tp.column("vehicle_local_position", c) for c in POS_COLUMNS])
        for flag, cols in (("xy_valid", [0, 1]), ("z_valid", [2])):
            if flag in lp.columns:
                bad = tp.column("vehicle_local_position", flag) < 0.5
                pos[np.ix_(bad, cols)] = np.nan
        extra["pos"] = [(tp.time("vehicle_local_position"), pos)]
    else:
        missing["pos"] = "vehicle_local_position x, y, z"
    if "pos" in extra and not np.isfinite(extra["pos"][0][1]).all(axis=1).any():
        del extra["pos"]
        missing["pos"] = "vehicle_local_position x, y, z with xy_valid and z_valid set"
    return _from_table(log, extra, missing, data)


def read_px4_motors(path, data, pole_pairs: int = 0) -> list[MotorLog]:
    from gpquad.data.px4 import read_px4_folder

    path = Path(path)
    return [_px4(read_px4_folder(path), data, path.name)]


def read_ulog_motors(path, data, pole_pairs: int = 0) -> list[MotorLog]:
    from gpquad.data.ulog import read_ulog_topics

    return [_px4(read_ulog_topics(path), data, Path(path).stem)]


def betaflight_pole_pairs(headers: dict, pole_pairs: int, source: str) -> int:
    """Pole pairs from [vehicle] (when > 0), else the header's motor_poles (magnets) / 2."""
    if pole_pairs > 0:
        return pole_pairs
    poles = headers.get("motor_poles")
    try:
        poles = int(poles)
    except (TypeError, ValueError):
        poles = 0
    if poles < 2:
        raise GpquadError(
            "the log's header has no motor_poles; set [vehicle] motor_pole_pairs "
            "(14 magnets: 7) to turn eRPM into rad/s",
            source=source,
            field="vehicle.motor_pole_pairs",
        )
    return poles // 2


def read_betaflight_motors(path, data, pole_pairs: int = 0) -> list[MotorLog]:
    from gpquad.data.betaflight import read_betaflight_logs, read_frames

    path = Path(path)
    tables, _ = read_betaflight_logs(path, data)
    frames = {}
    out = []
    for log in tables:
        m = re.search(r"\.log(\d+)", log.name)
        index = int(m.group(1)) if m else 1
        if index not in frames:
            frames[index] = read_frames(path, index)[:2]
        df, headers = frames[index]
        fields = [f"eRPM[{i}]" for i in range(4)]
        extra, missing = {}, {}
        if all(f in df.columns for f in fields):
            pp = betaflight_pole_pairs(headers, pole_pairs, log.source)
            t = df["time"].to_numpy(dtype=float) * 1e-6
            erpm = df[fields].to_numpy(dtype=float) * 100.0
            extra["rotor"] = [(t, erpm_to_rad_s(erpm, pp))]
        else:
            firmware = headers.get("Firmware revision", "unknown firmware")
            missing["rotor"] = (
                f"fields eRPM[0..3]: {firmware}; Betaflight 4.3+ logs them "
                "with dshot_bidir = ON and the RPM blackbox field enabled"
            )
        out.append(_from_table(log, extra, missing, data))
    return out


def read_ardupilot_motors(path, data, pole_pairs: int = 0) -> list[MotorLog]:
    from gpquad.data.ardupilot import _first, ardupilot_log_table
    from gpquad.data.dataflash import DataFlashLog

    log = ardupilot_log_table(path, data)
    df = DataFlashLog(path)
    extra, missing = {}, {}
    esc = df.get("ESC")
    if esc and "RPM" in esc and "Instance" in esc:
        inst = np.asarray(esc["Instance"], dtype=int)
        parts = [
            (
                np.asarray(esc["TimeUS"], float)[inst == i] * 1e-6,
                np.abs(np.asarray(esc["RPM"], float)[inst == i]) * RPM_TO_RAD_S,
            )
            for i in range(4)
        ]
        if all(len(p[0]) >= 2 for p in parts):
            extra["rotor"] = parts
    if "rotor" not in extra:
        missing["rotor"] = "ESC messages with RPM for instances 0..3, from ESC telemetry"
    _, imu = _first(df, ("IMU",))
    if imu and all(f in imu for f in ("AccX", "AccY", "AccZ")):
        extra["acc"] = [
            (
                np.asarray(imu["TimeUS"], float) * 1e-6,
                np.column_stack([imu["AccX"], imu["AccY"], imu["AccZ"]]),
            )
        ]
    else:
        missing["acc"] = "IMU messages AccX, AccY, AccZ"
    _, ekf = _first(df, ("XKF1", "NKF1"))
    if ekf and all(f in ekf for f in ("PN", "PE", "PD")):
        extra["pos"] = [
            (
                np.asarray(ekf["TimeUS"], float) * 1e-6,
                np.column_stack([ekf["PN"], ekf["PE"], ekf["PD"]]),
            )
        ]
    else:
        missing["pos"] = "XKF1 or NKF1 PN, PE, PD"
    return [_from_table(log, extra, missing, data)]


READERS = {
    "generic": read_generic_motors,
    "betaflight": read_betaflight_motors,
    "px4-csv": read_px4_motors,
    "ulog": read_ulog_motors,
    "ardupilot": read_ardupilot_motors,
}


def read_motor_logs(path, data, pole_pairs: int = 0) -> list[MotorLog]:
    """Every log (piece) of one file in the configured format, with motor speeds and
    accelerometer where the format has them."""
    reader = READERS.get(data.format)
    if reader is None:
        raise GpquadError(
            f"format '{data.format}' has no motor-speed reader; use one of {list(FORMATS)}",
            source=str(path),
            field="data.format",
        )
    return reader(path, data, pole_pairs)
