"""From raw log streams to engine-ready flights: the paper's data pipeline (section 2.1).

Steps, each set in `[data]` and recorded in `Flight.meta["pipeline"]` (steps 1 and 2 are the
readers' side, in gpquad.data.streams):

1. **One clock.** Every stream (a topic or a group of fields with its own timestamps) is put
   on a uniform clock of `resample_hz`: states are interpolated linearly (quaternions
   component-wise with sign continuity, then normalised), inputs and flags are held (zero-order
   hold); a stream much faster than the clock is first smoothed by a centred boxcar of one
   clock period (anti-aliasing). A grid point inside a gap longer than `max_gap_s` (or 2.5
   sample periods of a slow stream) of any required stream is invalid: flights are split
   there, never interpolated across. Logged body rates are checked against the rates the
   quaternion implies (`check_rate_units`): deg/s or a flipped axis is a one-line error.
2. **Segmentation.** Keep the in-flight samples (armed and thrust above a threshold, or a time
   range; see the readers), in runs of at least `min_segment_s`.
3. **Zero-phase FIR low-pass** (`filter_taps`, `cutoff_hz`; paper 200 taps, 5 Hz). The symmetric
   filter's delay of (taps - 1) / 2 samples is compensated exactly by time-stamping each output
   at the centre of its window; edge samples without full support are dropped, so there are no
   start-up transients.
4. **Downsampling** by `downsample` (paper 4: 100 Hz to 25 Hz).
5. **Rates and velocities from pose.** By default the body rates are those that carry each
   quaternion exactly to the next one under the engine's integrator
   (`rates_from_quaternions`), so attitude, rates and accelerations are mutually consistent;
   world velocity is rotated into the body frame with the (filtered) attitude.
6. The accelerations themselves are computed by `build_dataset` with the engine's exact discrete
   inverse (`body_accelerations`); trim subtraction and the time split happen there too.

A reference of the unfiltered measurements on the final clock is kept in
`Flight.meta["reference"]` for the integration check.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from gpquad.data.flight import MAX_PLAUSIBLE_RATE, Flight
from gpquad.data.plausibility import runs
from gpquad.data.streams import continuous_quat
from gpquad.engine.kernels.integrator import rates_from_quaternions, world_to_body
from gpquad.engine.kernels.quaternion import euler_array
from gpquad.engine.variables import (
    BODY_VEL_COLUMNS,
    POSITION_COLUMNS,
    QUAT_COLUMNS,
    RATE_COLUMNS,
    WORLD_VEL_COLUMNS,
)
from gpquad.errors import GpquadError

QUAT_COLS = QUAT_COLUMNS
RATE_COLS = RATE_COLUMNS
WORLD_VEL_COLS = WORLD_VEL_COLUMNS
POS_COLS = POSITION_COLUMNS
BODY_VEL_COLS = BODY_VEL_COLUMNS
VEL_COLS = {"body": BODY_VEL_COLS, "world": WORLD_VEL_COLS, "position": POS_COLS}


@dataclass
class LogTable:
    """A whole log on one uniform clock, before segmentation and filtering.

    table: columns t (s, log clock), qw..qz, p, q, r (rad/s, may be absent), vx, vy, vz
    (world NED m/s) or u, v, w (body m/s), the inputs, and extra signals. valid (N,) bool:
    no gap; in_flight (N,) bool. measured maps each state variable to a short description
    that starts with "measured" or "not measured".
    """

    name: str
    source: str
    table: pd.DataFrame
    valid: np.ndarray
    in_flight: np.ndarray
    rate_hz: float
    input_names: tuple[str, ...]
    measured: dict[str, str]
    streams: list[dict] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    #: Input levels the log supports (level -> {input name: column}), the choice, its map.
    levels: dict[str, dict[str, str]] = field(default_factory=dict)
    input_level: str = "explicit"
    input_columns: dict[str, str] = field(default_factory=dict)
    units: dict[str, str] = field(default_factory=dict)

    @property
    def velocity_frame(self) -> str:
        """body (u, v, w), world (vx, vy, vz) or position (x, y, z only: differentiated)."""
        cols = self.table.columns
        return "body" if "u" in cols else "world" if "vx" in cols else "position"


def is_measured(description: str) -> bool:
    """Whether a `LogTable.measured` description says the signal is real."""
    return description.startswith("measured")


def lowpass_taps(taps: int, cutoff_hz: float, rate_hz: float) -> np.ndarray:
    """Symmetric (linear-phase) FIR low-pass taps, unit DC gain."""
    from scipy.signal import firwin  # scipy.signal takes a second to import: only when used

    h = firwin(taps, cutoff_hz, fs=rate_hz)
    return h / h.sum()


def zero_phase_fir(t: np.ndarray, x: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Filter x (N, k) with symmetric taps h; return (t_out, y) with the delay compensated.

    Output j is sum_i h[i] x[j + i], stamped at the centre of its window, t[j] + (L-1)/2 dt,
    so a sine comes out without phase lag. Returns N - L + 1 samples (no edge transients).
    """
    x = np.asarray(x, dtype=float)
    two_d = x.ndim == 2
    x2 = x if two_d else x[:, None]
    L = len(h)
    if len(t) < L:
        raise ValueError("segment shorter than the filter")
    y = np.column_stack([np.convolve(x2[:, j], h[::-1], mode="valid") for j in range(x2.shape[1])])
    dt = (t[-1] - t[0]) / (len(t) - 1)
    t_out = t[: len(t) - L + 1] + 0.5 * (L - 1) * dt
    return t_out, (y if two_d else y[:, 0])


