"""PX4 logs as topic tables: a folder of `ulog2csv` CSVs (format "px4-csv").

`px4_log_table` turns topic tables (from CSVs or from a .ulg, see gpquad.data.ulog) into one
`LogTable` on one clock. Signals used (PX4 conventions, NED/FRD, SI units):

- vehicle_attitude: q[0..3] (w, x, y, z), body-to-world; rollspeed/pitchspeed/yawspeed
  (rad/s), or vehicle_angular_velocity xyz[0..2] in newer logs.
- vehicle_local_position: vx, vy, vz (NED m/s), with the v_xy_valid / v_z_valid flags. A
  velocity whose flag is never set was not measured: it is kept (the log's value, usually 0)
  but reported as "not measured"; when the flag is set only part of the time, the invalid rows
  are gaps.
- actuator_controls_0: control[0..3] = roll, pitch, yaw torque in [-1, 1] and thrust in [0, 1];
  the default inputs u_R, u_P, u_Y, u_T.
- vehicle_status: arming_state (2 = armed), nav_state; vehicle_rates_setpoint (rad/s);
  input_rc (PWM us -> (pwm - 1500) / 500); actuator_outputs (PWM us -> (pwm - PWM_MIN) /
  (PWM_MAX - PWM_MIN) from the parameters). These are extra columns that `[data.columns]` can
  map to inputs, e.g. `u_T = "motor_0"`.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd

from gpquad.data.flight import Flight
from gpquad.data.levels import check_input_rates, resolve_inputs
from gpquad.data.pipeline import LogTable, flights_from_log
from gpquad.data.plausibility import check_rate_peak, check_rate_units
from gpquad.data.px4_signals import UNITS, counter_labels, optional_streams, torque_stream
from gpquad.data.px4_signals import levels as px4_levels
from gpquad.data.resets import reset_mask
from gpquad.data.streams import Stream, in_flight_mask, resample
from gpquad.errors import GpquadError

#: PX4's ARMING_STATE_ARMED (2016 and later).
ARMED = 2
REQUIRED_TOPICS = ("vehicle_attitude", "vehicle_local_position")


class Topics:
    """Topic tables of one log: name -> DataFrame (timestamp in us), with their sources."""

    def __init__(
        self, tables: dict[str, pd.DataFrame], sources: dict[str, str], params: dict, where: str
    ):
        self.tables = tables
        self.sources = sources
        self.params = params
        self.where = where

    def has(self, topic: str) -> bool:
        return topic in self.tables and len(self.tables[topic]) > 0

    def get(self, topic: str) -> pd.DataFrame:
        if topic not in self.tables:
            hint = (
                "the .ulg may be truncated before its first message"
                if self.where.lower().endswith(".ulg")
                else f"expected a file *_{topic}_0.csv"
            )
            raise GpquadError(f"missing topic '{topic}' ({hint})", source=self.where, field=topic)
        return self.tables[topic]

    def column(self, topic: str, name: str) -> np.ndarray:
        df = self.get(topic)
        if name not in df.columns:
            raise GpquadError(
                f"missing column '{name}' in topic '{topic}'",
                source=self.sources.get(topic, self.where),
                field=name,
            )
        return pd.to_numeric(df[name], errors="coerce").to_numpy(dtype=float)

    def time_field(self, topic: str) -> str:
        """`timestamp_sample` where the topic logs it (increasing), else `timestamp`."""
        df = self.get(topic)
        if "timestamp_sample" in df.columns:
            ts = pd.to_numeric(df["timestamp_sample"], errors="coerce").to_numpy(dtype=float)
            if len(ts) > 1 and np.isfinite(ts).all() and (np.diff(ts) > 0).all():
                return "timestamp_sample"
        return "timestamp"

    def time(self, topic: str) -> np.ndarray:
        """Topic times in s (from microseconds)."""
        return self.column(topic, self.time_field(topic)) * 1e-6

    def stream(
        self,
        topic: str,
        fields,
        columns,
        kind: str,
        required: bool = True,
        scale=1.0,
        offset: float = 0.0,
    ) -> Stream:
        scales = np.broadcast_to(np.asarray(scale, dtype=float), (len(fields),))
        values = np.column_stack(
            [(self.column(topic, f) - offset) * k for f, k in zip(fields, scales, strict=True)]
        )
        return Stream(
            topic,
            self.time(topic),
            values,
            tuple(columns),
            kind,
            self.sources.get(topic, self.where),
            self.time_field(topic),
            required,
        )


_TOPIC_FILE = re.compile(r"^(?P<topic>.+)_(?P<inst>\d+)\.csv$")


def read_octave_params(path: Path) -> dict[str, float]:
    """Parameters from ulog2csv's `parameters.octave` (name -> value)."""
    params = {}
    name = None
    for line in path.read_text(errors="replace").splitlines():
        if line.startswith("# name "):
            name = line[7:].strip()
        elif line and not line.startswith("#") and name:
            try:
                params[name] = float(line.strip())
            except ValueError:
                pass
            name = None
    return params


