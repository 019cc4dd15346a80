"""Flights of rotorpy's vehicles for the benchmark's `rotorpy-*` scenarios.

Three fleets: "tuned", rotorpy's crazyflie and hummingbird (the `rotorpy-*` scenarios, on which
the engine settings of experiments/recommended.toml were measured and chosen); "heldout",
rotorpy's brushless crazyflie (the `rotorpy-heldout-*` scenarios: a vehicle that no setting was
chosen on; its attitude loop, kp_att 3265 and kd_att 362, is six to eight times stiffer than
the tuned fleet's, its motor lag 50 ms); and "px4sih", rotorpy's parameters of PX4's SIH quad X
(the `rotorpy-px4sih-*` scenarios: 1 kg, arms of 0.24 m, motor lag 50 ms). rotorpy ships no
attitude gains for it, so it gets a loop like the tuned fleet's (`GAINS`: kp_att 400, natural
frequency 20 rad/s as the crazyflie's 17.6 and the hummingbird's 23.3; kd_att 80, damping 2,
kd_att / kp_att = 4 motor lags) and the tuned fleet's rate gain k_w 40. Its yaw authority per
unit of yaw inertia is about 1/50 of the crazyflie's, so in rate mode its set-point excitation
is scaled (`EXCITATION_SCALE`: roll and pitch 0.7, yaw 0.35): the full rate-mode excitation
drives it into the ground within seconds.

Each flight: rotorpy's SE3 controller follows a slow random reference around a hover point;
a band-limited, pilot-like excitation (second-order Butterworth-filtered Gaussian noise) is
added to its set-points; the vehicle (rotorpy's crazyflie or hummingbird, aero effects and
motor lag on) flies them through rotorpy's `cmd_ctatt` (mode "angle": roll, pitch, yaw and
collective-thrust set-points) or `cmd_ctbr` (mode "rate": body-rate set-points from an
attitude-to-rate law plus excitation, and thrust). Physics at 500 Hz (rotorpy's usual step),
set-points and log at 100 Hz. The files are gpquad "table" logs in NED/FRD, which gpquad's
pipeline resamples, filters and downsamples to 25 Hz (`config` of `ensure_flights`).

Frames: rotorpy's world is z up and its body x forward, z up (FLU); both are turned by pi
about x (world x stays north): q_NED/FRD = (w, x, -y, -z), v = (vx, -vy, -vz),
rates = (p, -q, -r). Inputs: u_R, u_P, u_Y are the roll, pitch, yaw set-points (rad, ZYX
Euler angles of the commanded attitude in NED/FRD) or the p, q, r set-points (rad/s, FRD);
u_T is the commanded collective thrust divided by the vehicle's weight.

Every random draw comes from `numpy.random.default_rng([seed, stream])` with the flight's
recorded seed: stream 0 for the reference and excitation, stream 1 for the sensor noise of
the noisy variant, so the noisy flight is the clean flight plus noise. The noise family
(`noise_scale` 2 and 4 of `ensure_flights`) multiplies every SD of NOISE and GYRO_BIAS_SD and
draws the same standard normals: its noise is exactly 2 or 4 times the noisy flight's.
"""

from __future__ import annotations

import importlib
import io
import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.signal import butter, sosfilt

from gpquad.benchmark import rotorpy_model as model
from gpquad.benchmark.rotorpy_checks import LIMITS, check_flight
from gpquad.data.simulator import add_measurement_noise
from gpquad.engine.kernels.quaternion import euler_array
from gpquad.errors import GpquadError
from gpquad.study.store import atomic_write_bytes, atomic_write_text, provenance