def min_samples(data) -> int:
    """Samples (at resample_hz) that a segment needs to give a few filtered, downsampled rows."""
    taps = data.filter_taps if data.cutoff_hz > 0 else 1
    return taps + 8 * data.downsample


def segments_of(log: LogTable, data) -> tuple[list[tuple[int, int]], list[str]]:
    """Usable [start, stop) ranges of log.table and notes on what was dropped."""
    keep = []
    notes = []
    need = max(int(round(data.min_segment_s * log.rate_hz)), min_samples(data))
    t = log.table["t"].to_numpy()
    for a, b in runs(log.valid & log.in_flight):
        if b - a < need:
            notes.append(
                f"dropped in-flight piece {t[a]:.2f}..{t[b - 1]:.2f} s "
                f"({(b - a) / log.rate_hz:.2f} s < {need / log.rate_hz:.2f} s)"
            )
        else:
            keep.append((a, b))
    return keep, notes


def no_flight_error(log: LogTable, data, notes: list[str]) -> GpquadError:
    t = log.table["t"].to_numpy()
    flying = float(log.in_flight.sum()) / log.rate_hz
    gaps = len(runs(~log.valid))
    detail = (
        f"{flying:.1f} s in flight by segment = '{data.segment}' over {t[0]:.1f}..{t[-1]:.1f} s"
    )
    if notes:
        detail += f", {len(notes)} piece(s) too short or cut by {gaps} gap(s)"
    return GpquadError(
        f"no usable flight in the log ({detail}); check arming/thrust, or set "
        "data.segment = 'range' with data.time_range",
        source=log.source,
        field="data.segment",
    )


def _reference(table: pd.DataFrame, t_out: np.ndarray, rates: np.ndarray) -> np.ndarray:
    """Unfiltered measurements (N, 9) at times t_out: Euler angles, body velocity, rates.

    Log rates are averaged over each step [t, t + dt], as the discrete rates are.
    """
    t = table["t"].to_numpy()
    q = np.column_stack([np.interp(t_out, t, table[c].to_numpy()) for c in QUAT_COLS])
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q = np.ascontiguousarray(q)
    if "u" in table.columns:
        vel = np.column_stack([np.interp(t_out, t, table[c].to_numpy()) for c in BODY_VEL_COLS])
    elif "vx" not in table.columns:  # position only: differences over each step
        dt = t_out[1] - t_out[0]
        world = np.column_stack(
            [
                (
                    np.interp(t_out + dt, t, table[c].to_numpy())
                    - np.interp(t_out, t, table[c].to_numpy())
                )
                / dt
                for c in POS_COLS
            ]
        )
        vel = world_to_body(q, np.ascontiguousarray(world))
    else:
        world = np.column_stack([np.interp(t_out, t, table[c].to_numpy()) for c in WORLD_VEL_COLS])
        vel = world_to_body(q, np.ascontiguousarray(world))
    if all(c in table.columns for c in RATE_COLS) and len(t_out) > 1:
        dt = t_out[1] - t_out[0]
        sub = np.linspace(0.0, dt, 9)
        w = np.full(9, 1.0 / 8)
        w[0] = w[-1] = 0.5 / 8
        times = np.minimum(t_out[:, None] + sub[None, :], t[-1])
        rates = np.column_stack([np.interp(times, t, table[c].to_numpy()) @ w for c in RATE_COLS])
    return np.hstack([euler_array(q), vel, rates])


def _step_means(x: np.ndarray, d: int) -> np.ndarray:
    """Trapezoidal means of x (M, k) over [i d, (i + 1) d] for every i (last: point value)."""
    m = len(x)
    out = x[::d].copy()
    n_full = (m - 1) // d
    if n_full > 0:
        w = np.full(d + 1, 1.0 / d)
        w[0] = w[-1] = 0.5 / d
        for i in range(n_full):
            out[i] = w @ x[i * d : i * d + d + 1]
    return out


def _filtered_reference(
    x: np.ndarray, frame: str, rates: np.ndarray, world_vel: np.ndarray | None = None
) -> np.ndarray:
    """Filtered (not downsampled-then-derived) measurements (N, 9) on the final clock."""
    q = np.ascontiguousarray(x[:, :4] / np.linalg.norm(x[:, :4], axis=1, keepdims=True))
    vel = x[:, 4:7] if world_vel is None else world_vel
    if frame != "body":
        vel = world_to_body(q, np.ascontiguousarray(vel))
    log_rates = x[:, 7:10] if x.shape[1] >= 10 else rates
    return np.hstack([euler_array(q), vel, log_rates])


