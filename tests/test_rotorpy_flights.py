"""The rotorpy flight generator: the numba port against rotorpy itself, frames and signs through
gpquad's pipeline, crash checks, sensor noise, caching and bit-identical regeneration."""

from __future__ import annotations

import dataclasses
import importlib

import numpy as np
import pytest

rotorpy = pytest.importorskip("rotorpy")

from rotorpy.controllers.quadrotor_control import SE3Control  # noqa: E402
from rotorpy.vehicles.multirotor import Multirotor  # noqa: E402
from scipy.spatial.transform import Rotation  # noqa: E402

from gpquad.benchmark import rotorpy_flights as rf  # noqa: E402
from gpquad.benchmark import rotorpy_model as model  # noqa: E402
from gpquad.data.dataset import build_dataset  # noqa: E402
from gpquad.data.integration_check import integration_check  # noqa: E402
from gpquad.data.table import read_table_log  # noqa: E402
from gpquad.errors import GpquadError  # noqa: E402
from gpquad.study.config import config_from_dict  # noqa: E402

VEHICLES = list(rf.VEHICLES)
ALL_VEHICLES = [v for fleet in rf.FLEETS.values() for v in fleet]


def random_state(rng, params):
    s = np.zeros(20)
    s[0:3], s[3:6], s[10:13] = rng.normal(size=3), 2 * rng.normal(size=3), rng.normal(size=3)
    s[6:10] = Rotation.random(random_state=int(rng.integers(1000))).as_quat() * 1.001
    s[16:] = model.hover_rotor_speed(params) * (1 + 0.1 * rng.normal(size=4))
    return s


@pytest.mark.parametrize("vehicle", ALL_VEHICLES)
def test_port_matches_rotorpy_derivative_low_level_laws_and_se3(vehicle):
    params, _ = rf.vehicle_params(vehicle)
    veh = model.vehicle_arrays(params)
    rng = np.random.default_rng(3)
    lo, hi = params["rotor_speed_min"], params["rotor_speed_max"]
    for _ in range(5):
        s = random_state(rng, params)
        cmd = model.hover_rotor_speed(params) * (1 + 0.1 * rng.normal(size=4))
        mr = Multirotor(params, control_abstraction="cmd_ctatt", aero=True)
        ref, out = mr._s_dot_fn(0.0, s, cmd), np.empty(20)
        model.state_derivative(s, cmd, veh, out)
        np.testing.assert_allclose(out, ref, rtol=1e-12, atol=1e-12 * np.abs(ref).max())
        state = Multirotor._unpack_state(s.copy())
        state["q"] = state["q"] / np.linalg.norm(state["q"])
        s_unit = Multirotor._pack_state(state)
        control = {
            "cmd_thrust": 0.7 * params["mass"] * 9.81,
            "cmd_q": Rotation.random(random_state=int(rng.integers(1000))).as_quat(),
            "cmd_w": rng.normal(size=3),
        }
        for mode, name, key in (
            (model.CTATT, "cmd_ctatt", "cmd_q"),
            (model.CTBR, "cmd_ctbr", "cmd_w"),
        ):
            mr.control_abstraction = name
            want = np.clip(mr.get_cmd_motor_speeds(state, control), lo, hi)
            got = np.empty(4)
            model.motor_commands(
                s_unit, control["cmd_thrust"], np.asarray(control[key]), mode, veh, got
            )
            np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-9)
        flat = {
            "x": rng.normal(size=3),
            "x_dot": rng.normal(size=3),
            "x_ddot": rng.normal(size=3),
            "yaw": 0.3,
            "yaw_dot": 0.0,
        }
        se3 = SE3Control(params).update(0.0, state, flat)
        r_des = np.empty((3, 3))
        ref10 = np.concatenate([flat["x"], flat["x_dot"], flat["x_ddot"], [0.3]])
        u1 = model.se3_setpoint(s_unit, ref10, params["mass"], r_des)
        assert u1 == pytest.approx(se3["cmd_thrust"], rel=1e-12)
        np.testing.assert_allclose(r_des, Rotation.from_quat(se3["cmd_q"]).as_matrix(), atol=1e-12)