#: Bump when the generator's output changes: cached flights of another version are remade.
GENERATOR_VERSION = 1
MODES = {"angle": model.CTATT, "rate": model.CTBR}
#: rotorpy vehicles flown per fleet, with overrides of rotorpy's cmd_ctbr body-rate gain k_w
#: (1/s): rotorpy's hummingbird has k_w = 1, a 1 s rate loop that cannot hold an attitude
#: under the SE3 position loop; 40 is close to its cmd_ctatt damping gain kd_att = 46.6. The
#: brushless crazyflie's k_w = 5.27 tilts it beyond 60 degrees within a minute of rate-mode
#: excitation; it gets the same 40.
FLEETS = {
    "tuned": {
        "crazyflie": ("rotorpy.vehicles.crazyflie_params", None),
        "hummingbird": ("rotorpy.vehicles.hummingbird_params", 40.0),
    },
    "heldout": {"crazyfliebrushless": ("rotorpy.vehicles.crazyfliebrushless_params", 40.0)},
    "px4sih": {"px4sih": ("rotorpy.vehicles.px4_sihsim_quadx_params", 40.0)},
}
VEHICLES = FLEETS["tuned"]
#: Attitude gains of vehicles whose rotorpy parameters have none (see the module docstring).
GAINS = {"px4sih": {"kp_att": 400.0, "kd_att": 80.0}}
#: Per fleet and mode: factors of EXCITATION's SDs (roll, pitch, yaw, thrust).
EXCITATION_SCALE = {"px4sih": {"rate": (0.7, 0.7, 0.35, 1.0)}}
#: Added to the flight seeds of a fleet, so that no two fleets share a seed.
FLEET_SEED_OFFSET = {"tuned": 0, "heldout": 500, "px4sih": 300}
#: Multiples of NOISE of the noise family (1 is the benchmark's noisy variant).
NOISE_SCALES = (1, 2, 4)
INPUT_NAMES = ("u_P", "u_R", "u_Y", "u_T")
LOG_HZ = 100.0
SUB_STEPS = 5  # physics at 500 Hz
ROLES = ("train", "validation", "test")
#: (role, count, duration s) per vehicle.
PLAN = (("train", 2, 150.0), ("validation", 1, 120.0), ("test", 1, 150.0))
#: Set-point excitation SD: roll, pitch, yaw (rad, angle mode; rad/s, rate mode) and thrust
#: (fraction of the weight); low-pass cutoff (Hz); rate mode's attitude-to-rate gain (1/s).
EXCITATION = {
    "angle": {"sd": (0.15, 0.15, 0.05, 0.08), "cutoff_hz": 1.0},
    "rate": {"sd": (1.0, 1.0, 0.5, 0.08), "cutoff_hz": 1.5, "rate_gain": 6.0},
}
RAMP_S = 2.0  # the excitation fades in over the first seconds
#: Slow reference: hover point (m, z up), amplitudes (m) and period range (s) of x, y, z.
REFERENCE = {"centre": (0.0, 0.0, 2.0), "amplitude": (0.8, 0.8, 0.3), "period_s": (20.0, 40.0)}
#: Sensor noise of the noisy variant (SD): attitude rad, velocity m/s, rates rad/s; the gyro
#: bias is constant per flight, drawn with this SD per axis (rad/s).
NOISE = {"attitude": 0.005, "velocity": 0.03, "rates": 0.02}
GYRO_BIAS_SD = 0.01
#: The [data] fields with which gpquad's pipeline reads these files.
DATA_CONFIG = {
    "format": "table",
    "frame": "NED/FRD",
    "inputs": list(INPUT_NAMES),
    "segment": "none",
    "resample_hz": LOG_HZ,
    "max_gap_s": 0.2,
    "filter_taps": 200,
    "cutoff_hz": 5.0,
    "filter_inputs": True,
    "downsample": 4,
    "rates_from": "quaternion",
    "trim": "none",
}


@dataclass(frozen=True)
class FlightSpec:
    """One flight: vehicle, role (train, validation, test), index, seed, duration (s)."""

    mode: str
    vehicle: str
    role: str
    index: int
    seed: int
    duration_s: float

    @property
    def name(self) -> str:
        return f"{self.vehicle}_{self.role}{self.index}"


def flight_plan(mode: str, fleet: str = "tuned") -> list[FlightSpec]:
    """Every flight of a mode and fleet with its fixed seed (fleet offset, mode digit,
    vehicle, role, index)."""
    if mode not in MODES:
        raise GpquadError(f"unknown mode '{mode}'; choose {sorted(MODES)}", field="mode")
    if fleet not in FLEETS:
        raise GpquadError(f"unknown fleet '{fleet}'; choose {sorted(FLEETS)}", field="fleet")
    specs = []
    for v, vehicle in enumerate(FLEETS[fleet]):
        for r, (role, count, duration) in enumerate(PLAN):
            for i in range(count):
                seed = (
                    8000
                    + FLEET_SEED_OFFSET[fleet]
                    + 1000 * list(MODES).index(mode)
                    + 100 * v
                    + 10 * r
                    + i
                )
                specs.append(FlightSpec(mode, vehicle, role, i, seed, duration))
    return specs


