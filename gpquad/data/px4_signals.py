"""PX4 signals beyond attitude and velocity, in the 2016 and the v1.14+ topic layouts.

- torque and thrust, roll_cmd, pitch_cmd, yaw_cmd ([-1, 1]) and thrust_cmd ([0, 1]):
  actuator_controls_0 control[0..3] (2016), or vehicle_torque_setpoint xyz[0..2] and
  vehicle_thrust_setpoint -xyz[2] (v1.14+);
- rate set-points p_sp, q_sp, r_sp (rad/s) and thrust_sp: vehicle_rates_setpoint roll,
  pitch, yaw and thrust (2016) or -thrust_body[2] (v1.14+);
- sticks rc_0 .. rc_7 ((PWM - 1500) / 500): input_rc values[i];
- motors motor_0 .. motor_3 ([0, 1]): actuator_motors control[i] (v1.14+), else
  actuator_outputs scaled by PWM_MIN..PWM_MAX; motor speeds esc_krpm_i (1000 rpm):
  esc_status esc[i].esc_rpm;
- reset counters: quat_reset_counter of vehicle_attitude (v1.14+) or control_state (2016);
  xy, z, vxy, vz reset counters of vehicle_local_position.

Levels (gpquad.data.levels): rates, torque, sticks (channels from RC_MAP_ROLL, RC_MAP_PITCH,
RC_MAP_YAW, RC_MAP_THROTTLE), motors. Times are `timestamp_sample` where a topic logs it
(the time of the measurement the message is about), else `timestamp`.
"""

from __future__ import annotations

import numpy as np

from gpquad.data.levels import paper_names

#: Reset counters: table column -> (topic, field, description).
COUNTERS = {
    "att_reset": ("vehicle_attitude", "quat_reset_counter", "attitude reset counter"),
    "att_reset_cs": ("control_state", "quat_reset_counter", "attitude reset counter"),
    "xy_reset": ("vehicle_local_position", "xy_reset_counter", "position reset counter"),
    "z_reset": ("vehicle_local_position", "z_reset_counter", "height reset counter"),
    "vxy_reset": ("vehicle_local_position", "vxy_reset_counter", "velocity reset counter"),
    "vz_reset": ("vehicle_local_position", "vz_reset_counter", "vertical velocity reset counter"),
}
TORQUE_COLUMNS = ("roll_cmd", "pitch_cmd", "yaw_cmd", "thrust_cmd")
UNITS = {"p_sp": " (rad/s)", "q_sp": " (rad/s)", "r_sp": " (rad/s)"}


def torque_stream(tp):
    """Torque and thrust commands from actuator_controls_0, else the v1.14+ setpoints."""
    if tp.has("actuator_controls_0") or not tp.has("vehicle_torque_setpoint"):
        return tp.stream(
            "actuator_controls_0", [f"control[{i}]" for i in range(4)], TORQUE_COLUMNS, "hold"
        )
    torque = tp.stream(
        "vehicle_torque_setpoint", ["xyz[0]", "xyz[1]", "xyz[2]"], TORQUE_COLUMNS[:3], "hold"
    )
    thrust = tp.stream(
        "vehicle_thrust_setpoint", ["xyz[2]"], TORQUE_COLUMNS[3:], "hold", scale=-1.0
    )
    return [torque, thrust]


def optional_streams(tp) -> list:
    """Factories of the optional streams the log has (each may raise GpquadError)."""
    out = []
    if tp.has("vehicle_status"):
        out.append(
            lambda: tp.stream(
                "vehicle_status",
                ["arming_state", "nav_state"],
                ("arming_state", "nav_state"),
                "hold",
                required=False,
            )
        )
    if tp.has("vehicle_rates_setpoint"):
        sp = tp.get("vehicle_rates_setpoint")
        new = "thrust_body[2]" in sp.columns
        out.append(
            lambda: tp.stream(
                "vehicle_rates_setpoint",
                ["roll", "pitch", "yaw", "thrust_body[2]" if new else "thrust"],
                ("p_sp", "q_sp", "r_sp", "thrust_sp"),
                "hold",
                required=False,
                scale=np.array([1.0, 1.0, 1.0, -1.0 if new else 1.0]),
            )
        )
    if tp.has("input_rc"):
        out.append(
            lambda: tp.stream(
                "input_rc",
                [f"values[{i}]" for i in range(8)],
                tuple(f"rc_{i}" for i in range(8)),
                "hold",
                required=False,
                scale=1 / 500,
                offset=1500.0,
            )
        )
    if tp.has("actuator_motors"):
        out.append(
            lambda: tp.stream(
                "actuator_motors",
                [f"control[{i}]" for i in range(4)],
                tuple(f"motor_{i}" for i in range(4)),
                "hold",
                required=False,
            )
        )
    elif tp.has("actuator_outputs"):
        lo, hi = tp.params.get("PWM_MIN", 1000.0), tp.params.get("PWM_MAX", 2000.0)
        out.append(
            lambda: tp.stream(
                "actuator_outputs",
                [f"output[{i}]" for i in range(4)],
                tuple(f"motor_{i}" for i in range(4)),
                "hold",
                required=False,
                scale=1 / (hi - lo),
                offset=lo,
            )
        )
    if tp.has("esc_status"):
        esc = tp.get("esc_status")
        n = sum(1 for i in range(8) if f"esc[{i}].esc_rpm" in esc.columns)
        if n:
            out.append(
                lambda: tp.stream(
                    "esc_status",
                    [f"esc[{i}].esc_rpm" for i in range(n)],
                    tuple(f"esc_krpm_{i}" for i in range(n)),
                    "hold",
                    required=False,
                    scale=1e-3,
                )
            )
    for col, (topic, field, _) in COUNTERS.items():
        if tp.has(topic) and field in tp.get(topic).columns:
            out.append(
                lambda topic=topic, field=field, col=col: tp.stream(
                    topic, [field], (col,), "hold", required=False
                )
            )
    return out


def counter_labels(columns) -> dict[str, str]:
    return {
        c: f"{COUNTERS[c][2]} ({COUNTERS[c][0]}.{COUNTERS[c][1]})" for c in COUNTERS if c in columns
    }


def levels(columns, params: dict) -> dict[str, dict[str, str]]:
    """Input levels this log supports: level -> {input name: table column}."""
    cols = set(columns)
    out = {}
    if {"p_sp", "q_sp", "r_sp", "thrust_sp"} <= cols:
        out["rates"] = paper_names("q_sp", "p_sp", "r_sp", "thrust_sp")
    if set(TORQUE_COLUMNS) <= cols:
        out["torque"] = paper_names("pitch_cmd", "roll_cmd", "yaw_cmd", "thrust_cmd")
    rc_map = [params.get(f"RC_MAP_{k}") for k in ("PITCH", "ROLL", "YAW", "THROTTLE")]
    if all(m and 1 <= m <= 8 for m in rc_map) and all(f"rc_{int(m) - 1}" in cols for m in rc_map):
        out["sticks"] = paper_names(*(f"rc_{int(m) - 1}" for m in rc_map))
    motors = [f"motor_{i}" for i in range(4)]
    if set(motors) <= cols:
        out["motors"] = {m: m for m in motors}
    return out
