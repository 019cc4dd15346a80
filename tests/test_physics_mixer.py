"""Betaflight mixer model: equations (thesis IV.A), real blackbox logs, bad logs."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from gpquad.cli.commands import main
from gpquad.errors import GpquadError
from gpquad.physics.mixer import (
    LAYOUTS,
    dshot_output,
    erpm_to_rpm,
    idle_value,
    motor_commands,
    rate_mix,
    runs_of,
)

SHARED = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "betaflight"
GIMBAL = SHARED / "gimbal_ghost" / "btfl_002.bbl"
needs_logs = pytest.mark.skipif(not GIMBAL.is_file(), reason="shared Betaflight logs absent")
QUADX = LAYOUTS["quadx"]


def test_table_one_is_betaflight_quadx():
    # thesis Table I, rows m1..m4, columns T, R, P, Y
    assert QUADX.tolist() == [[1, -1, 1, -1], [1, -1, -1, 1], [1, 1, 1, 1], [1, 1, -1, -1]]


def test_rate_mix_scales_by_1000_limits_and_flips_yaw():
    pid = np.array([[100.0, 0.0, 0.0], [0.0, 0.0, 50.0], [900.0, 0.0, 0.0]])
    mix = rate_mix(pid, QUADX, pidsum_limit=500, pidsum_limit_yaw=400)
    np.testing.assert_allclose(mix[0], [-0.1, -0.1, 0.1, 0.1])
    # yaw changes sign unless yaw_motors_reversed: motor 1 has yaw column -1
    np.testing.assert_allclose(mix[1], [0.05, -0.05, -0.05, 0.05])
    np.testing.assert_allclose(mix[2], [-0.5, -0.5, 0.5, 0.5])  # limited to 500
    rev = rate_mix(pid[1:2], QUADX, 500, 400, yaw_reversed=True)
    np.testing.assert_allclose(rev[0], -mix[1])


def test_airmode_example_of_the_thesis():
    # "if the throttle setpoint is 0.8 and mix values are 0.2, 0.3, -0.5, -0.1, the throttle
    # is set to 1 - 0.3 = 0.7"
    mix = np.array([[0.2, 0.3, -0.5, -0.1]])
    cmd, over = motor_commands(mix, np.array([0.8]), QUADX, airmode=True)
    np.testing.assert_allclose(cmd[0], mix[0] + 0.7)
    assert not over[0]
    # low throttle: airmode lifts it to -min(M) = 0.5; without airmode it stays (and clips)
    cmd_air, _ = motor_commands(mix, np.array([0.1]), QUADX, airmode=True)
    cmd_off, _ = motor_commands(mix, np.array([0.1]), QUADX, airmode=False)
    np.testing.assert_allclose(cmd_air[0], mix[0] + 0.5)
    np.testing.assert_allclose(cmd_off[0], mix[0] + 0.1)


def test_mix_range_over_one_is_scaled_and_centred():
    mix = np.array([[0.8, -0.8, 0.4, -0.4]])
    cmd, over = motor_commands(mix, np.array([0.9]), QUADX, airmode=True)
    assert over[0]
    np.testing.assert_allclose(cmd[0], mix[0] / 1.6 + 0.5)


def test_idle_and_dshot_scaling():
    assert idle_value(0.055) == pytest.approx(157.945)  # thesis: 5.5 % idle -> 158
    out = dshot_output(np.array([[-0.2, 0.0, 0.5, 1.3]]), 157.945, 2047)
    np.testing.assert_array_equal(out[0], [157, 157, 1102, 2047])


def test_erpm_to_rpm_and_runs():
    np.testing.assert_allclose(erpm_to_rpm(np.array([7000.0]), 7), [1000.0])
    with pytest.raises(ValueError):
        erpm_to_rpm(np.array([1.0]), 0)
    assert runs_of(np.array([0, 1, 1, 0, 1], bool)) == [(1, 3), (4, 5)]


@needs_logs
def test_mixer_reproduces_logged_motors_of_a_real_log():
    from gpquad.physics.bflog import load_mixer_log
    from gpquad.physics.mixer_check import check_log

    log = load_mixer_log(GIMBAL, 1)
    res = check_log(log)
    assert res["yaw_reversed"] is True  # props-out quad: the fit says so
    rmse = [m["rmse"] for m in res["motors"]]
    # integer PID terms and truncation give a few DShot units; the range is 157..2047
    assert max(rmse) < 8.0
    worse = check_log(log, yaw_reversed="no")  # the wrong yaw direction must be visible
    assert min(m["rmse"] for m in worse["motors"]) > 1.5 * max(rmse)
    without = [m["rmse"] for m in res["without_airmode"]["motors"]]
    assert min(without) > 2 * max(rmse)  # airmode handling matters on this log


@needs_logs
def test_cli_json_last_line(tmp_path, capsys):
    code = main(
        [
            "physics",
            "mixer",
            str(GIMBAL),
            "--log-index",
            "1",
            "--json",
            "--no-figures",
            "--out",
            str(tmp_path / "run"),
        ]
    )
    assert code == 0
    last = capsys.readouterr().out.strip().splitlines()[-1]
    obj = json.loads(last)
    (log,) = obj["logs"]
    assert log["index"] == 1 and len(log["motors"]) == 4
    assert {"rmse", "r2"} <= set(log["motors"][0]) and 0 <= log["saturated_fraction"] <= 1
    run = json.loads((tmp_path / "run" / "run.json").read_text())
    assert run["git_revision"] and "orangebox" in run["versions"]
    assert (tmp_path / "run" / "mixer.md").is_file()


def _renamed_copy(tmp_path: Path, old: bytes, new: bytes) -> Path:
    """The shared log with one field name changed in its header (same length: frames intact)."""
    assert len(old) == len(new)
    data = GIMBAL.read_bytes()
    assert old in data
    path = tmp_path / "edited.bbl"
    path.write_bytes(data.replace(old, new))
    return path


def _one_line_error(capsys, argv) -> str:
    code = main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("gpquad: error:")
    return err[0]


@needs_logs
def test_log_without_motor_field(tmp_path, capsys):
    path = _renamed_copy(tmp_path, b"motor[", b"motxr[")
    line = _one_line_error(capsys, ["physics", "mixer", str(path), "--log-index", "1"])
    assert "no motor field" in line and "motor[0]" in line


@needs_logs
def test_log_without_pid_field(tmp_path, capsys):
    path = _renamed_copy(tmp_path, b"axisP[", b"axisQ[")
    line = _one_line_error(capsys, ["physics", "mixer", str(path), "--log-index", "1"])
    assert "no PID field" in line and "axisP[0]" in line


@needs_logs
def test_truncated_log(tmp_path, capsys):
    data = GIMBAL.read_bytes()
    path = tmp_path / "cut.bbl"
    start = data.index(b"H Product:", 10)  # second log starts here: cut inside the first
    path.write_bytes(data[: start // 2])
    line = _one_line_error(capsys, ["physics", "mixer", str(path), "--log-index", "1"])
    assert "truncated" in line or "damaged" in line


def test_not_a_log(tmp_path, capsys):
    path = tmp_path / "noise.bbl"
    path.write_bytes(bytes(range(256)) * 8)
    _one_line_error(capsys, ["physics", "mixer", str(path)])
    _one_line_error(capsys, ["physics", "mixer", str(tmp_path / "missing.bbl")])


@needs_logs
def test_missing_log_index(tmp_path):
    from gpquad.physics.mixer_check import check_file

    src = tmp_path / "three.bbl"
    shutil.copy(GIMBAL, src)
    with pytest.raises(GpquadError, match="log 9 does not exist"):
        check_file(src, log_index=9)


def test_thrust_linearization_matches_betaflight_formula():
    from gpquad.physics.mixer import thrust_linearization

    m = np.array([-0.1, 0.0, 0.25, 0.5, 1.0])
    np.testing.assert_array_equal(thrust_linearization(m, 0), m)
    t, b = 0.2, 0.8 / 0.4
    out = thrust_linearization(m, 20)
    np.testing.assert_allclose(out[2:], np.sqrt(m[2:] / t + b * b) - b)
    assert out[0] == -0.1 and out[1] == 0.0 and out[-1] == pytest.approx(1.0)
    assert out[3] > 0.5  # raises mid throttle, keeps the ends


def test_bad_thrust_linear_value_is_one_line(capsys):
    if not GIMBAL.is_file():
        pytest.skip("shared Betaflight logs absent")
    line = _one_line_error(
        capsys,
        [
            "physics",
            "mixer",
            str(GIMBAL),
            "--log-index",
            "1",
            "--thrust-linear",
            "lots",
            "--no-figures",
        ],
    )
    assert "--thrust-linear" in line