def read_px4_folder(path) -> Topics:
    """Topic tables from a folder of `<log>_<topic>_<instance>.csv` files (ulog2csv)."""
    path = Path(path)
    if not path.is_dir():
        if not path.exists():
            raise GpquadError("no such file or folder", source=str(path))
        raise GpquadError(
            "not a folder of ulog2csv topic CSVs (format px4-csv); give the "
            "folder ulog2csv wrote, or a .ulg file",
            source=str(path),
        )
    files = sorted(path.glob("*.csv"))
    if not files:
        raise GpquadError("no topic CSVs in the folder", source=str(path))
    stems = [f.name for f in files]
    prefix = _common_prefix(stems)
    tables, sources = {}, {}
    for f in files:
        m = _TOPIC_FILE.match(f.name[len(prefix) :])
        if not m:
            continue
        topic, inst = m.group("topic"), int(m.group("inst"))
        key = topic if inst == 0 else f"{topic}#{inst}"
        if topic not in _WANTED:
            continue
        try:
            tables[key] = pd.read_csv(f)
        except Exception as exc:  # truncated or corrupt CSV
            raise GpquadError(
                f"cannot read the topic CSV ({type(exc).__name__}: {exc})", source=str(f)
            ) from None
        sources[key] = str(f)
    octave = path / "parameters.octave"
    params = read_octave_params(octave) if octave.is_file() else {}
    return Topics(tables, sources, params, str(path))


_WANTED = {
    "vehicle_attitude",
    "vehicle_angular_velocity",
    "vehicle_local_position",
    "sensor_combined",
    "vehicle_acceleration",
    "actuator_controls_0",
    "vehicle_status",
    "vehicle_rates_setpoint",
    "input_rc",
    "actuator_outputs",
    "control_state",
    "vehicle_torque_setpoint",
    "vehicle_thrust_setpoint",
    "actuator_motors",
    "esc_status",
}


def _common_prefix(names: list[str]) -> str:
    """The log-name prefix `<log>_` shared by ulog2csv files (empty if there is none)."""
    for topic in ("vehicle_attitude_0.csv", "actuator_controls_0_0.csv"):
        for n in names:
            if n.endswith("_" + topic):
                return n[: -len(topic)]
    return ""


def _velocity_stream(tp: Topics, measured: dict) -> Stream:
    topic = "vehicle_local_position"
    t = tp.time(topic)
    vel = np.column_stack([tp.column(topic, c) for c in ("vx", "vy", "vz")])
    df = tp.get(topic)
    for flag, axes in (("v_xy_valid", ("u", "v")), ("v_z_valid", ("w",))):
        cols = [0, 1] if flag == "v_xy_valid" else [2]
        if flag not in df.columns:
            for a in axes:
                measured[a] = "measured (estimator velocity; no validity flag in the log)"
            continue
        ok = tp.column(topic, flag) > 0.5
        if not ok.any():
            for a in axes:
                measured[a] = (
                    f"not measured ({flag} = 0 throughout; the log's value "
                    f"{np.nanmean(np.abs(vel[:, cols])):.3g} m/s is kept)"
                )
        else:
            for a in axes:
                measured[a] = (
                    f"measured (estimator, {flag} = 1 for {ok.mean():.0%} of rows; "
                    "invalid rows are gaps)"
                )
            vel[~ok] = np.nan  # a gap: never interpolated across
    return Stream(topic, t, vel, ("vx", "vy", "vz"), "state", tp.sources.get(topic, tp.where))


