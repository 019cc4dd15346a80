"""Ground-truth flights from rotorpy (PyPI `rotorpy`), with the thesis's kinds of manoeuvres.

rotorpy's `Multirotor` (aero on) computes per rotor the thrust k_eta w^2 plus translational
lift k_h V_h,i^2, the rotor drag H = -w diag(k_d, k_d, k_z) V_i (so the inflow term of eq. 9 is
-k_z V_z,i w_i) and a parasitic drag -|V| diag(c_D) V. Summed over four rotors, the thesis's
eq. (19) holds with k_t = k_eta, k_z = rotor k_z, k_h = 4 k_h, and eq. (18) with
k_dx = k_dy = -4 k_d / m (rotor drag alone; the parasitic drag adds -c_D |V| V / m).

Flights follow rotorpy's own minimum-snap trajectories (`MinSnap`) flown by its geometric
controller (`SE3Control`), integrated by `Multirotor.step` at `dt`. Logged per sample: time,
world position and velocity, quaternion (x, y, z, w), body rates, rotor speeds, and the
specific force f = R^T (v_dot - g) from `Multirotor.statedot` (what an ideal accelerometer
reads; rotorpy's `Imu` draws noise from numpy's global generator, so sensor noise is added
in `sensors.py` from an explicit one instead). rotorpy draws no random numbers here (motor
noise is zero in its parameter sets), so a flight is deterministic and is cached as .npz.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np

from gpquad.errors import GpquadError

G = 9.81
PARAM_SETS = ("hummingbird", "crazyflie")
MANOEUVRES = ("hover", "forward", "lateral", "L", "U", "square")
FLIGHT_VERSION = 2  # part of the cache key: bump when the paths or the logging change


def vehicle_params(name: str) -> dict:
    if name == "hummingbird":
        from rotorpy.vehicles.hummingbird_params import quad_params
    elif name == "crazyflie":
        from rotorpy.vehicles.crazyflie_params import quad_params
    else:
        raise GpquadError(
            f"unknown rotorpy vehicle '{name}'; use one of {PARAM_SETS}", field="truth.vehicle"
        )
    return dict(quad_params)


def true_coefficients(params: dict) -> dict:
    """The coefficients of eqs. (5), (18), (19) implied by rotorpy's parameters."""
    n, m = params["num_rotors"], params["mass"]
    return {
        "mass": m,
        "k_t": params["k_eta"],
        "k_z": params.get("k_z", 0.0),
        "k_h": n * params.get("k_h", 0.0),
        "k_dx": -n * params.get("k_d", 0.0) / m,
        "k_dy": -n * params.get("k_d", 0.0) / m,
        "c_dx": -params.get("c_Dx", 0.0) / m,
        "c_dy": -params.get("c_Dy", 0.0) / m,
    }


