"""PX4 readers (ulog2csv folders and .ulg) on synthetic folders, the bundled fixture and the
real flights in ../shared/data (skipped when absent), and every bad-input case."""

import dataclasses
import re
import shutil
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from gpquad.data.integration_check import integration_check
from gpquad.data.io import READERS
from gpquad.data.px4 import read_px4_csv, read_px4_folder_log
from gpquad.data.ulog import read_ulog, read_ulog_log
from gpquad.engine.kernels.integrator import body_accelerations, integrate
from gpquad.errors import GpquadError
from gpquad.study.config import DataConfig, config_from_dict

FIXTURES = Path(__file__).parent / "fixtures"
SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"
S250 = SHARED / "px4" / "S250AQ_2016-12-13"
needs_shared = pytest.mark.skipif(
    not S250.is_dir(), reason="../shared/data (real PX4 logs) is not present"
)


def true_rates(t):
    """Smooth body rates (rad/s) well below the 5 Hz cutoff."""
    return np.column_stack(
        [
            0.6 * np.sin(2 * np.pi * 0.4 * t),
            0.5 * np.sin(2 * np.pi * 0.25 * t + 1.0),
            0.3 + 0.2 * np.cos(2 * np.pi * 0.1 * t),
        ]
    )


def make_folder(root: Path, duration=50.0, xy_valid=0, edit=None) -> Path:
    """A ulog2csv-style folder of a synthetic flight (armed, thrust 0.45 from 3 s to end-3 s)."""
    folder = root / "flight"
    folder.mkdir()
    fine = np.arange(0.0, duration, 0.001)
    w = true_rates(fine)
    alpha = body_accelerations(np.zeros_like(w), np.ascontiguousarray(w), 0.001)
    q, _, _, _ = integrate(
        np.array([1.0, 0, 0, 0]), np.zeros(3), w[0].copy(), np.zeros(3), alpha, 0.001
    )
    t0 = 20.0

    def at(period):
        idx = np.arange(0, len(fine), int(round(period / 0.001)))
        return idx, ((fine[idx] + t0) * 1e6).astype(np.int64)

    i, ts = at(0.012)
    att = pd.DataFrame(
        {
            "timestamp": ts,
            "rollspeed": w[i, 0],
            "pitchspeed": w[i, 1],
            "yawspeed": w[i, 2],
            **{f"q[{k}]": q[i, k] for k in range(4)},
        }
    )
    i, ts = at(0.1)
    vz = 0.3 * np.sin(2 * np.pi * 0.2 * fine[i])
    pos = pd.DataFrame(
        {
            "timestamp": ts,
            "x": 0.0,
            "y": 0.0,
            "z": 0.0,
            "vx": 0.0 if not xy_valid else 0.5,
            "vy": 0.0,
            "vz": vz,
            "xy_valid": xy_valid,
            "v_xy_valid": xy_valid,
            "v_z_valid": 1,
        }
    )
    i, ts = at(0.02)
    tt = fine[i]
    thrust = np.where((tt > 3) & (tt < duration - 3), 0.45, 0.0)
    ctl = pd.DataFrame(
        {
            "timestamp": ts,
            "control[0]": 0.1 * np.sin(tt),
            "control[1]": 0.1 * np.cos(tt),
            "control[2]": 0.0,
            "control[3]": thrust,
        }
    )
    i, ts = at(0.25)
    status = pd.DataFrame({"timestamp": ts, "arming_state": 2, "nav_state": 0})
    tables = {
        "vehicle_attitude_0": att,
        "vehicle_local_position_0": pos,
        "actuator_controls_0_0": ctl,
        "vehicle_status_0": status,
    }
    if edit:
        edit(tables)
    for name, df in tables.items():
        df.to_csv(folder / f"log7_{name}.csv", index=False)
    (folder / "parameters.octave").write_text("# name PWM_MIN\n# type: scalar\n1000\n")
    return folder


DATA = DataConfig(format="px4-csv", min_segment_s=5.0)