def vehicle_params(vehicle: str) -> tuple[dict, float | None]:
    """rotorpy's parameter dict of a vehicle (of any fleet), with its GAINS, and the cmd_ctbr
    gain override (or None)."""
    module, k_w = next(f[vehicle] for f in FLEETS.values() if vehicle in f)
    params = importlib.import_module(module).quad_params
    return ({**params, **GAINS[vehicle]} if vehicle in GAINS else params), k_w


def fleet_of(vehicle: str) -> str:
    return next(name for name, f in FLEETS.items() if vehicle in f)


def reference(rng: np.random.Generator, t: np.ndarray) -> np.ndarray:
    """Slow reference (N, 10): position, velocity, acceleration (world z up) and yaw 0."""
    amp = np.asarray(REFERENCE["amplitude"])
    omega = 2.0 * np.pi / rng.uniform(*REFERENCE["period_s"], size=3)
    phase = rng.uniform(0.0, 2.0 * np.pi, size=3)
    arg = omega * t[:, None] + phase
    pos = np.asarray(REFERENCE["centre"]) + amp * np.sin(arg)
    return np.hstack(
        [pos, amp * omega * np.cos(arg), -amp * omega**2 * np.sin(arg), np.zeros((len(t), 1))]
    )


def excitation(rng: np.random.Generator, n: int, mode: str, scale=(1.0, 1.0, 1.0, 1.0)):
    """Band-limited set-point excitation (n, 4) with the mode's SDs times `scale`, faded in
    over RAMP_S."""
    ex = EXCITATION[mode]
    sos = butter(2, ex["cutoff_hz"], fs=LOG_HZ, output="sos")
    warm = int(10 * LOG_HZ)  # start from the stationary filtered process
    x = sosfilt(sos, rng.standard_normal((n + warm, 4)), axis=0)[warm:]
    x = x / x.std(axis=0) * np.asarray(ex["sd"]) * np.asarray(scale)
    ramp = np.clip(np.arange(n) / (RAMP_S * LOG_HZ), 0.0, 1.0)
    return np.ascontiguousarray(x * ramp[:, None])


def simulate_flight(spec: FlightSpec) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """Fly one spec. Returns t (N,), rotorpy states (N, 20), commands (N, 5), checks."""
    params, k_w = vehicle_params(spec.vehicle)
    veh = model.vehicle_arrays(params, k_w)
    n = int(round(spec.duration_s * LOG_HZ)) + 1
    t = np.arange(n) / LOG_HZ
    rng = np.random.default_rng([spec.seed, 0])
    ref = np.ascontiguousarray(reference(rng, t))
    scale = EXCITATION_SCALE.get(fleet_of(spec.vehicle), {}).get(spec.mode, (1.0,) * 4)
    exc = excitation(rng, n, spec.mode, scale)
    s0 = np.zeros(20)
    s0[0:6] = ref[0, 0:6]
    s0[9] = 1.0
    s0[16:] = model.hover_rotor_speed(params)
    states, commands = np.zeros((n, 20)), np.zeros((n, 5))
    flown = model.fly(
        s0,
        veh,
        MODES[spec.mode],
        ref,
        exc,
        EXCITATION[spec.mode].get("rate_gain", 0.0),
        SUB_STEPS,
        1.0 / (LOG_HZ * SUB_STEPS),
        states,
        commands,
    )
    checks = check_flight(
        spec, t, states, ref, flown, (params["rotor_speed_min"], params["rotor_speed_max"])
    )
    return t, states, commands, checks


