"""Input levels, estimator resets, the v1.14+ PX4 layout, ArduPilot .bin, export and score,
on real cut logs (tests/fixtures/LICENSE.md) and every bad case."""

import dataclasses
import json
import re
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pytest
from px4_reset_edit import SHARED_S250, make_yaw_reset_log

from gpquad.cli.commands import main
from gpquad.data.ardupilot import ardupilot_log_table, read_ardupilot
from gpquad.data.dataflash import DataFlashLog
from gpquad.data.generic import read_generic
from gpquad.data.integration_check import screen_segments
from gpquad.data.io import load_dataset
from gpquad.data.px4 import read_px4_csv, read_px4_folder_log
from gpquad.data.ulog import read_ulog_log
from gpquad.errors import GpquadError
from gpquad.study.config import DataConfig, config_from_dict

FIXTURES = Path(__file__).parent / "fixtures"
V114 = FIXTURES / "px4_v114_sitl.ulg"
AP = FIXTURES / "ardupilot_copter_cut.bin"
PX4 = DataConfig(format="px4-csv", min_segment_s=5.0)


_RESET_DIR: list[Path] = []


def reset_log() -> Path:
    """The S250AQ flight with an EKF yaw reset at 137.0 s (tests/px4_reset_edit.py)."""
    if not SHARED_S250.is_dir():
        pytest.skip("../shared/data (real PX4 logs) is not present")
    if not _RESET_DIR:
        _RESET_DIR.append(make_yaw_reset_log(Path(tempfile.mkdtemp(prefix="gpquad-reset-"))))
    return _RESET_DIR[0]


def _one_line(err) -> str:
    msg = str(err.value)
    assert "\n" not in msg
    return msg


def test_yaw_reset_splits_the_flight_and_the_rest_passes():
    """The EKF turns the yaw by 90 deg in one sample at 137.0 s (a documented edit)."""
    log = read_px4_folder_log(reset_log(), PX4)
    assert log.input_level == "rates" and log.input_columns["u_R"] == "p_sp"
    splits = [n for n in log.notes if n.startswith("split at 137.0")]
    assert any(re.search(r"attitude step of \d+ deg", n) for n in splits)
    assert any("quat_reset_counter) 0 -> 1" in n for n in splits)
    t = log.table["t"].to_numpy()
    assert not log.valid[np.abs(t - 137.0) < 0.05].any()
    flights = read_px4_csv(reset_log(), PX4)
    assert flights[-1].t[0] > 137.0 and flights[-1].t[-1] > 155.0
    kept, dropped, check = screen_segments(flights)
    assert check.passed and check.row("r").rse < 0.05 and not dropped
    from gpquad.data.pipeline import process_segment

    a, b = np.searchsorted(t, [133.0, 160.0])  # the same flight, not split at the reset
    with pytest.raises(GpquadError, match="integration check failed: .*r "):
        screen_segments([process_segment(log, int(a), int(b), PX4, 0)])


def test_data_check_accepts_the_reset_log(capsys, tmp_path):
    assert main(["data", "check", str(reset_log()), "--plot", str(tmp_path / "c.png")]) == 0
    out = capsys.readouterr().out
    assert "split at 137.00 s" in out and "verdict: PASS" in out
    assert "rates   u_P = q_sp (rad/s)" in out and "torque  u_P = pitch_cmd" in out


def test_failing_segment_is_dropped_not_the_flight():
    (good,) = read_px4_csv(
        reset_log(), dataclasses.replace(PX4, time_range=(138.0, 160.0), segment="range")
    )
    bad = dataclasses.replace(good, name="bad", meta=dict(good.meta))
    ref = bad.meta["reference"].copy()
    ref[:, 8] = ref[:, 8] * 3.0 + 0.5
    bad.meta["reference"] = ref
    kept, dropped, _ = screen_segments([good, bad])
    assert kept == [good] and len(dropped) == 1 and "dropped segment bad" in dropped[0]
    assert " r " in dropped[0]
    with pytest.raises(GpquadError) as err:
        screen_segments([bad], source="x.log")
    assert "x.log" in _one_line(err) and "r " in str(err.value)


@pytest.mark.parametrize("level,column", [("torque", "roll_cmd"), ("rates", "p_sp")])
def test_input_levels(level, column):
    log = read_px4_folder_log(reset_log(), dataclasses.replace(PX4, inputs=level))
    assert log.input_level == level and log.input_columns["u_R"] == column
    assert np.array_equal(log.table["u_R"], log.table[column])
    with pytest.raises(GpquadError) as err:  # the cut has no input_rc
        read_px4_folder_log(reset_log(), dataclasses.replace(PX4, inputs="sticks"))
    assert "no signals for input level 'sticks'" in _one_line(err)
    assert "field 'data.inputs'" in str(err.value)