def process_segment(log: LogTable, a: int, b: int, data, index: int) -> Flight:
    """Filter, downsample and derive rates/velocities for table rows [a, b)."""
    seg = log.table.iloc[a:b]
    t = seg["t"].to_numpy()
    vel_cols = VEL_COLS[log.velocity_frame]
    has_rates = all(c in seg.columns for c in RATE_COLS)
    state_cols = list(QUAT_COLS) + list(vel_cols) + (list(RATE_COLS) if has_rates else [])
    inputs = list(log.input_names)
    x_state = seg[state_cols].to_numpy(dtype=float, copy=True)
    x_state[:, :4] = continuous_quat(x_state[:, :4])
    x_in = seg[inputs].to_numpy(dtype=float, copy=True)
    steps = [f"resampled to {log.rate_hz:g} Hz (states interpolated, inputs held)"]
    if data.cutoff_hz > 0:
        h = lowpass_taps(data.filter_taps, data.cutoff_hz, log.rate_hz)
        t_f, x_state = zero_phase_fir(t, x_state, h)
        if data.filter_inputs:
            _, x_in = zero_phase_fir(t, x_in, h)
        else:
            x_in = x_in[(len(h) - 1) // 2 : (len(h) - 1) // 2 + len(t_f)]
        t = t_f
        steps.append(
            f"zero-phase FIR low-pass: {data.filter_taps} taps, {data.cutoff_hz:g} Hz "
            f"(delay {(data.filter_taps - 1) / 2:g} samples compensated; inputs "
            f"{'filtered' if data.filter_inputs else 'not filtered'})"
        )
    d = data.downsample
    filtered_ref = x_state[::d].copy()
    if has_rates:  # the discrete rate is the mean over [t, t + dt]: average the gyro likewise
        filtered_ref[:, 7:10] = _step_means(x_state[:, 7:10], d)
    t, x_state, x_in = t[::d], x_state[::d], x_in[::d]
    rate = log.rate_hz / d
    dt = 1.0 / rate
    steps.append(f"downsampled by {d} to {rate:g} Hz")
    quat = x_state[:, :4] / np.linalg.norm(x_state[:, :4], axis=1, keepdims=True)
    quat = np.ascontiguousarray(quat)
    if data.rates_from == "quaternion" or not has_rates:
        rates = rates_from_quaternions(quat, dt)
        steps.append("body rates from the quaternion (exact inverse of the integrator)")
        n = len(t) - 1
    else:
        rates = x_state[:, 7:10]
        steps.append("body rates from the log (filtered)")
        n = len(t)
    world_vel = ref_vel = None
    if log.velocity_frame == "position":  # exact inverse of x_{t+1} = x_t + R(q_t) V_t dt
        n = min(n, len(t) - 1)
        world_vel = (x_state[1 : n + 1, 4:7] - x_state[:n, 4:7]) / dt
        ref_vel = (filtered_ref[1 : n + 1, 4:7] - filtered_ref[:n, 4:7]) / dt
    t, quat, x_state, x_in, rates = t[:n], quat[:n], x_state[:n], x_in[:n], rates[:n]
    if world_vel is not None:
        vel = world_to_body(quat, np.ascontiguousarray(world_vel))
        steps.append(
            "body velocity from position differences (exact inverse of the "
            "integrator's position update)"
        )
    elif log.velocity_frame == "world":
        vel = world_to_body(quat, np.ascontiguousarray(x_state[:, 4:7]))
        steps.append("body velocity = world velocity rotated by the filtered attitude")
    else:
        vel = np.ascontiguousarray(x_state[:, 4:7])
    if np.abs(rates).max() > MAX_PLAUSIBLE_RATE:
        raise GpquadError(
            f"body rates reach {np.abs(rates).max():.1f} rad/s, implausible; "
            "degrees where radians are expected?",
            source=log.source,
            field="p",
        )
    meta = {
        "source": log.source,
        "log": log.name,
        "segment": index,
        "t_start_s": float(t[0]),
        "t_stop_s": float(t[-1]),
        "dt": dt,
        "measured": dict(log.measured),
        "pipeline": steps,
        "input_level": log.input_level,
        "reference_raw": _reference(log.table.iloc[a:b], t, rates),
        "reference": _filtered_reference(filtered_ref[:n], log.velocity_frame, rates, ref_vel),
    }
    return Flight(
        name=f"{log.name}#{index}",
        t=t,
        quat=quat,
        vel=np.ascontiguousarray(vel),
        rates=np.ascontiguousarray(rates),
        inputs=np.ascontiguousarray(x_in),
        input_names=tuple(inputs),
        pos=None,
        meta=meta,
    )


def flights_from_log(log: LogTable, data) -> list[Flight]:
    """The in-flight segments of a log, filtered and downsampled per the config.

    Raises GpquadError when no segment is long enough.
    """
    keep, notes = segments_of(log, data)
    log.notes.extend(notes)
    if not keep:
        raise no_flight_error(log, data, notes)
    return [process_segment(log, a, b, data, i) for i, (a, b) in enumerate(keep)]
