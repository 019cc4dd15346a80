"""A user's log as the physics commands see it: in-flight segments in this package's frames
(world z up, body z along the thrust), with the checks that keep a bad log from giving
coefficients.

From each `gpquad.data.motor_log.MotorLog` (NED/FRD): world vectors turned by
C_w = [[0, 1, 0], [1, 0, 0], [0, 0, -1]] (NED -> ENU), body vectors by C_b = diag(1, -1, -1)
(FRD -> FLU), attitude R = C_w R_ned C_b. Segments are the runs of valid, in-flight samples of
at least `data.min_segment_s`. The thesis's causal moving average
(`regression.smoothing_window`) smooths, per segment, the accelerometer and, with the same
window (so that the two keep the same delay), the rotor speeds and the velocity; the raw
accelerometer is kept for the checks.

Checks, each one line naming the file, the field and the fix:
- the regression's signals are in the log (motor speeds, accelerometer; velocity and position
  where the command needs them);
- hover level: in hover the accelerometer's norm is g. About 1 means g instead of m/s^2;
- frame: in hover the specific force points up along the body z axis and up in the world.
  A negative level means data.frame (or the log's axes) is wrong.
"""

from __future__ import annotations

import numpy as np

from gpquad.errors import GpquadError
from gpquad.physics.mixer import runs_of
from gpquad.physics.sync import causal_moving_average

G = 9.81
C_WORLD = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
C_BODY = np.diag([1.0, -1.0, -1.0])
SHORT = {
    "rotor": "motor speeds",
    "acc": "accelerometer",
    "vel": "measured velocity",
    "pos": "measured position",
}
NEEDS = {
    "rotor": "the four rotor speeds",
    "acc": "the accelerometer (body specific force)",
    "vel": "a measured velocity",
    "pos": "a measured position (motion capture or GPS)",
}
#: Hover level of |specific force| (m/s^2) accepted as m/s^2; about 1 is a log in g.
LEVEL_RANGE = (6.0, 15.0)


def require(logs, needs: tuple[str, ...], command: str) -> None:
    """One line when a signal that the command needs is not in the log."""
    for key in needs:
        for log in logs:
            if getattr(log, key) is None:
                what = log.missing.get(key, key)
                raise GpquadError(
                    f"no {SHORT[key]} in the log ({what}); "
                    f"physics {command} needs {_needs_text(needs)}",
                    source=log.source,
                    field=key,
                )


def _needs_text(needs) -> str:
    names = [NEEDS[k] for k in needs]
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]


def physics_segments(log, data, smoothing_window: int) -> list[dict]:
    """The valid in-flight runs of a MotorLog as dicts of arrays in this package's frames:
    t, rot (N, 3, 3) body to world, rotor, force (smoothed), force_raw, and where the log
    has them vel (world), vel_body, pos, omega."""
    from scipy.spatial.transform import Rotation

    ok = log.valid & log.in_flight
    for key in ("rotor", "acc"):
        arr = getattr(log, key)
        if arr is not None:
            ok &= np.all(np.isfinite(arr), axis=1)
    rate = 1.0 / float(np.median(np.diff(log.t)))
    need = max(int(round(data.min_segment_s * rate)), 2 * smoothing_window, 20)

    def smooth(x):
        return causal_moving_average(x, smoothing_window) if smoothing_window > 1 else x

    out = []
    for a, b in runs_of(ok):
        if b - a < need:
            continue
        q = log.quat[a:b]
        rot = C_WORLD @ Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_matrix() @ C_BODY
        seg = {
            "name": f"{log.name}@{log.t[a] - log.t[0]:.1f}s",
            "source": log.source,
            "t": log.t[a:b] - log.t[a],
            "t0": float(log.t[a]),
            "rot": rot,
        }
        if log.rotor is not None:
            seg["rotor"] = smooth(log.rotor[a:b])
        if log.acc is not None:
            raw = log.acc[a:b] @ C_BODY
            seg["force_raw"] = raw
            seg["force"] = smooth(raw)
        if log.vel is not None:
            seg["vel"] = smooth(log.vel[a:b] @ C_WORLD.T)
            seg["vel_body"] = np.einsum("nji,nj->ni", rot, seg["vel"])
        if log.pos is not None:
            seg["pos"] = log.pos[a:b] @ C_WORLD.T
        if log.rates is not None:
            seg["omega"] = log.rates[a:b] @ C_BODY
        out.append(seg)
    return out