def waypoints(
    manoeuvre: str, side: float, altitude: float = 1.0, yaw: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """Waypoints (m, world z up) and yaw angles: the thesis's L, U and square paths (with yaw,
    the vehicle faces its direction of travel), plus identification flights."""
    s, h = side, altitude
    paths = {
        "hover": [[0, 0, h], [0, 0, h + 0.4], [0, 0, h - 0.4], [0, 0, h + 0.2], [0, 0, h]],
        # out and back (forward then backward flight): the sign change of the body velocity
        # separates drag from a constant accelerometer bias
        "forward": [
            [0, 0, h],
            [1.5 * s, 0, h + 0.4 * s],
            [3 * s, 0, h],
            [1.5 * s, 0, h - 0.2 * s],
            [0, 0, h],
        ],
        "lateral": [
            [0, 0, h],
            [0, 1.5 * s, h + 0.4 * s],
            [0, 3 * s, h],
            [0, 1.5 * s, h - 0.2 * s],
            [0, 0, h],
        ],
        "L": [[0, 0, h], [s, 0, h], [s, s, h]],
        "U": [[0, 0, h], [s, 0, h], [s, s, h], [0, s, h]],
        "square": [[0, 0, h], [s, 0, h], [s, s, h], [0, s, h], [0, 0, h]],
    }
    if manoeuvre not in paths:
        raise GpquadError(
            f"unknown manoeuvre '{manoeuvre}'; use one of {MANOEUVRES}", field="manoeuvre"
        )
    corners = np.array(paths[manoeuvre], dtype=float)
    # two intermediate points per leg keep the minimum-snap path close to the straight legs
    # (not on short legs: rotorpy's MinSnap drops segments under 0.1 m and then fails)
    legs = []
    for a, b in zip(corners[:-1], corners[1:]):
        parts = 3 if np.linalg.norm(b - a) >= 0.6 else 1
        legs.append(a + np.outer(np.arange(parts) / parts, b - a))
    pts = np.vstack(legs + [corners[-1:]])
    yaws = np.zeros(len(pts))
    if yaw:
        heading = np.arctan2(np.diff(pts[:, 1]), np.diff(pts[:, 0]))
        heading = np.unwrap(np.concatenate([heading, heading[-1:]]))
        yaws = heading - heading[0]
    return pts, yaws


def simulate(
    manoeuvre: str,
    *,
    side: float = 4.0,
    speed: float = 3.0,
    yaw: bool = False,
    vehicle: str = "hummingbird",
    dt: float = 0.01,
    tail: float = 0.5,
    pre: float = 0.5,
) -> dict:
    """Fly one manoeuvre with rotorpy; arrays per sample (see the module docstring). The
    vehicle hovers `pre` s before the trajectory starts (for sensor calibration) and `tail` s
    after it ends."""
    from gpquad.extras import require

    require("rotorpy", "simulated rotorpy flights")
    from rotorpy.controllers.quadrotor_control import SE3Control
    from rotorpy.trajectories.minsnap import MinSnap
    from rotorpy.vehicles.multirotor import Multirotor

    params = vehicle_params(vehicle)
    pts, yaws = waypoints(manoeuvre, side, yaw=yaw)
    v_avg = 0.15 * speed if manoeuvre == "hover" else speed
    traj = MinSnap(pts, yaw_angles=yaws, v_avg=v_avg, v_max=3.0 * v_avg, verbose=False)
    hover = np.sqrt(params["mass"] * G / (params["num_rotors"] * params["k_eta"]))
    state = {
        "x": pts[0].copy(),
        "v": np.zeros(3),
        "q": np.array([0.0, 0.0, 0.0, 1.0]),
        "w": np.zeros(3),
        "wind": np.zeros(3),
        "rotor_speeds": np.full(params["num_rotors"], hover),
    }
    quad = Multirotor(params, initial_state=state)
    ctrl = SE3Control(params)
    t_end = pre + float(traj.t_keyframes[-1]) + tail
    n = int(round(t_end / dt)) + 1
    rows = {k: [] for k in ("x", "v", "q", "w", "rotor_speeds", "f")}
    from scipy.spatial.transform import Rotation

    for k in range(n):
        t_traj = max(0.0, k * dt - pre)
        control = ctrl.update(t_traj, state, traj.update(t_traj))
        vdot = quad.statedot(state, control, dt)["vdot"]
        rot = Rotation.from_quat(state["q"]).as_matrix()
        for key in ("x", "v", "q", "w", "rotor_speeds"):
            rows[key].append(np.array(state[key], dtype=float))
        rows["f"].append(rot.T @ (vdot - np.array([0.0, 0.0, -G])))
        state = quad.step(state, control, dt)
    out = {
        "t": np.arange(n) * dt,
        "pos": np.array(rows["x"]),
        "vel": np.array(rows["v"]),
        "quat": np.array(rows["q"]),
        "omega": np.array(rows["w"]),
        "rotor": np.array(rows["rotor_speeds"]),
        "force": np.array(rows["f"]),
    }
    if not np.all(np.isfinite(out["pos"])):
        raise GpquadError("the rotorpy flight diverged", field="truth")
    return out


def flight_key(spec: dict) -> str:
    return hashlib.sha1(json.dumps(spec, sort_keys=True).encode()).hexdigest()[:12]


def cached_flight(spec: dict, cache_dir: Path | None) -> dict:
    """`simulate(**spec)`, cached as <cache_dir>/<manoeuvre>-<hash>.npz (None: no cache)."""
    import rotorpy

    spec = dict(spec)
    pts, yaws = waypoints(spec["manoeuvre"], spec.get("side", 4.0), yaw=spec.get("yaw", False))
    key_spec = {
        **spec,
        "rotorpy": getattr(rotorpy, "__version__", "3"),
        "version": FLIGHT_VERSION,
        "waypoints": pts.round(9).tolist(),
        "yaws": yaws.round(9).tolist(),
    }
    if cache_dir is not None:
        path = Path(cache_dir) / f"{spec['manoeuvre']}-{flight_key(key_spec)}.npz"
        if path.is_file():
            with np.load(path, allow_pickle=False) as data:
                return {k: data[k] for k in data.files}
    manoeuvre = spec.pop("manoeuvre")
    flight = simulate(manoeuvre, **spec)
    if cache_dir is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".tmp.npz")
        np.savez(tmp, **flight)
        tmp.replace(path)
    return flight