def test_synthetic_folder_reads_with_exact_rates(tmp_path):
    folder = make_folder(tmp_path)
    log = read_px4_folder_log(folder, DATA)
    assert log.rate_hz == 100.0
    assert log.measured["u"].startswith("not measured")
    assert log.measured["w"].startswith("measured")
    (flight,) = read_px4_csv(folder, DATA)
    assert flight.dt == pytest.approx(0.04)
    assert flight.input_names == ("u_P", "u_R", "u_Y", "u_T")
    # in flight: thrust 0.45 from 3 s (20 s log clock offset), minus the filter's 1 s edges
    assert flight.t[0] == pytest.approx(23.0 + 0.995, abs=0.05)
    assert np.allclose(flight.inputs[:, 3], 0.45, atol=1e-9)
    # rates from the filtered quaternion = mean true rate over each 40 ms step (<1 % of peak)
    fine = flight.t[:, None] + np.linspace(0, 0.04, 41)[None, :] - 20.0
    mean_rate = np.stack([true_rates(row).mean(axis=0) for row in fine])
    assert np.abs(flight.rates - mean_rate).max() < 0.006
    check = integration_check([flight], 750, 0.05)
    assert check.passed
    assert check.row("p").rse < 1e-3 and check.row("u").status == "not measured"


def test_horizontal_velocity_measured_when_flag_set(tmp_path):
    log = read_px4_folder_log(make_folder(tmp_path, xy_valid=1), DATA)
    assert log.measured["u"].startswith("measured") and log.measured["v"].startswith("measured")


def test_inputs_can_be_mapped_to_other_signals(tmp_path):
    folder = make_folder(tmp_path)
    data = dataclasses.replace(DATA, inputs=("u_R", "u_T"), columns={"u_R": "pitch_cmd"})
    (flight,) = read_px4_csv(folder, data)
    assert flight.input_names == ("u_R", "u_T")
    with pytest.raises(GpquadError, match="unknown signal 'nope'"):
        read_px4_csv(folder, dataclasses.replace(data, columns={"u_R": "nope"}))


def test_gap_in_an_optional_topic_mapped_to_an_input_splits_the_flight(tmp_path):
    """actuator_outputs is optional, but once u_T reads motor_0 its 1 s hole is a gap, not a
    held value; unmapped, the same hole is held over (the flight stays whole)."""

    def motors(tables):
        ts = np.arange(20.0, 70.0, 0.05)
        ts = ts[(ts < 45.0) | (ts > 46.0)]
        tables["actuator_outputs_0"] = pd.DataFrame(
            {
                "timestamp": (ts * 1e6).astype(np.int64),
                **{f"output[{i}]": 1450.0 + 10 * i for i in range(4)},
            }
        )

    folder = make_folder(tmp_path, duration=50.0, edit=motors)
    (whole,) = read_px4_csv(folder, DATA)
    mapped = dataclasses.replace(DATA, columns={"u_T": "motor_0"})
    first, second = read_px4_csv(folder, mapped)
    assert first.t[-1] < 45.0 and second.t[0] > 46.0
    assert np.allclose(first.inputs[:, 3], 0.45, atol=1e-9)  # (1450 - 1000) / 1000


def _one_line(err) -> str:
    msg = str(err.value)
    assert "\n" not in msg and "Traceback" not in msg
    return msg


def test_missing_topic(tmp_path):
    folder = make_folder(tmp_path)
    next(folder.glob("*actuator_controls_0_0.csv")).unlink()
    with pytest.raises(GpquadError) as err:
        read_px4_csv(folder, DATA)
    msg = _one_line(err)
    assert "field 'actuator_controls_0'" in msg and str(folder) in msg


def test_missing_column(tmp_path):
    folder = make_folder(tmp_path, edit=lambda t: t["vehicle_attitude_0"].pop("q[2]"))
    with pytest.raises(GpquadError) as err:
        read_px4_csv(folder, DATA)
    msg = _one_line(err)
    assert "q[2]" in msg and "vehicle_attitude_0.csv" in msg