def test_signal_names_need_no_column_map_and_bad_names_are_one_line():
    data = dataclasses.replace(PX4, inputs=("p_sp", "thrust_sp"))
    log = read_px4_folder_log(reset_log(), data)
    assert log.input_names == ("p_sp", "thrust_sp")
    with pytest.raises(GpquadError) as err:
        read_px4_folder_log(reset_log(), dataclasses.replace(PX4, inputs=("nope",)))
    msg = _one_line(err)
    assert "field 'data.columns.nope'" in msg and "p_sp" in msg and str(reset_log()) in msg
    with pytest.raises(GpquadError) as err:
        read_ulog_log(V114, dataclasses.replace(DataConfig(format="ulog"), inputs="sticks"))
    assert "no signals for input level 'sticks'" in _one_line(err)
    for bad in (
        {"inputs": "rats", "files": ["x"], "format": "ulog"},
        {"inputs": "rates"},
        {"validation": "nope"},
    ):
        with pytest.raises(GpquadError) as err:
            config_from_dict({"data": bad})
        assert "data." in _one_line(err)


def test_px4_v114_layout():
    """PX4 SITL log (pyulog test/sample_px4_events.ulg): torque/thrust set-points,
    vehicle_angular_velocity, actuator_motors, esc_status, timestamp_sample."""
    log = read_ulog_log(V114, DataConfig(format="ulog", min_segment_s=5.0))
    assert set(log.levels) == {"rates", "torque", "motors"}
    assert log.input_level == "rates" and log.measured["p"].startswith("measured")
    thrust = log.table["thrust_cmd"].to_numpy()[log.in_flight]
    assert 0.2 < np.median(thrust) < 0.8  # -vehicle_thrust_setpoint.xyz[2]
    assert np.median(log.table["thrust_sp"].to_numpy()[log.in_flight]) == pytest.approx(
        np.median(thrust), abs=0.05
    )
    assert {"esc_krpm_0", "motor_3"} <= set(log.table.columns)
    assert any("quat_reset_counter) 1 -> 2" in n for n in log.notes)
    motors = read_ulog_log(V114, DataConfig(format="ulog", min_segment_s=5.0, inputs="motors"))
    assert motors.input_names == ("motor_0", "motor_1", "motor_2", "motor_3")
    assert any("actuator_motors' logged at 10.0 Hz, below 25 Hz" in n for n in motors.notes)
    rows = {r["stream"]: r for r in log.streams}
    assert rows["vehicle_angular_velocity"]["rate_hz"] == pytest.approx(50.0, abs=1.0)


def test_dataflash_reader_on_a_real_log():
    """ArduCopter log (spark404/dataflashlog test/log.bin, Apache-2.0), cut."""
    log = DataFlashLog(AP)
    assert log.skipped == 0 and {"NKQ1", "IMU", "RATE", "RCOU"} <= set(log.names())
    att = log.get("RATE")
    assert len(att["TimeUS"]) == 504 and att["RDes"][0] == pytest.approx(5.5075812)
    q = log.get("NKQ1")
    assert np.allclose(q["Q1"] ** 2 + q["Q2"] ** 2 + q["Q3"] ** 2 + q["Q4"] ** 2, 1.0, atol=1e-5)
    assert log.params()["RCMAP_YAW"] == 4.0


def test_dataflash_agrees_with_pymavlink():
    mavutil = pytest.importorskip("pymavlink.mavutil")
    mine = DataFlashLog(AP)
    conn = mavutil.mavlink_connection(str(AP))
    theirs = {"NKQ1": [], "RATE": [], "IMU": [], "RCOU": []}
    while (msg := conn.recv_match(type=list(theirs))) is not None:
        theirs[msg.get_type()].append(msg.to_dict())
    for name, rows in theirs.items():
        got = mine.get(name)
        assert len(rows) == len(got["TimeUS"])
        for field in rows[0]:
            if field != "mavpackettype":
                ref = np.array([r[field] for r in rows], dtype=float)
                assert np.allclose(got[field].astype(float), ref, rtol=1e-6, atol=1e-9), field


def test_ardupilot_reader():
    data = DataConfig(format="ardupilot", thrust_threshold=0.1, min_segment_s=5.0)
    log = ardupilot_log_table(AP, data)
    assert set(log.levels) == {"rates", "torque", "sticks", "motors"}
    assert log.input_level == "rates" and log.measured["u"].startswith("measured")
    assert any("'RATE' logged at 9.9 Hz" in n for n in log.notes)
    (flight,) = read_ardupilot(AP, data)
    assert 40.0 < flight.t[-1] - flight.t[0] < 50.0
    eul_yaw = (
        np.degrees(
            np.unwrap(
                np.arctan2(
                    2
                    * (
                        flight.quat[:, 0] * flight.quat[:, 3]
                        + flight.quat[:, 1] * flight.quat[:, 2]
                    ),
                    1 - 2 * (flight.quat[:, 2] ** 2 + flight.quat[:, 3] ** 2),
                )
            )
        )
        % 360
    )
    assert 240 < eul_yaw[0] < 270  # ATT.Yaw about 256 deg at the start
    bad = AP.parent / "nope.bin"
    with pytest.raises(GpquadError):
        read_ardupilot(bad, data)


