"""Validate the mixer model on blackbox logs: predicted vs logged motor[0..3] per log.

Per log and motor: RMSE (DShot units), R^2, mean error, and the RMSE outside saturated
stretches; with the airmode handling the header declares (feature AIRMODE) and without it.
Saturated samples: the rate mix did not fit (range > 1, Betaflight scales it down), a predicted
command left [0, 1] before clipping, or a logged motor sits at the top of the output range.

Betaflight 4.2 does not log yaw_motors_reversed ("props out"); with `yaw_reversed="auto"` both
yaw directions are fitted and the one with the lower RMSE is kept (and reported). Nor does it
log `thrust_linear` (percent, default 0); with `thrust_linear="auto"` the integer percent in
0..40 with the lowest RMSE is kept (and reported).
"""

from __future__ import annotations

import numpy as np

from gpquad.errors import GpquadError
from gpquad.physics.bflog import MixerLog, load_mixer_log, log_count
from gpquad.physics.mixer import (
    DSHOT_MAX,
    DSHOT_MIN,
    LAYOUTS,
    idle_value,
    motor_commands,
    rate_mix,
    runs_of,
    thrust_linearization,
)

DSHOT_PROTOCOLS = (5, 6, 7, 8)  # Betaflight 4.2 PWM_TYPE_DSHOT150..PROSHOT1000
MAX_STRETCHES = 20


def output_range(log: MixerLog) -> tuple[float, float, str]:
    """Low and high motor values: the DShot idle of eq. (15) from dshot_idle_value (0.01 %)
    when the protocol is DShot (the header's motorOutput[0] is that value rounded), else the
    header's motorOutput."""
    idle = log.header.get("dshot_idle_value")
    proto = log.header.get("motor_pwm_protocol")
    if idle is not None and proto in DSHOT_PROTOCOLS:
        return (
            idle_value(float(idle) / 10000.0),
            float(DSHOT_MAX),
            f"eq. (15): 48 + {float(idle) / 100:.2f} % x 1999",
        )
    return log.low, log.high, "header motorOutput"


def motor_metrics(
    pred: np.ndarray, logged: np.ndarray, keep: np.ndarray, unsaturated: np.ndarray
) -> list[dict]:
    """RMSE, R^2 and bias per motor over `keep`, and the RMSE over `keep & unsaturated`."""
    out = []
    for k in range(logged.shape[1]):
        y, p = logged[keep, k], pred[keep, k]
        e = p - y
        sst = float(np.sum((y - y.mean()) ** 2))
        calm = unsaturated[keep]
        out.append(
            {
                "rmse": float(np.sqrt(np.mean(e**2))),
                "r2": float(1.0 - np.sum(e**2) / sst) if sst > 0 else None,
                "bias": float(np.mean(e)),
                "rmse_unsaturated": float(np.sqrt(np.mean(e[calm] ** 2))) if calm.any() else None,
            }
        )
    return out


def _predict(
    log: MixerLog,
    low: float,
    high: float,
    airmode: bool,
    yaw_reversed: bool,
    thrust_linear: float = 0.0,
):
    mixer = LAYOUTS["quadx"]
    mix = rate_mix(log.pid_sums, mixer, log.pidsum_limit, log.pidsum_limit_yaw, yaw_reversed)
    cmd, over = motor_commands(mix, log.throttle, mixer, airmode)
    cmd = thrust_linearization(cmd, thrust_linear)
    pred = np.trunc(np.clip(low + (high - low) * cmd, low, high))
    out_of_range = np.any((cmd < -1e-9) | (cmd > 1.0 + 1e-9), axis=1)
    return pred, over | out_of_range


