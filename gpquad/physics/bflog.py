"""The mixer's inputs and outputs from a Betaflight blackbox log.

Frames are decoded by `gpquad.data.betaflight.read_frames` (orangebox 0.4.0), which keeps every
field and the header. From them: PID sums per axis (axisP + axisI + axisD + axisF; a term the
log does not hold, such as yaw D in Betaflight 4.2, is zero), the throttle, the logged motor
values, and the header values the mixer needs (motorOutput, pidsum limits, airmode feature,
yaw_motors_reversed, DShot idle).

Throttle sources: "setpoint" is setpoint[3] / 1000, which Betaflight 4.2 logs as the mixer's
throttle (mixerGetThrottle(): after throttle boost and limits, before the airmode adjustment);
"rccommand" is (rcCommand[3] - 1000) / 1000 clipped to [0, 1], the stick throttle T_r of the
thesis (it misses throttle boost).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gpquad.errors import GpquadError

FEATURE_AIRMODE = 1 << 22  # Betaflight src/main/config/feature.h
THROTTLE_SOURCES = ("setpoint", "rccommand")


@dataclass
class MixerLog:
    """One armed log: time (s), PID sums (N, 3), throttle (N,), logged motors (N, M)."""

    source: str
    index: int
    t: np.ndarray
    pid_sums: np.ndarray
    throttle: np.ndarray
    motors: np.ndarray
    low: float
    high: float
    pidsum_limit: float
    pidsum_limit_yaw: float
    airmode_feature: bool
    yaw_reversed: bool
    header: dict = field(default_factory=dict)
    missing_terms: tuple = ()


def log_count(path) -> int:
    """Number of logs in a blackbox file (one clear error when it is not one)."""
    from gpquad.data.betaflight import _open

    _, count = _open(Path(path))
    return count


def _header_pair(headers: dict, key: str, source: str) -> tuple[float, float]:
    value = headers.get(key)
    if not isinstance(value, (list, tuple)) or len(value) < 2:
        raise GpquadError(
            f"header '{key}' is missing or not 'low,high' ({value!r}); the log "
            "does not say the motor output range",
            source=source,
            field=key,
        )
    return float(value[0]), float(value[1])


def load_mixer_log(
    path, index: int, throttle_source: str = "setpoint", allow_truncated: bool = False
) -> MixerLog:
    """PID sums, throttle and motors of log `index` (1-based); a user-facing error when the
    log lacks motor or PID fields, or when its decoding stopped early (unless allowed)."""
    from gpquad.data.betaflight import read_frames

    if throttle_source not in THROTTLE_SOURCES:
        raise GpquadError(
            f"unknown throttle source '{throttle_source}'; use one of {THROTTLE_SOURCES}",
            field="--throttle",
        )
    count = log_count(path)
    source = f"{path} (log {index} of {count})"
    try:
        df, headers, stop = read_frames(path, index)
    except GpquadError:
        raise
    except Exception as exc:  # orangebox fails on a damaged header or frame definition
        raise GpquadError(
            f"the log cannot be decoded ({type(exc).__name__}: {exc}); it is damaged", source=source
        ) from None
    if stop and not allow_truncated:
        raise GpquadError(
            f"truncated or corrupt log: {stop}; pass --allow-truncated to use "
            "the frames before the damage",
            source=source,
        )
    if len(df) < 2:
        raise GpquadError(f"the log holds {len(df)} frames", source=source)
    motor_cols = [f"motor[{i}]" for i in range(8) if f"motor[{i}]" in df]
    if not motor_cols:
        raise GpquadError(
            "no motor field (motor[0..3]) in the log; enable motor logging "
            "(blackbox field MOTOR) to validate the mixer",
            source=source,
            field="motor[0]",
        )
    if len(motor_cols) != 4:
        raise GpquadError(
            f"{len(motor_cols)} motors logged; only the quad-X mixer is built in",
            source=source,
            field="motor[0]",
        )
    terms = ("axisP", "axisI", "axisD", "axisF")
    present = [f"{k}[{a}]" for k in terms for a in range(3) if f"{k}[{a}]" in df]
    if not any(c.startswith("axisP") for c in present):
        raise GpquadError(
            "no PID field (axisP/I/D/F) in the log; enable PID logging to validate the mixer",
            source=source,
            field="axisP[0]",
        )
    sums = np.zeros((len(df), 3))
    for a in range(3):
        for k in terms:
            col = f"{k}[{a}]"
            if col in df:
                sums[:, a] += df[col].to_numpy(float)
    missing = tuple(f"{k}[{a}]" for k in terms for a in range(3) if f"{k}[{a}]" not in df)
    if throttle_source == "setpoint":
        if "setpoint[3]" not in df:
            raise GpquadError(
                "no setpoint[3] (mixer throttle) in the log; use --throttle rccommand",
                source=source,
                field="setpoint[3]",
            )
        throttle = df["setpoint[3]"].to_numpy(float) / 1000.0
    else:
        if "rcCommand[3]" not in df:
            raise GpquadError("no rcCommand[3] in the log", source=source, field="rcCommand[3]")
        throttle = np.clip((df["rcCommand[3]"].to_numpy(float) - 1000.0) / 1000.0, 0.0, 1.0)
    low, high = _header_pair(headers, "motorOutput", source)
    features = int(headers.get("features") or 0)
    motors = df[motor_cols].to_numpy(float)
    t = df["time"].to_numpy(float) * 1e-6 if "time" in df else np.arange(len(df), dtype=float)
    ok = (
        np.all(np.isfinite(motors), axis=1)
        & np.all(np.isfinite(sums), axis=1)
        & np.isfinite(throttle)
        & np.isfinite(t)
    )
    return MixerLog(
        source=source,
        index=index,
        t=t[ok],
        pid_sums=sums[ok],
        throttle=throttle[ok],
        motors=motors[ok],
        low=low,
        high=high,
        pidsum_limit=float(headers.get("pidsum_limit") or 500),
        pidsum_limit_yaw=float(headers.get("pidsum_limit_yaw") or 400),
        airmode_feature=bool(features & FEATURE_AIRMODE),
        yaw_reversed=bool(int(headers.get("yaw_motors_reversed") or 0)),
        header={
            k: headers.get(k)
            for k in (
                "Firmware revision",
                "Craft name",
                "motorOutput",
                "dshot_idle_value",
                "pidsum_limit",
                "pidsum_limit_yaw",
                "features",
                "motor_pwm_protocol",
                "airmode_activate_throttle",
            )
            if k in headers
        },
        missing_terms=missing,
    )