def to_ned_frame(spec: FlightSpec, t, states, commands, weight: float) -> pd.DataFrame:
    """The flight as a gpquad table in NED/FRD: t, quaternion, world velocity, rates,
    position and the inputs u_P, u_R, u_Y, u_T (see the module docstring)."""
    flip = np.array([1.0, -1.0, -1.0])
    quat = np.column_stack([states[:, 9], states[:, 6], -states[:, 7], -states[:, 8]])
    quat *= np.where(quat[:, :1] < 0, -1.0, 1.0)
    cols = {"t": t}
    cols.update(dict(zip(("qw", "qx", "qy", "qz"), quat.T)))
    cols.update(dict(zip(("vx", "vy", "vz"), (states[:, 3:6] * flip).T)))
    cols.update(dict(zip(("p", "q", "r"), (states[:, 10:13] * flip).T)))
    cols.update(dict(zip(("x", "y", "z"), (states[:, 0:3] * flip).T)))
    if spec.mode == "angle":
        cq = np.ascontiguousarray(
            np.column_stack([commands[:, 4], commands[:, 1], -commands[:, 2], -commands[:, 3]])
        )
        roll, pitch, yaw = euler_array(cq).T
    else:
        roll, pitch, yaw = (commands[:, 1:4] * flip).T
    cols.update({"u_P": pitch, "u_R": roll, "u_Y": yaw, "u_T": commands[:, 0] / weight})
    return pd.DataFrame(cols)


def noise_sd(scale: float = 1.0) -> dict:
    """The sensor noise SDs of the noisy variant times `scale` (with "gyro_bias_sd")."""
    return {k: scale * v for k, v in {**NOISE, "gyro_bias_sd": GYRO_BIAS_SD}.items()}


def add_sensor_noise(frame: pd.DataFrame, seed: int, scale: float = 1.0) -> pd.DataFrame:
    """The noisy variant of a clean flight table: NOISE plus a constant gyro bias, every SD
    times `scale`, from default_rng([seed, 1]) (the flight itself is unchanged)."""
    rng = np.random.default_rng([seed, 1])
    sd = noise_sd(scale)
    quat = frame[["qw", "qx", "qy", "qz"]].to_numpy()
    vel = frame[["vx", "vy", "vz"]].to_numpy()
    rates = frame[["p", "q", "r"]].to_numpy()
    q, v, w = add_measurement_noise(quat, vel, rates, sd, rng)
    w = w + rng.normal(0.0, sd["gyro_bias_sd"], size=3)
    out = frame.copy()
    out[["qw", "qx", "qy", "qz"]] = q * np.where(q[:, :1] < 0, -1.0, 1.0)
    out[["vx", "vy", "vz"]] = v
    out[["p", "q", "r"]] = w
    return out


def settings(mode: str, noisy: bool, fleet: str = "tuned", noise_scale: float = 1.0) -> dict:
    """Everything that determines the files (compared with a cache's manifest)."""
    vehicles = FLEETS[fleet]
    extra = {
        "gains": {v: GAINS[v] for v in vehicles if v in GAINS},
        "excitation_scale": EXCITATION_SCALE.get(fleet, {}).get(mode),
        "noise_scale": noise_scale if noisy and noise_scale != 1 else None,
    }
    return {
        "generator_version": GENERATOR_VERSION,
        "mode": mode,
        "noisy": noisy,
        **({} if fleet == "tuned" else {"fleet": fleet}),
        **{k: v for k, v in extra.items() if v},  # only where set: older caches stay valid
        "plan": [asdict(s) for s in flight_plan(mode, fleet)],
        "vehicles": list(vehicles),
        "ctbr_k_w_override": {v: k for v, (_, k) in vehicles.items()},
        "excitation": EXCITATION[mode],
        "ramp_s": RAMP_S,
        "reference": REFERENCE,
        "log_hz": LOG_HZ,
        "physics_hz": LOG_HZ * SUB_STEPS,
        "limits": LIMITS,
        "noise": noise_sd(noise_scale) if noisy else None,
        "data_config": DATA_CONFIG,
    }


def _parquet_bytes(frame: pd.DataFrame) -> bytes:
    buf = io.BytesIO()
    frame.to_parquet(buf, index=False)
    return buf.getvalue()


def _result(folder: Path, specs: list[FlightSpec], mode: str, noisy: bool) -> dict:
    out = {
        role: [str(folder / f"{s.name}.parquet") for s in specs if s.role == role] for role in ROLES
    }
    out.update(
        {
            "input_names": INPUT_NAMES,
            "config": dict(DATA_CONFIG),
            "vehicles": list(dict.fromkeys(s.vehicle for s in specs)),
            "seeds": [s.seed for s in specs],
            "flights": [
                {
                    "path": str(folder / f"{s.name}.parquet"),
                    "vehicle": s.vehicle,
                    "role": s.role,
                    "seed": s.seed,
                    "duration_s": s.duration_s,
                }
                for s in specs
            ],
            "mode": mode,
            "noisy": noisy,
        }
    )
    return out