def test_nan_run_splits_the_flight(tmp_path):
    def nan_run(tables):
        att = tables["vehicle_attitude_0"]
        rows = (att.timestamp > 45e6) & (att.timestamp < 46e6)
        att.loc[rows, ["q[0]", "q[1]"]] = np.nan

    flights = read_px4_csv(make_folder(tmp_path, duration=60.0, edit=nan_run), DATA)
    assert len(flights) == 2
    assert flights[0].t[-1] < 45.0 and flights[1].t[0] > 46.0


def test_all_nan_column(tmp_path):
    def blank(tables):
        tables["vehicle_local_position_0"]["vz"] = np.nan

    with pytest.raises(GpquadError) as err:
        read_px4_csv(make_folder(tmp_path, edit=blank), DATA)
    msg = _one_line(err)
    assert "NaN" in msg and "vehicle_local_position_0.csv" in msg and "field 'vz'" in msg


@pytest.mark.parametrize("kind", ["duplicate", "backwards"])
def test_bad_timestamps(tmp_path, kind):
    def damage(tables):
        ts = tables["vehicle_attitude_0"]["timestamp"].to_numpy().copy()
        ts[100] = ts[99] if kind == "duplicate" else ts[99] - 5000
        tables["vehicle_attitude_0"]["timestamp"] = ts

    with pytest.raises(GpquadError) as err:
        read_px4_csv(make_folder(tmp_path, edit=damage), DATA)
    msg = _one_line(err)
    assert kind in msg and "vehicle_attitude_0.csv" in msg and "timestamp" in msg


def test_degrees_instead_of_radians(tmp_path):
    def degrees(tables):
        for c in ("rollspeed", "pitchspeed", "yawspeed"):
            tables["vehicle_attitude_0"][c] = np.degrees(tables["vehicle_attitude_0"][c]) * 60

    with pytest.raises(GpquadError) as err:
        read_px4_csv(make_folder(tmp_path, edit=degrees), DATA)
    msg = _one_line(err)
    assert "deg" in msg and "field 'rollspeed'" in msg and "vehicle_attitude_0.csv" in msg


def test_calm_flight_logged_in_degrees_is_caught_by_the_quaternion(tmp_path):
    """Peak rates of 34 deg/s look plausible in rad/s; the attitude says they are 57x too big."""

    def degrees(tables):
        for c in ("rollspeed", "pitchspeed", "yawspeed"):
            tables["vehicle_attitude_0"][c] = np.degrees(tables["vehicle_attitude_0"][c])

    with pytest.raises(GpquadError) as err:
        read_px4_csv(make_folder(tmp_path, edit=degrees), DATA)
    msg = _one_line(err)
    assert "57 times" in msg and "field 'rollspeed'" in msg and "vehicle_attitude_0.csv" in msg


def test_rates_in_another_frame_are_caught(tmp_path):
    def flu(tables):
        tables["vehicle_attitude_0"]["pitchspeed"] *= -1  # FLU pitch rate with an FRD attitude

    with pytest.raises(GpquadError) as err:
        read_px4_csv(make_folder(tmp_path, edit=flu), DATA)
    msg = _one_line(err)
    assert "opposite sign" in msg and "field 'pitchspeed'" in msg


def test_no_flight_in_log(tmp_path):
    def grounded(tables):
        tables["actuator_controls_0_0"]["control[3]"] = 0.05

    folder = make_folder(tmp_path, edit=grounded)
    with pytest.raises(GpquadError) as err:
        read_px4_csv(folder, DATA)
    msg = _one_line(err)
    assert "no usable flight" in msg and str(folder) in msg and "field 'data.segment'" in msg
    assert "0.0 s in flight" in msg


