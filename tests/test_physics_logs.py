"""`gpquad physics thrust|drag|deadreckon` on logs: rotorpy flights written as files (generic
CSV and a PX4 ulog2csv folder, not through the simulated-truth path) give the vehicle's own
coefficients; bad logs are one line and exit code 2; the simulated-truth results are the
ones the truth mode gave before logs were read."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

pytest.importorskip("rotorpy")

from gpquad.cli.commands import main  # noqa: E402
from gpquad.data.motors import erpm_to_rad_s, on_clock  # noqa: E402
from gpquad.errors import GpquadError  # noqa: E402
from gpquad.physics.commands import run_command  # noqa: E402
from gpquad.physics.truth import cached_flight, vehicle_params  # noqa: E402

FIXTURES = Path(__file__).parent / "fixtures"
FLIGHTS = {"hover": False, "forward": False, "lateral": False, "L": True}
PARAMS = vehicle_params("hummingbird")
K_D_FORCE = -4 * PARAMS["k_d"]  # N per (rad/s) per (m/s), eq. (18) times the mass


def _flight(name: str, cache: Path) -> dict:
    return cached_flight(
        {
            "manoeuvre": name,
            "side": 1.5,
            "speed": 2.0,
            "yaw": FLIGHTS[name],
            "vehicle": "hummingbird",
            "dt": 0.02,
        },
        cache,
    )


def _csv_columns(f: dict, rng: np.random.Generator) -> dict:
    """A rotorpy flight as generic ENU/FLU columns, with sensor noise."""
    n = len(f["t"])
    q = f["quat"]
    cols = {"t": f["t"], "qw": q[:, 3], "qx": q[:, 0], "qy": q[:, 1], "qz": q[:, 2]}
    vel = f["vel"] + rng.normal(0, 0.01, (n, 3))
    force = f["force"] + rng.normal(0, 0.2, (n, 3))
    rotor = f["rotor"] + rng.normal(0, 2.0, (n, 4))
    cols.update({f"v{a}": vel[:, i] for i, a in enumerate("xyz")})
    cols.update({a: f["pos"][:, i] for i, a in enumerate("xyz")})
    cols.update({f"rotor_{i + 1}": rotor[:, i] for i in range(4)})
    cols.update({f"acc_{a}": force[:, i] for i, a in enumerate("xyz")})
    return cols


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    root = tmp_path_factory.mktemp("physics_logs")
    rng = np.random.default_rng(11)
    for name in FLIGHTS:
        cols = _csv_columns(_flight(name, root / "flights"), rng)
        pd.DataFrame(cols).to_csv(root / f"{name}.csv", index=False, float_format="%.17g")
    return root


def _config(
    root: Path,
    files,
    extra: str = "",
    frame: str = "ENU/FLU",
    vehicle: str = f"mass = {PARAMS['mass']}",
) -> Path:
    path = root / f"cfg{abs(hash((tuple(files), extra, frame, vehicle)))}.toml"
    path.write_text(
        f'name = "log"\n[data]\nfiles = {list(files)}\nframe = "{frame}"\n'
        f"min_segment_s = 1.0\n{extra}\n[vehicle]\n{vehicle}\n"
        "[regression]\nparasitic_drag = true\n"
    )
    return path


ID_FILES = ["hover.csv", "forward.csv", "lateral.csv"]


def test_generic_csv_gives_the_vehicles_thrust_and_drag(root, tmp_path):
    cfg = _config(root, ID_FILES)
    out, thrust = run_command("thrust", cfg, tmp_path / "t", summary=True)
    assert abs(thrust["k_t"] / PARAMS["k_eta"] - 1) < 0.03, thrust
    assert 0 < thrust["k_t_se"] < 0.01 * thrust["k_t"] and thrust["rmse_val"] > 0
    assert abs(thrust["k_t_refined"] / PARAMS["k_eta"] - 1) < 0.03
    assert (out / "thrust_standard_hover.png").is_file() and (out / "thrust.md").is_file()
    out, drag = run_command("drag", cfg, tmp_path / "d", summary=True)
    for axis in "xy":
        assert abs(drag[f"k_d{axis}"] / K_D_FORCE - 1) < 0.15, drag
        assert drag[f"k_d{axis}_se"] > 0 and np.isfinite(drag[f"rmse_val_{axis}"])
        assert drag[f"k_d{axis}_specific"] == pytest.approx(drag[f"k_d{axis}"] / PARAMS["mass"])
    assert (out / "drag_x.png").is_file()


def test_deadreckon_on_the_logs_segments(root, tmp_path):
    out, res = run_command(
        "deadreckon", _config(root, ID_FILES + ["L.csv"]), tmp_path / "r", summary=True
    )
    (seg,) = [s for s in res["segments"] if s["name"].startswith("L.csv")]
    norm = {m: np.linalg.norm(r) for m, r in seg["rmse_m"].items()}
    assert norm["coriolis"] < norm["refined"] < norm["base"]
    assert norm["coriolis"] < 0.5
    assert "| L.csv" in (out / "deadreckon.md").read_text()


def _run_cli(capsys, kind: str, cfg: Path, tmp_path) -> str:
    assert main(["physics", kind, str(cfg), "--out", str(tmp_path / "o")]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    # one error line, after any warnings of the reading (each a "gpquad: warning:" line)
    errors = [line for line in lines if not line.startswith("gpquad: warning:")]
    assert len(errors) == 1 and errors[0].startswith("gpquad: error:"), lines
    return errors[0]


def _variant(root: Path, name: str, change) -> str:
    df = change(pd.read_csv(root / "hover.csv"))
    df.to_csv(root / name, index=False)
    return name


def test_a_log_without_motor_speeds_is_one_line(root, tmp_path, capsys):
    name = _variant(
        root, "no_rotor.csv", lambda df: df.drop(columns=[f"rotor_{i}" for i in range(1, 5)])
    )
    err = _run_cli(capsys, "thrust", _config(root, [name]), tmp_path)
    assert "no motor speeds" in err and "rotor_1" in err and "four rotor speeds" in err


def test_an_accelerometer_in_g_is_caught_by_the_hover_level(root, tmp_path, capsys):
    def in_g(df):
        for a in "xyz":
            df[f"acc_{a}"] /= 9.81
        return df

    err = _run_cli(capsys, "thrust", _config(root, [_variant(root, "in_g.csv", in_g)]), tmp_path)
    assert "in g" in err and "9.81" in err and "acc_z" in err


def test_a_wrong_frame_is_one_line(root, tmp_path, capsys):
    err = _run_cli(capsys, "drag", _config(root, ["hover.csv"], frame="NED/FRD"), tmp_path)
    assert "data.frame" in err and "NED/FRD" in err


def test_drag_without_velocity_and_a_missing_mass_are_one_line(root, tmp_path, capsys):
    name = _variant(root, "no_vel.csv", lambda df: df.drop(columns=["vx", "vy", "vz"]))
    err = _run_cli(capsys, "drag", _config(root, [name]), tmp_path)
    assert "no measured velocity" in err and "vx, vy, vz" in err
    err = _run_cli(capsys, "thrust", _config(root, ["hover.csv"], vehicle=""), tmp_path)
    assert "vehicle.mass" in err


TRUTH = """name = "test"
seed = 5
[truth]
vehicle = "hummingbird"
dt = 0.02
side = 1.5
speed = 2.0
cache = "{cache}"
[noise]
accel_noise_sd = 0.2
accel_bias_sd = 0.05
calibration_s = 0.4
rotor_noise_sd = 2.0
velocity_noise_sd = 0.01
[regression]
parasitic_drag = true
drag_intercept = true
method = "wls"
smoothing_window = 5
[drag]
flights = ["forward", "lateral"]
[deadreckon]
manoeuvres = ["L"]
yaw = [true]
"""
# What the simulated-truth mode gave on this config before it could read logs.
PINNED = {
    "standard_hover": [5.598260398007303e-06],
    "refined_forward": [5.569977065104268e-06, 6.251782310647938e-05, -0.010002256488235387],
    "x_parasitic": [-0.0009992600074056554, 0.014229688049811185, 0.00022870871401020143],
    "coriolis": [0.6562214377870201, 0.16612794721029583, 0.1920461587312781],
}


def test_simulated_truth_results_are_unchanged(root, tmp_path):
    import json

    cfg = tmp_path / "truth.toml"
    cfg.write_text(TRUTH.format(cache=(root / "flights").as_posix()))
    got = {}
    for kind in ("thrust", "drag", "deadreckon"):
        out = run_command(kind, cfg, tmp_path / kind)
        res = json.loads((out / f"{kind}.json").read_text())
        if kind == "deadreckon":
            got["coriolis"] = res["flights"][0]["models"]["coriolis"]["rmse"]
        else:
            got.update({k: v["coef"] for k, v in res["fits"].items() if k in PINNED})
    for key, values in PINNED.items():
        np.testing.assert_allclose(got[key], values, rtol=1e-9, err_msg=key)


def test_erpm_and_clock_helpers_against_hand_values():
    # 14 magnets = 7 pole pairs: 21000 eRPM is 3000 RPM = 100 pi rad/s
    assert erpm_to_rad_s(np.array([21000.0, -21000.0]), 7) == pytest.approx([100 * np.pi] * 2)
    t = np.array([0.0, 0.1, 0.2, 1.0, 1.1])
    v, covered = on_clock(np.array([0.05, 0.15, 0.5, 1.05, 1.2]), t, t * 2, max_gap_s=0.3)
    assert v[:, 0] == pytest.approx([0.1, 0.3, 1.0, 2.1, 2.2])
    assert covered.tolist() == [True, True, False, True, False]  # a gap; past the end


def test_betaflight_pole_pairs_from_header_or_vehicle():
    from gpquad.data.motors import betaflight_pole_pairs

    assert betaflight_pole_pairs({"motor_poles": "14"}, 0, "log") == 7
    assert betaflight_pole_pairs({"motor_poles": "14"}, 6, "log") == 6
    with pytest.raises(GpquadError, match="motor_pole_pairs"):
        betaflight_pole_pairs({}, 0, "log")


def test_bundled_betaflight_42_log_says_it_has_no_erpm(tmp_path, capsys):
    log = FIXTURES / "btfl_001_cut.bbl"
    cfg = tmp_path / "bf.toml"
    cfg.write_text(
        f'[data]\nfiles = ["{log.as_posix()}"]\nformat = "betaflight"\n[vehicle]\nmass = 0.6\n'
    )
    err = _run_cli(capsys, "thrust", cfg, tmp_path)
    assert "no motor speeds" in err and "eRPM[0..3]" in err and "4.2" in err


def _ned_log(flights: list[dict], rng) -> dict:
    """Rotorpy flights 1 s apart (a gap: one segment each) in NED/FRD with sensor noise:
    us (timestamps), q, rates, acc, vel, pos, rotor (rad/s)."""
    from gpquad.data.flight import enu_flu_quat, flip_body, flip_world

    parts, t0 = [], 0.0
    for f in flights:
        parts.append({**f, "t": f["t"] + t0})
        t0 += f["t"][-1] + 1.0
    f = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    n = len(f["t"])
    return {
        "us": np.round(f["t"] * 1e6).astype(np.int64) + 1_000_000,
        "q": enu_flu_quat(f["quat"][:, [3, 0, 1, 2]]),
        "rates": flip_body(f["omega"]),
        "acc": flip_body(f["force"]) + rng.normal(0, 0.2, (n, 3)),
        "vel": flip_world(f["vel"]),
        "pos": flip_world(f["pos"]),
        "rotor": f["rotor"] + rng.normal(0, 2.0, f["rotor"].shape),
    }


def _px4_folder(folder: Path, flights: list[dict], rng, esc: bool = True) -> Path:
    """Rotorpy flights as the topic CSVs of `ulog2csv` (NED/FRD)."""
    g = _ned_log(flights, rng)
    us, q, rates, acc, vel, pos = (g[k] for k in ("us", "q", "rates", "acc", "vel", "pos"))
    n = len(us)
    topics = {
        "vehicle_attitude": {
            **{f"q[{i}]": q[:, i] for i in range(4)},
            "rollspeed": rates[:, 0],
            "pitchspeed": rates[:, 1],
            "yawspeed": rates[:, 2],
        },
        "vehicle_local_position": {
            **{a: pos[:, i] for i, a in enumerate("xyz")},
            **{f"v{a}": vel[:, i] for i, a in enumerate("xyz")},
            "v_xy_valid": np.ones(n),
            "v_z_valid": np.ones(n),
            "xy_valid": np.ones(n),
            "z_valid": np.ones(n),
        },
        "actuator_controls_0": {
            **{f"control[{i}]": np.zeros(n) for i in range(3)},
            "control[3]": np.full(n, 0.5),
        },
        "vehicle_status": {"arming_state": np.full(n, 2), "nav_state": np.zeros(n)},
        "sensor_combined": {f"accelerometer_m_s2[{i}]": acc[:, i] for i in range(3)},
    }
    if esc:
        rpm = g["rotor"] * 60 / (2 * np.pi)
        topics["esc_status"] = {f"esc[{i}].esc_rpm": rpm[:, i] for i in range(4)}
    folder.mkdir(parents=True, exist_ok=True)
    for topic, cols in topics.items():
        pd.DataFrame({"timestamp": us, **cols}).to_csv(folder / f"sim_{topic}_0.csv", index=False)
    return folder


def test_px4_topics_give_the_vehicles_thrust_and_drag(root, tmp_path, capsys):
    rng = np.random.default_rng(3)
    flights = [_flight(n, root / "flights") for n in ("hover", "forward", "lateral")]
    folder = _px4_folder(tmp_path / "px4", flights, rng)
    cfg = _config(tmp_path, [str(folder)], extra='format = "px4-csv"', frame="NED/FRD")
    _, thrust = run_command("thrust", cfg, tmp_path / "t", summary=True)
    assert abs(thrust["k_t"] / PARAMS["k_eta"] - 1) < 0.03, thrust
    _, drag = run_command("drag", cfg, tmp_path / "d", summary=True)
    assert abs(drag["k_dx"] / K_D_FORCE - 1) < 0.15 and abs(drag["k_dy"] / K_D_FORCE - 1) < 0.15
    bare = _px4_folder(tmp_path / "px4_no_esc", flights, rng, esc=False)
    err = _run_cli(
        capsys,
        "thrust",
        _config(tmp_path, [str(bare)], extra='format = "px4-csv"', frame="NED/FRD"),
        tmp_path,
    )
    assert "no motor speeds" in err and "esc_status" in err


def test_betaflight_erpm_fields_become_rad_s_with_the_headers_pole_pairs(monkeypatch):
    import gpquad.data.betaflight as bf
    from gpquad.data.motors import read_betaflight_motors
    from gpquad.physics.config import PhysicsConfig

    log = FIXTURES / "btfl_001_cut.bbl"
    real = bf.read_frames

    def with_erpm(path, index):  # a 4.2 log with eRPM fields added: 300 x 100 eRPM
        df, headers, stop = real(path, index)
        df = df.assign(**{f"eRPM[{i}]": 300.0 for i in range(4)})
        return df, {**headers, "motor_poles": "14"}, stop

    monkeypatch.setattr(bf, "read_frames", with_erpm)
    data = PhysicsConfig(data={"files": [str(log)], "format": "betaflight"}).data_config()
    logs = read_betaflight_motors(log, data)
    rotor = np.concatenate([lg.rotor[lg.valid] for lg in logs])
    assert rotor == pytest.approx(np.full_like(rotor, 30000 / 7 * 2 * np.pi / 60))
    assert all(lg.acc is not None and lg.vel is None and lg.pos is None for lg in logs)


@pytest.mark.parametrize(
    "name, fmt, says",
    [
        ("ardupilot_copter_cut.bin", "ardupilot", ("no motor speeds", "ESC messages")),
        ("px4_v114_sitl.ulg", "ulog", ("no accelerometer", "sensor_combined")),
    ],
)
def test_real_log_fixtures_name_the_signal_they_lack(name, fmt, says, tmp_path, capsys):
    cfg = tmp_path / "fx.toml"
    cfg.write_text(
        f'[data]\nfiles = ["{(FIXTURES / name).as_posix()}"]\nformat = "{fmt}"\n'
        "min_segment_s = 2.0\nthrust_threshold = 0.1\n[vehicle]\nmass = 1.0\n"
    )
    err = _run_cli(capsys, "thrust", cfg, tmp_path)
    assert all(s in err for s in says) and "four rotor speeds and the accelerometer" in err


def test_deadreckon_windows_cover_the_segment():
    from gpquad.physics.identify_log import windows

    seg = {"t": np.arange(0, 10.0, 0.1)}  # 100 samples
    assert windows(seg, 0.0) == [(0, 100)]
    assert windows(seg, 3.0) == [(0, 30), (30, 60), (60, 100)]  # the 10-sample rest joins
    assert windows(seg, 4.0) == [(0, 40), (40, 80), (80, 100)]


def test_px4_sitl_log_with_esc_rpm_gives_coefficients(tmp_path, capsys):
    import json

    cfg = tmp_path / "sitl.toml"
    cfg.write_text(
        f'[data]\nfiles = ["{(FIXTURES / "px4_v114_sitl_esc.ulg").as_posix()}"]\n'
        'format = "ulog"\nmin_segment_s = 2.0\nthrust_threshold = 0.1\n'
        "[vehicle]\nmass = 1.5\n[thrust]\nmin_height = 0.3\n"
        "[regression]\nsmoothing_window = 25\n"
    )
    assert main(["physics", "thrust", str(cfg), "--json", "--out", str(tmp_path / "t")]) == 0
    res = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert 1e-5 < res["k_t"] < 1e-4 and 0 < res["k_t_se"] < 0.05 * res["k_t"]
    assert res["n"] > 50 and res["units"]["k_t"] == "N/(rad/s)^2"
    assert main(["physics", "deadreckon", str(cfg), "--json", "--out", str(tmp_path / "d")]) == 0
    dr = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert dr["segments"] and set(dr["segments"][0]["rmse_m"]) == {
        "accelerometer",
        "base",
        "refined",
        "coriolis",
    }


def _dataflash(path: Path, messages: dict) -> Path:
    """A DataFlash .bin: one FMT record per message, then its records. messages: name ->
    (type id, format, column names, {column: array})."""
    import struct

    sizes = {"Q": 8, "B": 1, "f": 4}
    out = bytearray()
    for name, (typ, fmt, cols, values) in messages.items():
        length = 3 + sum(sizes[c] for c in fmt)
        out += b"\xa3\x95\x80" + struct.pack(
            "<BB4s16s64s", typ, length, name.encode(), fmt.encode(), ",".join(cols).encode()
        )
        dtype = np.dtype(
            [("h", "u1", (3,))]
            + [(c, {"Q": "<u8", "B": "u1", "f": "<f4"}[f]) for c, f in zip(cols, fmt)]
        )
        rec = np.zeros(len(values[cols[0]]), dtype=dtype)
        rec["h"] = (0xA3, 0x95, typ)
        for c in cols:
            rec[c] = values[c]
        out += rec.tobytes()
    path.write_bytes(bytes(out))
    return path


def test_ardupilot_esc_and_imu_give_the_vehicles_thrust(root, tmp_path):
    rng = np.random.default_rng(4)
    g = _ned_log([_flight(n, root / "flights") for n in ("hover", "forward", "lateral")], rng)
    us = g["us"].astype(np.uint64)
    q, gyr, acc, vel, pos = (g[k] for k in ("q", "rates", "acc", "vel", "pos"))
    n = len(us)
    zero = np.zeros(n)
    esc_t = np.repeat(us, 4)
    rpm = g["rotor"].reshape(-1) * 60 / (2 * np.pi)
    path = _dataflash(
        tmp_path / "sim.bin",
        {
            "XKQ": (
                130,
                "QBffff",
                ("TimeUS", "C", "Q1", "Q2", "Q3", "Q4"),
                {"TimeUS": us, "C": zero, **{f"Q{i + 1}": q[:, i] for i in range(4)}},
            ),
            "IMU": (
                131,
                "QBffffff",
                ("TimeUS", "I", "GyrX", "GyrY", "GyrZ", "AccX", "AccY", "AccZ"),
                {
                    "TimeUS": us,
                    "I": zero,
                    **{f"Gyr{a}": gyr[:, i] for i, a in enumerate("XYZ")},
                    **{f"Acc{a}": acc[:, i] for i, a in enumerate("XYZ")},
                },
            ),
            "XKF1": (
                132,
                "QBffffff",
                ("TimeUS", "C", "VN", "VE", "VD", "PN", "PE", "PD"),
                {
                    "TimeUS": us,
                    "C": zero,
                    **{k: vel[:, i] for i, k in enumerate(("VN", "VE", "VD"))},
                    **{k: pos[:, i] for i, k in enumerate(("PN", "PE", "PD"))},
                },
            ),
            "RATE": (
                133,
                "Qffffff",
                ("TimeUS", "RDes", "PDes", "YDes", "ROut", "POut", "YOut"),
                {
                    "TimeUS": us,
                    **{k: zero for k in ("RDes", "PDes", "YDes", "ROut", "POut", "YOut")},
                },
            ),
            "CTUN": (134, "Qf", ("TimeUS", "ThO"), {"TimeUS": us, "ThO": np.full(n, 0.5)}),
            "EV": (135, "QB", ("TimeUS", "Id"), {"TimeUS": us[[0, -1]], "Id": np.array([10, 11])}),
            "ESC": (
                136,
                "QBf",
                ("TimeUS", "Instance", "RPM"),
                {"TimeUS": esc_t, "Instance": np.tile(np.arange(4), n), "RPM": rpm},
            ),
        },
    )
    cfg = _config(tmp_path, [str(path)], extra='format = "ardupilot"', frame="NED/FRD")
    _, thrust = run_command("thrust", cfg, tmp_path / "t", summary=True)
    assert abs(thrust["k_t"] / PARAMS["k_eta"] - 1) < 0.03, thrust
    _, drag = run_command("drag", cfg, tmp_path / "d", summary=True)
    assert abs(drag["k_dx"] / K_D_FORCE - 1) < 0.15 and abs(drag["k_dy"] / K_D_FORCE - 1) < 0.15


@pytest.mark.parametrize(
    "text, match",
    [
        (
            '[data]\nfiles = ["a.csv"]\n[truth]\nvehicle = "hummingbird"\n[vehicle]\nmass = 1.0\n',
            "two sources",
        ),
        ('[data]\nfiles = ["a.csv"]\n[vehicle]\nmass = 1.0\nmagnets = 14\n', "vehicle.magnets"),
        ("[vehicle]\nmass = 1.0\n", "lists no files"),
        (
            '[data]\nfiles = ["a.csv"]\nformat = "table"\n[vehicle]\nmass = 1.0\n',
            "no motor-speed reader",
        ),
        (
            '[data]\nfiles = ["a.csv"]\n[vehicle]\nmass = 1.0\n[thrust]\nmin_height = -1.0\n',
            "thrust.min_height",
        ),
        (
            '[data]\nfiles = ["a.csv"]\nsegment = "sometimes"\n[vehicle]\nmass = 1.0\n',
            "data.segment",
        ),
    ],
)
def test_log_config_errors_name_the_field(tmp_path, text, match):
    from gpquad.physics.config import load_physics_config

    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(GpquadError, match=match):
        load_physics_config(path)


def test_a_time_range_keeps_part_of_a_generic_file(root, tmp_path):
    import json

    cfg = _config(root, ["hover.csv"], extra='segment = "range"\ntime_range = [1.0, 4.0]')
    out = run_command("thrust", cfg, tmp_path / "t")
    (seg,) = json.loads((out / "thrust.json").read_text())["log"]["segments"]
    assert seg["name"] == "hover.csv@1.0s" and 2.9 < seg["duration_s"] <= 3.0