@pytest.mark.parametrize(
    "vehicle, mode",
    [("hummingbird", "cmd_ctatt"), ("crazyflie", "cmd_ctbr"), ("crazyfliebrushless", "cmd_ctatt")],
)
def test_closed_loop_matches_rotorpy_step(vehicle, mode):
    """0.2 s of rotorpy's own Multirotor.step (solve_ivp, tight tolerances) at rotorpy's 2 ms
    step, set-points changing, the low-level law recomputed every step, against the kernels:
    RK4 in four substeps agrees to 1e-6 (the port is rotorpy's model); one RK4 step per 2 ms,
    what the generator uses, stays within 1e-4 relative (rotorpy's default solve_ivp
    tolerance is rtol 1e-3)."""
    params, _ = rf.vehicle_params(vehicle)
    veh = model.vehicle_arrays(params)
    mr = Multirotor(
        params,
        control_abstraction=mode,
        aero=True,
        integrator_kwargs={"method": "DOP853", "rtol": 1e-10, "atol": 1e-10},
    )
    s = np.zeros(20)
    s[0:3], s[3:6], s[9] = (0.0, 0.0, 2.0), (1.0, -0.5, 0.2), 1.0
    s[16:] = model.hover_rotor_speed(params)
    state = Multirotor._unpack_state(s.copy())
    mine = {4: s.copy(), 1: s.copy()}
    nxt, speeds = np.empty(20), np.empty(4)
    dt = 0.002
    for k in range(100):
        thrust = params["mass"] * 9.81 * (1.0 + 0.1 * np.sin(20 * k * dt))
        if mode == "cmd_ctatt":
            cmd = Rotation.from_euler("ZYX", [0.1, 0.3 * np.sin(15 * k * dt), 0.2]).as_quat()
            control, m = {"cmd_thrust": thrust, "cmd_q": cmd}, model.CTATT
        else:
            cmd = np.array([2.0 * np.sin(15 * k * dt), -1.0, 0.5, 0.0])
            control, m = {"cmd_thrust": thrust, "cmd_w": cmd[:3]}, model.CTBR
        state = mr.step(state, control, dt)
        for sub, x in mine.items():
            model.motor_commands(x, thrust, cmd, m, veh, speeds)
            for _ in range(sub):
                model.vehicle_step(x, speeds, veh, dt / sub, nxt)
                x[:] = nxt
    theirs = Multirotor._pack_state(state)
    assert np.abs(theirs[10:13]).max() > 0.3  # the vehicle really rotated
    scale = np.maximum(np.abs(theirs), 1.0)
    assert np.abs(mine[4] - theirs).max() < 1e-6 * scale.max()
    assert (np.abs(mine[1] - theirs) / scale).max() < 1e-4


def short_flight(tmp_path, mode, vehicle="hummingbird", duration=36.0, seed=5):
    spec = rf.FlightSpec(mode, vehicle, "train", 0, seed, duration)
    t, states, commands, checks = rf.simulate_flight(spec)
    weight = rf.vehicle_params(vehicle)[0]["mass"] * model.GRAVITY
    frame = rf.to_ned_frame(spec, t, states, commands, weight)
    return spec, frame, checks


def pipeline_dataset(frame, tmp_path, name="flight"):
    path = tmp_path / f"{name}.parquet"
    frame.to_parquet(path, index=False)
    cfg = config_from_dict({"data": {**rf.DATA_CONFIG, "files": [str(path)]}})
    flights = read_table_log(path, cfg.data)
    return flights, build_dataset(flights, validation_fraction=0.0)


def sign_gains(ds):
    """Least-squares a_y = g_y phi, a_x = g_x theta, a_z = k_T u_T + b (NED/FRD: g_y ~ +g,
    g_x ~ -g, k_T ~ -g) on the pipeline's 25 Hz accelerations."""
    s, acc = ds.arrays.states[:-1], ds.arrays.acc[:-1]
    u_t = ds.arrays.inputs[:-1, list(ds.input_names).index("u_T")]
    g_y = np.linalg.lstsq(s[:, [0]], acc[:, 1], rcond=None)[0][0]
    g_x = np.linalg.lstsq(s[:, [1]], acc[:, 0], rcond=None)[0][0]
    k_t = np.linalg.lstsq(np.column_stack([u_t, np.ones_like(u_t)]), acc[:, 2], rcond=None)[0][0]
    return g_y, g_x, k_t


