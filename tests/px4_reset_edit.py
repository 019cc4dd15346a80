"""A real PX4 log with an EKF yaw reset, made at test time by a documented edit.

The shared S250AQ_2016-12-13 flight (../shared/data/px4, GPL-3.0, not bundled) is cut to the
log times 130.0..162.0 s and to the topics the readers use; then, from 137.0 s on, every
attitude quaternion is turned by +90 degrees of yaw about the NED down axis
(q <- q_yaw90 * q, what an EKF yaw reset does to the published attitude) and control_state's
quat_reset_counter steps 0 -> 1 there. The body rates, set-points and everything else are the
flight's own values, unchanged. Nothing of the GPL log is committed: only this recipe.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

SHARED_S250 = Path(__file__).resolve().parents[2] / "shared" / "data" / "px4" / "S250AQ_2016-12-13"
START_S, END_S, RESET_S = 130.0, 162.0, 137.0
TOPICS = {  # topic -> columns kept
    "vehicle_attitude_0": [
        "timestamp",
        "rollspeed",
        "pitchspeed",
        "yawspeed",
        "q[0]",
        "q[1]",
        "q[2]",
        "q[3]",
    ],
    "vehicle_local_position_0": [
        "timestamp",
        "vx",
        "vy",
        "vz",
        "v_xy_valid",
        "v_z_valid",
        "xy_reset_counter",
        "z_reset_counter",
        "vxy_reset_counter",
        "vz_reset_counter",
    ],
    "actuator_controls_0_0": ["timestamp", "control[0]", "control[1]", "control[2]", "control[3]"],
    "vehicle_rates_setpoint_0": ["timestamp", "roll", "pitch", "yaw", "thrust"],
    "vehicle_status_0": ["timestamp", "arming_state", "nav_state"],
    "control_state_0": ["timestamp", "quat_reset_counter"],
}


def yaw_quaternion(angle: float) -> np.ndarray:
    return np.array([np.cos(angle / 2), 0.0, 0.0, np.sin(angle / 2)])


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of a (4,) with rows of b (N, 4)."""
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b.T
    return np.stack(
        [
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ],
        axis=1,
    )


def make_yaw_reset_log(folder: Path) -> Path:
    """Write the edited topic CSVs into `folder` (ulog2csv naming) and return it."""
    folder.mkdir(parents=True, exist_ok=True)
    for topic, columns in TOPICS.items():
        table = pd.read_csv(SHARED_S250 / f"log1_{topic}.csv")
        t = table["timestamp"].to_numpy() / 1e6
        table = table.loc[(t >= START_S) & (t <= END_S), columns].reset_index(drop=True)
        after = (table["timestamp"].to_numpy() / 1e6) >= RESET_S
        if topic == "vehicle_attitude_0":
            q = table[["q[0]", "q[1]", "q[2]", "q[3]"]].to_numpy()
            q[after] = quat_mul(yaw_quaternion(np.pi / 2), q[after])
            table[["q[0]", "q[1]", "q[2]", "q[3]"]] = q
        if topic == "control_state_0":
            table["quat_reset_counter"] = table["quat_reset_counter"] + after.astype(int)
        table.to_csv(folder / f"log1_{topic}.csv", index=False, float_format="%.9g")
    return folder
