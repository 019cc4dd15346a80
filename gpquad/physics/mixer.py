"""Betaflight's mixer: PID sums and throttle to DShot motor commands (thesis IV.A).

Follows Betaflight 4.2 `src/main/flight/mixer.c` (mixTable, applyMixToMotors):

- PID sum per axis (axisP + axisI + axisD + axisF) limited to +-pidsum_limit (roll, pitch) and
  +-pidsum_limit_yaw, divided by PID_MIXER_SCALING = 1000 (thesis eq. 13); the yaw sum changes
  sign unless yaw_motors_reversed.
- rate mix M_i = sum over axes of scaled PID x mixer column (Table I, Betaflight's QUADX).
- if the mix range max(M) - min(M) (both taken with 0) exceeds 1, the mix is divided by the
  range and airmode puts the throttle at 0.5; otherwise airmode (or any throttle above 0.5)
  constrains the throttle into [-min M_i, 1 - max M_i] (thesis text before eq. 14).
- motor command M_cmd = M_i + T_adj (eq. 14), then DShot output
  motorOutput[0] + M_cmd (motorOutput[1] - motorOutput[0]) (eq. 16, the low end being the idle
  value of eq. 15), clipped to the output range and truncated to an integer as Betaflight's
  float-to-int16 store does.
"""

from __future__ import annotations

import numpy as np

PID_MIXER_SCALING = 1000.0
DSHOT_MIN, DSHOT_MAX = 48, 2047

# columns: throttle, roll, pitch, yaw (Betaflight mixerQuadX; the thesis's Table I)
LAYOUTS = {
    "quadx": np.array(
        [
            [1.0, -1.0, 1.0, -1.0],  # motor 1, rear right
            [1.0, -1.0, -1.0, 1.0],  # motor 2, front right
            [1.0, 1.0, 1.0, 1.0],  # motor 3, rear left
            [1.0, 1.0, -1.0, -1.0],
        ]
    ),  # motor 4, front left
}


def idle_value(
    idle_fraction: float, cmd_min: float = DSHOT_MIN, cmd_max: float = DSHOT_MAX
) -> float:
    """Idle DShot command, eq. (15): cmd_min + idle% (cmd_max - cmd_min); 5.5 % gives 158."""
    return cmd_min + idle_fraction * (cmd_max - cmd_min)


def rate_mix(
    pid_sums: np.ndarray,
    mixer: np.ndarray,
    pidsum_limit: float,
    pidsum_limit_yaw: float,
    yaw_reversed: bool = False,
) -> np.ndarray:
    """Rate mix M (N, motors) from PID sums (N, 3: roll, pitch, yaw), eq. (13)."""
    limits = np.array([pidsum_limit, pidsum_limit, pidsum_limit_yaw], dtype=float)
    scaled = np.clip(pid_sums, -limits, limits) / PID_MIXER_SCALING
    if not yaw_reversed:
        scaled = scaled * np.array([1.0, 1.0, -1.0])
    return scaled @ mixer[:, 1:4].T


def motor_commands(
    mix: np.ndarray, throttle: np.ndarray, mixer: np.ndarray, airmode: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """Motor commands M_cmd (N, motors) in [0, 1] units (eq. 14, not yet clipped) and the
    per-sample flag 'the rate mix did not fit' (range > 1: Betaflight scales it down)."""
    mix_max = np.maximum(mix.max(axis=1), 0.0)
    mix_min = np.minimum(mix.min(axis=1), 0.0)
    span = mix_max - mix_min
    over = span > 1.0
    scaled = np.where(over[:, None], mix / np.where(over, span, 1.0)[:, None], mix)
    thr = np.asarray(throttle, dtype=float).copy()
    adjust = np.ones_like(over) if airmode else thr > 0.5
    # constrainf(x, lo, hi) in Betaflight: lo wins when lo > hi cannot happen here (span <= 1)
    constrained = np.minimum(np.maximum(thr, -mix_min), 1.0 - mix_max)
    thr = np.where(~over & adjust, constrained, thr)
    if airmode:
        thr = np.where(over, 0.5, thr)
    return scaled + thr[:, None] * mixer[:, 0][None, :], over


def thrust_linearization(commands: np.ndarray, percent: float) -> np.ndarray:
    """Betaflight's `thrust_linear` (pid.c pidApplyThrustLinearization, default 0 in 4.2 and
    not written to 4.2 headers): M -> sqrt(M / t + b^2) - b, b = (1 - t) / (2 t), for M > 0."""
    if percent == 0:
        return commands
    t = percent / 100.0
    b = (1.0 - t) / (2.0 * t)
    pos = np.maximum(commands, 0.0)
    return np.where(commands > 0, np.sqrt(pos / t + b * b) - b, commands)


def dshot_output(commands: np.ndarray, low: float, high: float) -> np.ndarray:
    """DShot values, eq. (16): low + M_cmd (high - low), clipped and truncated like Betaflight."""
    out = np.clip(low + (high - low) * commands, low, high)
    return np.trunc(out)


def predict_motors(
    pid_sums: np.ndarray,
    throttle: np.ndarray,
    *,
    mixer: np.ndarray,
    low: float,
    high: float,
    pidsum_limit: float,
    pidsum_limit_yaw: float,
    airmode: bool = True,
    yaw_reversed: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """Predicted DShot motor values (N, motors) and the 'mix did not fit' flag (N,)."""
    mix = rate_mix(pid_sums, mixer, pidsum_limit, pidsum_limit_yaw, yaw_reversed)
    cmd, over = motor_commands(mix, throttle, mixer, airmode)
    return dshot_output(cmd, low, high), over


def erpm_to_rpm(erpm: np.ndarray, pole_pairs: int) -> np.ndarray:
    """Mechanical RPM from electrical RPM (eq. 17). The thesis prints RPM = ERPM x np; an
    electrical revolution is 1/np of a mechanical one, so this divides (14 magnets: np = 7)."""
    if pole_pairs < 1:
        raise ValueError("pole_pairs must be >= 1")
    return np.asarray(erpm, dtype=float) / pole_pairs


def runs_of(flag: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) index ranges where a boolean flag is true."""
    f = np.concatenate([[False], np.asarray(flag, dtype=bool), [False]])
    d = np.diff(f.astype(np.int8))
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist()))