def hover_mask(seg: dict, max_speed: float, max_rate: float) -> np.ndarray:
    """Near-hover samples: slower than max_speed (when the velocity is measured) and turning
    slower than max_rate (when the rates are logged)."""
    mask = np.ones(len(seg["t"]), dtype=bool)
    if "vel" in seg:
        mask &= np.linalg.norm(seg["vel"], axis=1) < max_speed
    if "omega" in seg:
        mask &= np.linalg.norm(seg["omega"], axis=1) < max_rate
    return mask


def airborne_mask(seg: dict, min_height: float) -> np.ndarray:
    """Samples at least min_height above the segment's lowest position (all without a
    position or with min_height 0): on the ground the spinning rotors' thrust is not what
    the accelerometer reads."""
    if min_height <= 0 or "pos" not in seg:
        return np.ones(len(seg["t"]), dtype=bool)
    z = seg["pos"][:, 2]
    return z >= z.min() + min_height


def check_levels(segs: list[dict], masks: list[np.ndarray], data) -> str:
    """Units and frame of the accelerometer from its hover level (module docstring); returns
    a note on which samples were used."""
    hover = [s["force_raw"][m] for s, m in zip(segs, masks)]
    n = sum(len(h) for h in hover)
    use = hover if n >= 10 else [s["force_raw"] for s in segs]
    rots = [s["rot"][m] for s, m in zip(segs, masks)] if n >= 10 else [s["rot"] for s in segs]
    f = np.vstack(use)
    rot = np.concatenate(rots)
    note = f"hover level from {len(f)} {'hover' if n >= 10 else 'in-flight'} samples"
    source = segs[0]["source"]
    level = float(np.median(np.linalg.norm(f, axis=1)))
    if 0.5 < level < 2.0:
        raise GpquadError(
            f"the accelerometer reads {level:.3f} in hover, about 1: it is in g, "
            "not m/s^2; multiply it by 9.81 (specific force in m/s^2 is needed)",
            source=source,
            field="acc_z",
        )
    if not LEVEL_RANGE[0] < level < LEVEL_RANGE[1]:
        raise GpquadError(
            f"the accelerometer reads {level:.3g} in hover, not about 9.81 m/s^2; "
            "give the body specific force in m/s^2",
            source=source,
            field="acc_z",
        )
    body_z = float(np.median(f[:, 2]))
    world_z = float(np.median(np.einsum("nij,nj->ni", rot, f)[:, 2]))
    if body_z < 0 or world_z < 0:
        which = "body z axis" if body_z < 0 else "world vertical (attitude)"
        raise GpquadError(
            f"in hover the specific force points down along the {which} "
            f"(body {body_z:+.2f}, world {world_z:+.2f} m/s^2, expected about "
            f"+9.81 up): data.frame = '{data.frame}' does not match the log's "
            "axes",
            source=source,
            field="data.frame",
        )
    return note


def load_log_segments(cfg, needs: tuple[str, ...], command: str) -> tuple[list[dict], dict]:
    """Segments of every configured file, checked; and a summary (files, notes, data)."""
    from gpquad.data.motors import read_motor_logs

    data = cfg.data_config()
    logs = []
    for path in cfg.data_paths():
        logs.extend(read_motor_logs(path, data, cfg.vehicle.motor_pole_pairs))
    require(logs, needs, command)
    segs = []
    for log in logs:
        segs.extend(physics_segments(log, data, cfg.regression.smoothing_window))
    if not segs:
        total = sum(float(np.sum(lg.valid & lg.in_flight)) / max(len(lg.t), 1) for lg in logs)
        raise GpquadError(
            f"no valid in-flight segment of at least {data.min_segment_s:g} s "
            f"(mean in-flight valid fraction {total / len(logs):.0%}); lower "
            "data.min_segment_s or check the segmentation",
            source=logs[0].source,
            field="data.min_segment_s",
        )
    for s in segs:
        s["airborne"] = airborne_mask(s, cfg.thrust.min_height)
    masks = [
        hover_mask(s, cfg.thrust.hover_max_speed, cfg.thrust.hover_max_rate) & s["airborne"]
        for s in segs
    ]
    note = check_levels(segs, masks, data)
    for s, m in zip(segs, masks):
        s["hover"] = m
    notes = [note] + [n for lg in logs for n in lg.notes]
    return segs, {
        "files": [str(p) for p in cfg.data_paths()],
        "format": data.format,
        "frame": data.frame,
        "notes": notes,
        "segments": [
            {
                "name": s["name"],
                "duration_s": float(s["t"][-1]),
                "hover_samples": int(s["hover"].sum()),
                "airborne_samples": int(s["airborne"].sum()),
            }
            for s in segs
        ],
    }