def check_log(log: MixerLog, yaw_reversed: str = "auto", thrust_linear=0) -> dict:
    """Metrics of one log (see the module docstring); `yaw_reversed` is auto, yes or no;
    `thrust_linear` is "auto" or a percent."""
    low, high, low_from = output_range(log)
    armed = np.all(log.motors >= DSHOT_MIN, axis=1)
    if armed.sum() < 2:
        raise GpquadError(
            f"only {int(armed.sum())} armed frames (motor values >= "
            f"{DSHOT_MIN}); nothing to compare",
            source=log.source,
            field="motor[0]",
        )
    at_top = np.any(log.motors >= high - 1, axis=1)
    airmode = log.airmode_feature
    choices = {"auto": (False, True), "yes": (True,), "no": (False,)}
    if yaw_reversed not in choices:
        raise GpquadError(
            f"yaw_reversed must be auto, yes or no, not '{yaw_reversed}'", field="--yaw-reversed"
        )
    if thrust_linear == "auto":
        linears = range(0, 41)
    else:
        try:
            linears = [float(thrust_linear)]
        except ValueError:
            raise GpquadError(
                f"thrust_linear must be auto or a percent, not '{thrust_linear}'",
                field="--thrust-linear",
            ) from None
        if not 0 <= linears[0] <= 150:
            raise GpquadError("thrust_linear must be in 0..150 %", field="--thrust-linear")
    best = None
    for rev in choices[yaw_reversed]:
        for lin in linears:
            pred, flag = _predict(log, low, high, airmode, rev, lin)
            sse = float(np.sum((pred - log.motors)[armed] ** 2))
            if best is None or sse < best[0]:
                best = (sse, rev, pred, flag, lin)
    _, rev, pred, flag, lin = best
    saturated = flag | at_top
    result = {
        "index": log.index,
        "source": log.source,
        "frames": int(len(log.t)),
        "armed_frames": int(armed.sum()),
        "duration_s": float(log.t[armed][-1] - log.t[armed][0]),
        "yaw_reversed": rev,
        "yaw_reversed_from": "fit" if yaw_reversed == "auto" else "given",
        "thrust_linear": lin,
        "thrust_linear_from": "fit" if thrust_linear == "auto" else "given",
        "airmode_feature": airmode,
        "low": low,
        "high": high,
        "low_from": low_from,
        "pidsum_limit": log.pidsum_limit,
        "pidsum_limit_yaw": log.pidsum_limit_yaw,
        "missing_pid_terms": list(log.missing_terms),
        "header": log.header,
    }
    result["motors"] = motor_metrics(pred, log.motors, armed, ~saturated)
    result["saturated_fraction"] = float(saturated[armed].mean())
    other, other_flag = _predict(log, low, high, not airmode, rev, lin)
    key = "without_airmode" if airmode else "with_airmode"
    result[key] = {
        "motors": motor_metrics(other, log.motors, armed, ~(other_flag | at_top)),
        "saturated_fraction": float((other_flag | at_top)[armed].mean()),
    }
    stretches = [(a, b) for a, b in runs_of(saturated & armed)]
    stretches.sort(key=lambda ab: ab[0] - ab[1])
    result["saturated_stretches"] = len(stretches)
    result["longest_saturated_stretches_s"] = [
        [float(log.t[a]), float(log.t[b - 1])] for a, b in sorted(stretches[:MAX_STRETCHES])
    ]
    result["_series"] = {
        "t": log.t,
        "logged": log.motors,
        "predicted": pred,
        "saturated": saturated,
        "armed": armed,
    }
    return result


def check_file(
    path,
    log_index: int | None = None,
    throttle_source: str = "setpoint",
    yaw_reversed: str = "auto",
    allow_truncated: bool = False,
    thrust_linear=0,
) -> tuple[list[dict], list[str]]:
    """Every log of a file (or only `log_index`): results and skipped-log reasons.

    With a log index, or a file of one log, a bad log is an error (GpquadError). In a file of
    several logs, damaged logs and logs without motor/PID fields are skipped with a reason;
    none usable is an error."""
    count = log_count(path)
    indices = [log_index] if log_index else list(range(1, count + 1))
    strict = log_index is not None or count == 1
    results, skipped = [], []
    for index in indices:
        try:
            log = load_mixer_log(path, index, throttle_source, allow_truncated)
            results.append(check_log(log, yaw_reversed, thrust_linear))
        except GpquadError as exc:
            if strict:
                raise
            skipped.append(str(exc))
    if not results:
        raise GpquadError(
            f"no log with PID and motor fields among {len(indices)}; first "
            f"reason: {skipped[0] if skipped else 'none'}",
            source=str(path),
        )
    return results, skipped