def test_corrupt_and_missing_files(tmp_path):
    folder = make_folder(tmp_path)
    target = next(folder.glob("*vehicle_local_position_0.csv"))
    target.write_bytes(b"\x00\xff\x13garbage" * 10)
    with pytest.raises(GpquadError) as err:
        read_px4_csv(folder, DATA)
    assert str(target.name) in _one_line(err)
    with pytest.raises(GpquadError, match="no such file or folder"):
        read_px4_csv(tmp_path / "nowhere", DATA)
    bad = tmp_path / "bad.ulg"
    bad.write_bytes(b"definitely not a ulog" * 20)
    with pytest.raises(GpquadError) as err:
        read_ulog(bad, DATA)
    assert "ULog" in _one_line(err)


def test_truncated_ulog_reads_its_whole_messages_or_fails_in_one_line(tmp_path):
    whole = (FIXTURES / "px4_sample_20s.ulg").read_bytes()
    data = dataclasses.replace(DATA, segment="none", min_segment_s=2.0)
    cut = tmp_path / "cut.ulg"
    cut.write_bytes(whole[: int(0.6 * len(whole))])  # an interrupted download
    t = read_ulog_log(cut, data).table["t"].to_numpy()
    assert 5.0 < t[-1] - t[0] < 18.0  # the head of the 20 s log, not all of it
    cut.write_bytes(whole[:2000])  # only the header survives
    with pytest.raises(GpquadError) as err:
        read_ulog(cut, data)
    msg = _one_line(err)
    assert str(cut) in msg and "field 'vehicle_attitude'" in msg and "truncated" in msg


def test_truncated_csv_row_is_a_gap_or_dropped(tmp_path):
    folder = make_folder(tmp_path)
    target = next(folder.glob("*vehicle_attitude_0.csv"))
    text = target.read_text()
    target.write_text(text[: len(text) - 37])  # cut mid-row, as an interrupted copy would
    (flight,) = read_px4_csv(folder, DATA)
    assert np.isfinite(flight.quat).all()


def test_unknown_format_is_an_error():
    """Refused when the config is read, before any data: one line naming the file and field."""
    with pytest.raises(GpquadError) as err:
        config_from_dict({"data": {"files": ["x.log"], "format": "nonsense"}}, "exp.toml")
    msg = _one_line(err)
    assert "unknown format 'nonsense'" in msg and "exp.toml" in msg and "'data.format'" in msg
    for name in ("px4-csv", "ulog", "betaflight", "table"):
        assert name in READERS


def test_ulog_fixture_reads():
    """A real (bench, disarmed) PX4 ULog cut to 20 s, BSD-3 (see fixtures/LICENSE.md)."""
    path = FIXTURES / "px4_sample_20s.ulg"
    with pytest.raises(GpquadError, match="no usable flight"):
        read_ulog(path, DATA)  # never armed: a log with no flight in it
    data = dataclasses.replace(DATA, segment="none", min_segment_s=2.0)
    log = read_ulog_log(path, data)
    assert log.table["t"].iloc[0] == pytest.approx(112.57, abs=0.01)
    assert log.measured["p"].startswith("measured") and log.measured["u"].startswith("not")
    (flight,) = read_ulog(path, data)
    assert len(flight) == 446
    assert np.allclose(np.linalg.norm(flight.quat, axis=1), 1.0)
    assert integration_check([flight], 750, 0.05).passed


def test_ulog_and_csv_give_the_same_flight(tmp_path):
    """ulog2csv's folder of the fixture and the .ulg itself go through the same path."""
    from pyulog import ULog

    ulog = ULog(str(FIXTURES / "px4_sample_20s.ulg"))
    folder = tmp_path / "csv"
    folder.mkdir()
    for d in ulog.data_list:
        pd.DataFrame(d.data).to_csv(folder / f"fx_{d.name}_{d.multi_id}.csv", index=False)
    data = dataclasses.replace(DATA, segment="none", min_segment_s=2.0)
    (a,) = read_ulog(FIXTURES / "px4_sample_20s.ulg", data)
    (b,) = read_px4_csv(folder, data)
    assert np.allclose(a.quat, b.quat, atol=1e-6) and np.allclose(a.rates, b.rates, atol=1e-4)