@pytest.mark.parametrize(
    "mode, vehicle",
    [
        ("angle", "hummingbird"),
        ("rate", "hummingbird"),
        ("angle", "crazyfliebrushless"),
        ("rate", "crazyfliebrushless"),
        ("angle", "px4sih"),
        ("rate", "px4sih"),
    ],
)
def test_short_flight_signs_and_integration_check_through_gpquads_pipeline(tmp_path, mode, vehicle):
    _, frame, checks = short_flight(tmp_path, mode, vehicle)
    assert checks["min_altitude_m"] > 1.0 and checks["max_tilt_deg"] < 45.0
    flights, ds = pipeline_dataset(frame, tmp_path)
    check = integration_check(flights, 250, 0.05)
    assert check.passed, check.table()
    g_y, g_x, k_t = sign_gains(ds)
    # px4sih's collective swings twice the hummingbird's and its thrust lags it by about two
    # samples (50 ms motor lag): the static gain of a_z on u_T is about half of -g
    k_t_high = -4.0 if vehicle == "px4sih" else -7.0
    assert 8.0 < g_y < 10.5 and -10.5 < g_x < -8.0 and -11.0 < k_t < k_t_high, (g_y, g_x, k_t)
    s, u = ds.arrays.states, ds.arrays.inputs
    names = list(ds.input_names)
    tracked = (0, 1, 2) if mode == "angle" else (6, 7, 8)  # phi..psi or p..r follow the inputs
    for inp, j in zip(("u_R", "u_P", "u_Y"), tracked):
        assert np.corrcoef(u[:, names.index(inp)], s[:, j])[0, 1] > 0.6, inp
    assert 0.8 < u[:, names.index("u_T")].mean() < 1.2  # thrust over weight


def test_unconverted_frames_fail_the_checks(tmp_path):
    """The bad case of the sign checks: rotorpy's FLU rates are refused by gpquad's rate check,
    and a z-up world velocity flips the sign of the thrust and roll gains."""
    _, frame, _ = short_flight(tmp_path, "angle")
    flu = frame.copy()
    flu[["q", "r"]] = -flu[["q", "r"]]
    with pytest.raises(GpquadError, match="opposite sign"):
        pipeline_dataset(flu, tmp_path, "flu")
    up = frame.copy()
    up[["vy", "vz"]] = -up[["vy", "vz"]]
    g_y, _, k_t = sign_gains(pipeline_dataset(up, tmp_path, "up")[1])
    assert g_y < 0 and k_t > 0


def test_crash_and_divergence_are_errors(monkeypatch):
    spec = rf.FlightSpec("angle", "hummingbird", "train", 0, 1, 1.0)
    t = np.arange(101) / 100
    states = np.zeros((101, 20))
    states[:, 2], states[:, 9], states[:, 16:] = 2.0, 1.0, 500.0
    ref = np.zeros((101, 10))
    ref[:, 2] = 2.0
    limits = (0.0, 1500.0)
    assert rf.check_flight(spec, t, states, ref, 101, limits)["min_altitude_m"] == 2.0
    bad_cases = {
        "hit the ground": (2, 0.1),
        "diverged": (3, np.nan),
        "tilted": (6, 0.9),
        "spun": (10, 20.0),
    }
    for what, (col, value) in bad_cases.items():
        bad = states.copy()
        bad[50:, col] = value
        with pytest.raises(GpquadError, match=f"hummingbird_train0 .*{what}.* at t = 0.50 s"):
            rf.check_flight(spec, t, bad, ref, 101, limits)
    bad = states.copy()
    bad[:10, 16] = 0.0
    with pytest.raises(GpquadError, match="saturated"):
        rf.check_flight(spec, t, bad, ref, 101, limits)
    with pytest.raises(GpquadError, match="diverged"):
        rf.check_flight(spec, t, states, ref, 60, limits)
    # a pilot far too aggressive for the vehicle: the generator refuses the flight
    monkeypatch.setitem(rf.EXCITATION, "angle", {"sd": (1.0, 1.0, 0.5, 0.5), "cutoff_hz": 2.0})
    with pytest.raises(GpquadError, match="lower the excitation"):
        rf.simulate_flight(dataclasses.replace(spec, duration_s=20.0))