def px4_log_table(tp: Topics, data, name: str) -> LogTable:
    """One PX4 log on one clock (see the module docstring for the signals)."""
    for topic in REQUIRED_TOPICS:
        tp.get(topic)
    measured = {}
    streams = [
        tp.stream(
            "vehicle_attitude", [f"q[{i}]" for i in range(4)], ("qw", "qx", "qy", "qz"), "quat"
        )
    ]
    measured.update(
        {a: "measured (estimator attitude quaternion)" for a in ("phi", "theta", "psi")}
    )
    att = tp.get("vehicle_attitude")
    rate_fields = None
    if "rollspeed" in att.columns:
        rate_topic, rate_fields = "vehicle_attitude", ("rollspeed", "pitchspeed", "yawspeed")
    elif tp.has("vehicle_angular_velocity"):
        rate_topic, rate_fields = "vehicle_angular_velocity", ("xyz[0]", "xyz[1]", "xyz[2]")
    s_rates = None
    if rate_fields is not None:
        s_rates = tp.stream(rate_topic, rate_fields, ("p", "q", "r"), "state")
        check_rate_peak(s_rates.values, s_rates.source, rate_fields)
        streams.append(s_rates)
        measured.update({a: "measured (gyro, estimator output)" for a in ("p", "q", "r")})
    else:
        measured.update({a: "measured (derived from the quaternion only)" for a in "pqr"})
    streams.append(_velocity_stream(tp, measured))
    torque = torque_stream(tp)
    streams.extend(torque if isinstance(torque, list) else [torque])
    notes = []
    armed_ok = False
    for make in optional_streams(tp):
        try:
            s = make()
            if len(s.t) >= 2 and np.all(np.diff(s.t) > 0):
                streams.append(s)
                armed_ok |= s.name == "vehicle_status"
            else:
                notes.append(f"skipped topic {s.name}: timestamps not increasing")
        except GpquadError as exc:
            notes.append(f"skipped optional topic: {exc}")
    columns = ["t"] + [c for s in streams for c in s.columns]
    supported = px4_levels(columns, tp.params)
    inputs, chosen = resolve_inputs(data, supported, columns, tp.where)
    for s in streams:  # an optional signal used as an input: its gaps split the flight too
        s.required = s.required or bool(set(s.columns) & set(inputs.values()))
    table, valid, info = resample(streams, data.resample_hz, data.max_gap_s)
    if s_rates is not None:
        check_rate_units(table, valid, s_rates.source, rate_fields)
    bad, splits = reset_mask(
        table, data.resample_hz, counter_labels(table.columns), data.max_attitude_step_deg
    )
    valid &= ~bad
    notes.extend(splits)
    notes.extend(check_input_rates(info, inputs, {s.name: s.columns for s in streams}))
    for n_in, col in inputs.items():
        table[n_in] = table[col]
    t = table["t"].to_numpy()
    armed = (table["arming_state"].to_numpy() == ARMED) if armed_ok else None
    thrust = table["thrust_cmd"].to_numpy()
    mask = in_flight_mask(t, armed, thrust, data, tp.where)
    return LogTable(
        name=name,
        source=tp.where,
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


def read_px4_folder_log(path, data) -> LogTable:
    """A ulog2csv folder as one LogTable."""
    path = Path(path)
    return px4_log_table(read_px4_folder(path), data, path.name)


def read_px4_csv(path, data) -> list[Flight]:
    """Reader for format "px4-csv": in-flight segments of a ulog2csv folder."""
    return flights_from_log(read_px4_folder_log(path, data), data)