def test_dataflash_garbage_and_truncation(tmp_path):
    junk = tmp_path / "junk.bin"
    junk.write_bytes(b"\x00\x01not a log" * 100)
    with pytest.raises(GpquadError) as err:
        DataFlashLog(junk)
    assert "not an ArduPilot DataFlash log" in _one_line(err) and "junk.bin" in str(err.value)
    whole = AP.read_bytes()
    cut = tmp_path / "cut.bin"
    cut.write_bytes(whole[: len(whole) // 2] + b"\xa3\x95\x07garbage")
    log = DataFlashLog(cut)
    assert 0 < len(log.get("RATE")["TimeUS"]) < 504 and log.skipped > 0


def test_export_round_trip_gives_identical_data(tmp_path):
    out = tmp_path / "e.csv"
    assert main(["data", "export", str(reset_log()), "--out", str(out)]) == 0
    flights = read_px4_csv(reset_log(), DataConfig(format="px4-csv"))
    back = read_generic(out, DataConfig())
    assert len(back) == len(flights)
    for a, b in zip(flights, back, strict=True):
        for name in ("t", "quat", "vel", "rates", "inputs"):
            assert np.array_equal(getattr(a, name), getattr(b, name)), name
        assert a.dt == b.dt


def test_export_then_run_gives_the_same_model(tmp_path):
    from gpquad.study.config import Config
    from gpquad.study.runner import run_experiment

    out = tmp_path / "e.parquet"
    assert main(["data", "export", str(reset_log()), "--out", str(out)]) == 0
    evo = {
        "targets": ["p_dot"],
        "iterations": 1,
        "model_generations": 5,
        "test_generations": 2,
        "window_s": 4.0,
        "finish": ["repair"],
    }
    runs = []
    for files, fmt in (([str(reset_log())], "px4-csv"), ([str(out)], "generic")):
        cfg = config_from_dict(
            {
                "seed": 3,
                "preset": "paper",
                "data": {"files": files, "format": fmt},
                "evolution": evo,
                "output": {"progress": False},
            }
        )
        run_experiment(cfg, tmp_path / fmt, progress=False)
        d = json.loads((tmp_path / fmt / "model.json").read_text())
        d.pop("config")
        runs.append(d)
    assert runs[0] == runs[1]
    assert isinstance(Config().data.inputs, tuple)


def test_validation_by_whole_files(tmp_path):
    for name in ("a.csv", "b.csv"):
        assert main(["data", "export", str(reset_log()), "--out", str(tmp_path / name)]) == 0
    cfg = config_from_dict(
        {"data": {"files": ["a.csv"], "validation": ["b.csv"]}}, base_dir=str(tmp_path)
    )
    ds = load_dataset(cfg)
    (t0, t1), (v0, v1) = ds.train[0], ds.validation[0]
    assert t0 == 0 and t1 == ds.segments[0][1] and v1 - v0 == ds.segments[1][1] - v0
    assert len(ds.validation) == 1 and ds.train[1][0] == ds.train[1][1]


def test_score_command(tmp_path, capsys):
    from gpquad.study.runner import run_experiment

    evo = {
        "targets": ["p_dot"],
        "iterations": 1,
        "model_generations": 5,
        "test_generations": 2,
        "window_s": 4.0,
        "finish": ["repair"],
    }
    cfg = config_from_dict(
        {
            "seed": 1,
            "preset": "paper",
            "vehicle": {"symmetric": True},
            "data": {"files": [str(reset_log())], "format": "px4-csv"},
            "evolution": evo,
            "output": {"progress": False},
        }
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run_experiment(cfg, tmp_path / "run", progress=False)
    assert (
        main(
            [
                "score",
                str(tmp_path / "run"),
                "--data",
                str(reset_log()),
                "--json",
                "--horizon-s",
                "2",
            ]
        )
        == 0
    )
    res = json.loads(capsys.readouterr().out)
    assert res["part"] == "validation" and res["steps"] == 50 and res["windows"] >= 1
    assert np.isnan(res["rse"]["u"]) and 0 <= res["rse"]["p"] < np.inf and res["diverged"] == 0
    assert res["mirrored"] == {"inputs": ["u_R", "u_Y"], "diverged": 0}
    # the zero and the set-point model (a rate-level log) flown beside, on the same windows
    assert set(res["baselines"]) == {"zero", "set-point"}
    assert np.isnan(res["baselines"]["zero"]["u"]) and res["baselines"]["zero"]["p"] > 0
    assert (
        main(
            [
                "score",
                str(tmp_path / "run"),
                "--data",
                str(reset_log()),
                "--part",
                "all",
                "--horizon-s",
                "2",
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    assert "RSE of the integrated states over" in out
    assert "\nzero " in out and "\nset-point " in out and "\nmodel " in out
    assert "mirrored left-right (u_R, u_Y flipped): 0 of" in out
    code = main(["score", str(tmp_path / "run"), "--data", str(reset_log()), "--format", "ulog"])
    assert code == 2 and "file not found" in capsys.readouterr().err
    code = main(["score", str(tmp_path / "run"), "--data", str(reset_log()), "--horizon-s", "-1"])
    assert code == 2 and "--horizon-s" in capsys.readouterr().err