def test_ensure_flights_caches_regenerates_bit_identically_and_adds_noise(tmp_path, monkeypatch):
    monkeypatch.setattr(rf, "PLAN", (("train", 1, 8.0), ("validation", 1, 8.0), ("test", 1, 8.0)))
    res = rf.ensure_flights("angle", True, tmp_path / "a")
    assert set(res) >= {"train", "validation", "test", "input_names", "config", "vehicles", "seeds"}
    assert res["vehicles"] == VEHICLES and len(res["seeds"]) == 6 == len(set(res["seeds"]))
    assert res["input_names"] == ("u_P", "u_R", "u_Y", "u_T")
    config_from_dict({"data": {**res["config"], "files": res["train"]}})  # a valid [data]
    again = rf.ensure_flights("rate", False, tmp_path / "b")
    assert again["seeds"] != res["seeds"]
    other = rf.ensure_flights("angle", True, tmp_path / "c")
    paths = res["train"] + res["validation"] + res["test"]
    for p, q in zip(paths, other["train"] + other["validation"] + other["test"]):
        assert open(p, "rb").read() == open(q, "rb").read()
        clean_p = p.replace("angle-noisy", "angle")
        assert open(clean_p, "rb").read() == open(q.replace("angle-noisy", "angle"), "rb").read()

    def no_flying(spec):
        raise AssertionError("cached flights were flown again")

    monkeypatch.setattr(rf, "simulate_flight", no_flying)
    assert rf.ensure_flights("angle", True, tmp_path / "a") == res
    monkeypatch.setitem(rf.EXCITATION, "angle", {"sd": (0.1, 0.1, 0.05, 0.05), "cutoff_hz": 1.0})
    with pytest.raises(AssertionError, match="flown again"):  # other settings: remade
        rf.ensure_flights("angle", False, tmp_path / "a")

    import pandas as pd

    dv, dw, bias = [], [], []
    for p in paths:
        noisy, clean = pd.read_parquet(p), pd.read_parquet(p.replace("angle-noisy", "angle"))
        for col in ("t", "u_P", "u_R", "u_Y", "u_T", "x", "y", "z"):
            assert np.array_equal(noisy[col], clean[col])  # the same flight
        dv.append((noisy[["vx", "vy", "vz"]] - clean[["vx", "vy", "vz"]]).to_numpy())
        d = (noisy[["p", "q", "r"]] - clean[["p", "q", "r"]]).to_numpy()
        bias.append(d.mean(axis=0))
        dw.append(d - d.mean(axis=0))
    assert np.std(np.vstack(dv)) == pytest.approx(0.03, rel=0.05)
    assert np.std(np.vstack(dw)) == pytest.approx(0.02, rel=0.05)
    assert 0.002 < np.abs(np.array(bias)).mean() < 0.03


def test_unknown_mode_is_a_one_line_error(tmp_path):
    with pytest.raises(GpquadError, match="unknown mode 'yaw'"):
        rf.ensure_flights("yaw", False, tmp_path)
    with pytest.raises(GpquadError, match="unknown fleet 'spare'"):
        rf.ensure_flights("angle", False, tmp_path, fleet="spare")


def test_heldout_fleet_has_its_own_vehicle_seeds_and_folder(tmp_path, monkeypatch):
    """The held-out vehicle is none of the tuned fleet's, shares no flight seed with it in
    either mode, and its flights are cached beside (not over) the tuned fleet's."""
    assert not set(rf.FLEETS["heldout"]) & set(rf.FLEETS["tuned"])
    tuned = {s.seed for m in rf.MODES for s in rf.flight_plan(m)}
    held = {s.seed for m in rf.MODES for s in rf.flight_plan(m, "heldout")}
    assert held and not tuned & held
    monkeypatch.setattr(rf, "PLAN", (("train", 1, 6.0), ("validation", 1, 6.0), ("test", 1, 6.0)))
    res = rf.ensure_flights("rate", True, tmp_path, fleet="heldout")
    assert res["vehicles"] == ["crazyfliebrushless"]
    assert all("/heldout-rate-noisy/" in p for p in res["train"] + res["test"])
    assert (tmp_path / "heldout-rate" / "manifest.json").is_file()
    assert not (tmp_path / "rate").exists()
    assert res["seeds"] == [s.seed for s in rf.flight_plan("rate", "heldout")]