@needs_shared
def test_s250aq_loads_and_passes_the_integration_check():
    t0 = time.perf_counter()
    log = read_px4_folder_log(S250, DATA)
    flights = read_px4_csv(S250, DataConfig(format="px4-csv"))
    elapsed = time.perf_counter() - t0
    assert elapsed < 30.0
    assert log.measured["u"].startswith("not measured") and "v_xy_valid" in log.measured["v"]
    assert len(flights) == 3  # two logging dropouts (0.36 s, 0.38 s) split the flight
    assert sum(len(f) for f in flights) > 7000  # about 295 s at 25 Hz
    check = integration_check(flights, 750, 0.05)
    assert check.passed
    for name in ("w", "p", "q", "r"):
        assert check.row(name).status == "pass" and check.row(name).rse < 0.05
    assert check.row("u").status == "not measured" and check.row("v").status == "not measured"


@needs_shared
def test_aquaquad_has_horizontal_velocity():
    log = read_px4_folder_log(SHARED / "px4" / "AquaQuad_2016-09-17", DATA)
    assert log.measured["u"].startswith("measured")
    flights = read_px4_csv(SHARED / "px4" / "AquaQuad_2016-09-17", DataConfig())
    assert integration_check(flights, 750, 0.05).passed


@needs_shared
def test_flips_fail_the_check_at_the_paper_settings():
    """ZMR250 flips at up to 21 rad/s. Its estimator's quaternion and gyro disagree on q and r
    (RSE about 28 % and 660 % even unfiltered at 100 Hz, so not the pipeline's doing): the
    check must say so rather than let a run start."""
    flights = read_px4_csv(SHARED / "px4" / "ZMR250_flips", DataConfig())
    check = integration_check(flights, 750, 0.05)
    assert not check.passed
    assert check.row("r").status == "FAIL" and check.row("r").rse > 0.05
    assert "r " in check.failure() and "limit 5%" in check.failure()
    # and says why: the estimator's attitude and the gyro disagree, at flip rates
    assert "attitude and the gyro disagree on" in check.failure()
    assert re.search(r"gyro reaches 2\d\.\d rad/s", check.failure())
    # a log whose gyro follows its attitude gets no such diagnosis
    s250 = integration_check(read_px4_csv(S250, DataConfig()), 750, 0.05)
    assert s250.passed and s250.diagnosis == ""


@needs_shared
def test_bench_ulog_has_no_flight():
    with pytest.raises(GpquadError, match="no usable flight"):
        read_ulog(SHARED / "ulog" / "sample.ulg", DATA)


@needs_shared
def test_px4_folder_copy_with_missing_velocity_topic(tmp_path):
    copy = tmp_path / "s250"
    shutil.copytree(S250, copy)
    next(copy.glob("*vehicle_local_position_0.csv")).unlink()
    with pytest.raises(GpquadError, match="vehicle_local_position"):
        read_px4_csv(copy, DATA)


def test_log_readers_load_on_first_use():
    """A run imports only the reader of its own format: after `import gpquad.data.io` no
    built-in log reader module (nor pandas, which they need) is loaded, and each registered
    reader, called, is the module's own function (same flights)."""
    import subprocess
    import sys

    code = (
        "import sys, gpquad.data.io as io\n"
        "mods = [m for m in ('gpquad.data.generic', 'gpquad.data.px4', 'gpquad.data.ulog',"
        " 'gpquad.data.betaflight', 'gpquad.data.table', 'gpquad.data.ardupilot', 'pandas',"
        " 'scipy.ndimage')"
        " if m in sys.modules]\n"
        "print(','.join(mods))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""
    if not S250.is_dir():
        pytest.skip("../shared/data (real PX4 logs) is not present")
    lazy = READERS["px4-csv"](S250, DATA)
    direct = read_px4_csv(S250, DATA)
    assert len(lazy) == len(direct)
    for a, b in zip(lazy, direct, strict=True):
        assert np.array_equal(a.quat, b.quat) and np.array_equal(a.inputs, b.inputs)