def _cached(folder: Path, wanted: dict, specs: list[FlightSpec]) -> bool:
    manifest = folder / "manifest.json"
    if not manifest.is_file():
        return False
    try:
        stored = json.loads(manifest.read_text())["settings"]
    except (ValueError, KeyError):
        return False
    return stored == json.loads(json.dumps(wanted)) and all(
        (folder / f"{s.name}.parquet").is_file() for s in specs
    )


def ensure_flights(
    mode: str,
    noisy: bool,
    cache_dir: str | Path,
    progress=None,
    fleet: str = "tuned",
    noise_scale: float = 1,
) -> dict:
    """The rotorpy flights of a mode and fleet, generated once and cached under
    cache_dir/[<fleet>-]<mode>[-noisy[<k>x]] (no prefix for the tuned fleet; the suffix
    -noisy2x for noise_scale 2 of a noisy variant).

    mode "angle" or "rate"; fleet a key of FLEETS; noise_scale one of NOISE_SCALES.
    Returns {"train", "validation", "test": [absolute paths], "input_names", "config":
    [data] fields for gpquad's pipeline, "vehicles", "seeds" (one per flight, in the order
    train, validation, test per vehicle),
    "flights" (path, vehicle, role, seed, duration_s of each), "mode", "noisy"}.
    Files are 100 Hz gpquad "table" logs (Parquet, NED/FRD); the noisy variant is the clean
    flights plus sensor noise. Each file and then the manifest are written atomically; a
    cache made with other settings is regenerated. progress: optional callable(str).
    """
    if noise_scale not in NOISE_SCALES:
        raise GpquadError(
            f"noise scale {noise_scale} is not one of {NOISE_SCALES}", field="noise_scale"
        )
    specs = flight_plan(mode, fleet)
    clean_name = mode if fleet == "tuned" else f"{fleet}-{mode}"
    clean_folder = Path(cache_dir).resolve() / clean_name
    suffix = "-noisy" + (f"{noise_scale:g}x" if noise_scale != 1 else "")
    folder = clean_folder.with_name(clean_name + suffix) if noisy else clean_folder
    wanted = settings(mode, noisy, fleet, noise_scale)
    if _cached(folder, wanted, specs):
        return _result(folder, specs, mode, noisy)
    flights = {}
    if noisy:
        clean = ensure_flights(mode, False, cache_dir, progress, fleet)
        clean_meta = json.loads((Path(clean["train"][0]).parent / "manifest.json").read_text())
        for s in specs:
            frame = pd.read_parquet(clean_folder / f"{s.name}.parquet")
            noisy_frame = add_sensor_noise(frame, s.seed, noise_scale)
            atomic_write_bytes(folder / f"{s.name}.parquet", _parquet_bytes(noisy_frame))
            flights[s.name] = clean_meta["flights"][s.name]
    else:
        for s in specs:
            if progress:
                progress(f"rotorpy {mode}: flying {s.name} ({s.duration_s:g} s, seed {s.seed})")
            t, states, commands, checks = simulate_flight(s)
            weight = vehicle_params(s.vehicle)[0]["mass"] * model.GRAVITY
            frame = to_ned_frame(s, t, states, commands, weight)
            atomic_write_bytes(folder / f"{s.name}.parquet", _parquet_bytes(frame))
            flights[s.name] = {"seed": s.seed, "role": s.role, "checks": checks}
    result = _result(folder, specs, mode, noisy)
    manifest = {
        "settings": wanted,
        "flights": flights,
        "provenance": provenance(),
        "result": {k: list(v) if isinstance(v, tuple) else v for k, v in result.items()},
    }
    atomic_write_text(folder / "check.toml", data_toml())
    atomic_write_text(folder / "manifest.json", json.dumps(manifest, indent=2) + "\n")
    return result


def data_toml() -> str:
    """DATA_CONFIG as a TOML [data] section (for `gpquad data check FILE --config ...`)."""
    lines = ["# [data] settings with which gpquad reads these rotorpy flights", "[data]"]
    for k, v in DATA_CONFIG.items():
        lines.append(f"{k} = {json.dumps(v)}")
    return "\n".join(lines) + "\n"