def test_third_vehicle_differs_from_the_tuned_fleet_with_a_loop_tuned_like_theirs():
    """px4sih is a vehicle of its own (mass, inertia, arms, motor lag, rotor limits differ
    from both tuned vehicles), with attitude gains of its own that rotorpy's parameters lack;
    its loop is tuned like theirs: natural frequency between the crazyflie's and the
    hummingbird's, damped at least as well, stable behind its motor lag (kd > tau_m kp, the
    Routh condition of the third-order loop), and its seeds are no other fleet's."""
    third, k_w = rf.vehicle_params("px4sih")
    assert "kp_att" not in importlib.import_module(rf.FLEETS["px4sih"]["px4sih"][0]).quad_params
    assert (third["kp_att"], third["kd_att"]) == (400.0, 80.0) and k_w == 40.0
    arm = lambda p: max(np.linalg.norm(r) for r in p["rotor_pos"].values())  # noqa: E731
    wn = lambda p: np.sqrt(p["kp_att"])  # noqa: E731
    for other in rf.FLEETS["tuned"]:
        tuned, _ = rf.vehicle_params(other)
        for key in ("mass", "Ixx", "Izz", "tau_m", "k_eta", "rotor_speed_max", "kp_att"):
            assert third[key] != tuned[key], (other, key)
        assert arm(third) != arm(tuned)
    crazyflie, hummingbird = (rf.vehicle_params(v)[0] for v in rf.FLEETS["tuned"])
    assert wn(crazyflie) < wn(third) < wn(hummingbird)
    assert third["kd_att"] / (2 * wn(third)) >= 1.0
    assert third["kd_att"] > third["tau_m"] * third["kp_att"]
    seeds = {
        fleet: {s.seed for m in rf.MODES for s in rf.flight_plan(m, fleet)} for fleet in rf.FLEETS
    }
    assert not seeds["px4sih"] & (seeds["tuned"] | seeds["heldout"])


def test_noise_family_is_exactly_2x_and_4x_the_noisy_variant(tmp_path, monkeypatch):
    """noise_scale 2 and 4: the manifest's SDs (gyro bias included) are exactly 2 and 4 times
    the benchmark's, the flight is the clean flight, and the added noise is exactly 2 and 4
    times the noisy variant's (the same draws): velocity, rates with their bias, and the
    attitude noise's rotation angles. A scale outside NOISE_SCALES is a one-line error."""
    import json

    import pandas as pd

    monkeypatch.setattr(rf, "PLAN", (("train", 1, 6.0), ("validation", 1, 6.0), ("test", 1, 6.0)))
    made = {
        k: rf.ensure_flights("angle", True, tmp_path, fleet="px4sih", noise_scale=k)
        for k in (1, 2, 4)
    }
    assert "/px4sih-angle-noisy2x/" in made[2]["train"][0]
    assert "/px4sih-angle-noisy/" in made[1]["train"][0]
    base = {**rf.NOISE, "gyro_bias_sd": rf.GYRO_BIAS_SD}
    for k in (2, 4):
        manifest = json.loads((tmp_path / f"px4sih-angle-noisy{k}x" / "manifest.json").read_text())
        assert manifest["settings"]["noise"] == {n: k * v for n, v in base.items()}
        assert manifest["settings"]["noise_scale"] == k
    one = json.loads((tmp_path / "px4sih-angle-noisy" / "manifest.json").read_text())
    assert one["settings"]["noise"] == base and "noise_scale" not in one["settings"]
    for i, path in enumerate(made[1]["train"] + made[1]["validation"] + made[1]["test"]):
        clean = pd.read_parquet(path.replace("angle-noisy", "angle"))
        frames = {
            k: pd.read_parquet((made[k]["train"] + made[k]["validation"] + made[k]["test"])[i])
            for k in (1, 2, 4)
        }
        d1 = {c: frames[1][c].to_numpy() - clean[c].to_numpy() for c in ("vx", "p", "r")}
        assert np.std(d1["vx"]) == pytest.approx(rf.NOISE["velocity"], rel=0.2)
        # the attitude noise is the rotation (1, h) / |(1, h)| with h ~ N(0, (sd / 2)^2)
        half = {k: tilt_vector(clean, f) for k, f in frames.items()}
        for k in (2, 4):
            assert np.array_equal(frames[k]["u_R"], clean["u_R"])  # the same flight
            for c, d in d1.items():
                np.testing.assert_allclose(
                    frames[k][c].to_numpy() - clean[c].to_numpy(), k * d, rtol=1e-9, atol=1e-12
                )
            np.testing.assert_allclose(half[k], k * half[1], rtol=1e-7, atol=1e-12)
    with pytest.raises(GpquadError, match="noise scale 3 is not one of"):
        rf.ensure_flights("angle", True, tmp_path, noise_scale=3)


def tilt_vector(clean, noisy):
    """h of conj(clean) * noisy = (w, w h) per row: the attitude noise's vector."""
    cols = ["qw", "qx", "qy", "qz"]
    a, b = clean[cols].to_numpy(), noisy[cols].to_numpy()
    aw, av, bw, bv = a[:, 0], -a[:, 1:], b[:, 0], b[:, 1:]
    w = aw * bw - np.sum(av * bv, axis=1)
    return (aw[:, None] * bv + bw[:, None] * av + np.cross(av, bv)) / w[:, None]
