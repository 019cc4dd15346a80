"""Integration check semantics, `gpquad data check`, time alignment, the "table" format, and
`gpquad run` refusing (or accepting) real data."""

import dataclasses
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from gpquad.cli.commands import main
from gpquad.data.align import estimate_offset
from gpquad.data.flight import enu_flu_quat, flip_body
from gpquad.data.formats import FORMATS
from gpquad.data.integration_check import integration_check
from gpquad.data.io import READERS, load_dataset, register_reader
from gpquad.data.simulator import simulate
from gpquad.data.table import read_table_log
from gpquad.engine.kernels.quaternion import euler_array
from gpquad.errors import GpquadError
from gpquad.study.config import Config, DataConfig, SimulatorConfig, config_from_dict

FIXTURES = Path(__file__).parent / "fixtures"
SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"
S250 = SHARED / "px4" / "S250AQ_2016-12-13"
needs_shared = pytest.mark.skipif(
    not S250.is_dir(), reason="../shared/data (real PX4 logs) is not present"
)
INPUTS = ("u_P", "u_R", "u_Y", "u_T")


@pytest.fixture(scope="module")
def sim_flight():
    truth = SimulatorConfig(duration_s=70.0, seed=3, integrator="euler")  # eq. 2: exact round trip
    return simulate(truth, INPUTS)


def test_check_passes_on_consistent_data_and_reports_round_trip(sim_flight):
    check = integration_check([sim_flight], 750, 0.05)
    assert check.passed and check.n_windows == 2
    assert all(r.round_trip < 1e-9 for r in check.rows)
    assert all(r.rse < 1e-12 for r in check.rows)
    assert "verdict: PASS" in check.table()


def test_check_fails_with_numbers_when_rates_disagree(sim_flight):
    f = dataclasses.replace(sim_flight, meta=dict(sim_flight.meta))
    states = np.hstack([euler_array(f.quat), f.vel, f.rates])
    ref = states.copy()
    ref[:, 6] *= 1.3  # the "gyro" reads 30 % more than the attitude implies
    f.meta["reference"] = ref
    check = integration_check([f], 750, 0.05)
    assert not check.passed
    p = check.row("p")
    # RSE of x against 1.3 x is 0.09 var(x)/var(1.3 x) ... = 0.3^2 / 1.3^2 = 5.3 %
    assert p.status == "FAIL" and p.rse == pytest.approx(0.09 / 1.69, rel=0.02)
    assert check.row("q").status == "pass"
    assert "p 5.3%" in check.failure()


def test_not_measured_states_neither_pass_nor_fail(sim_flight):
    f = dataclasses.replace(sim_flight, meta=dict(sim_flight.meta))
    f.meta["measured"] = {"u": "not measured (test)", "v": "not measured (test)"}
    ref = np.hstack([euler_array(f.quat), f.vel, f.rates])
    ref[:, 3] += 5.0 * np.sin(np.arange(len(f)))  # u is garbage: would fail if judged
    f.meta["reference"] = ref
    check = integration_check([f], 750, 0.05)
    assert check.row("u").status == "not measured" and check.row("u").rse > 0.5
    assert not check.notes
    assert check.passed


def test_align_recovers_a_known_offset_with_noise():
    rng = np.random.default_rng(11)
    t = np.arange(0.0, 120.0, 0.01)
    sig = np.column_stack([np.sin(0.7 * t) + 0.5 * np.sin(2.3 * t + 1), np.cos(1.1 * t) ** 3])
    sig += rng.normal(0, 0.05, sig.shape)
    keep = (t > 30) & (t < 90)
    t_b = t[keep][::3] + 7.432  # another clock, another rate
    x_b = sig[keep][::3] + rng.normal(0, 0.05, (keep.sum() // 3 + 1, 2))[: len(t_b)]
    res = estimate_offset(t, sig, t_b, x_b)
    assert res.offset_s == pytest.approx(7.432, abs=2e-3)
    assert res.rmse == pytest.approx(np.sqrt(2) * 0.05, rel=0.35)  # noise of both logs
    assert res.correlation > 0.95
    assert np.allclose(res.shift(t_b), t[keep][::3], atol=2e-3)
    with pytest.raises(GpquadError, match="constant"):
        estimate_offset(t, np.ones_like(t), t_b, x_b[:, 0])


@needs_shared
def test_align_two_real_signals_of_one_log():
    """Attitude rates vs rate setpoints of S250AQ: the controller tracks with a small lag."""
    from gpquad.data.px4 import read_px4_folder

    tp = read_px4_folder(S250)
    ta = tp.time("vehicle_attitude")
    xa = np.column_stack([tp.column("vehicle_attitude", c) for c in ("rollspeed", "pitchspeed")])
    sel = (ta > 125) & (ta < 235)
    res = estimate_offset(ta[sel], xa[sel], ta[sel] + 3.0, xa[sel], max_lag_s=10.0)
    assert res.offset_s == pytest.approx(3.0, abs=1e-3) and res.rmse < 1e-3


def _write_table(flight, path, frame):
    df = flight.to_frame()
    if frame == "ENU/FLU":
        q = enu_flu_quat(flight.quat)
        df[["qw", "qx", "qy", "qz"]] = q
        df[["u", "v", "w"]] = flip_body(flight.vel)
        df[["p", "q", "r"]] = flip_body(flight.rates)
    df = df.drop(columns=["x", "y", "z"], errors="ignore")
    df.to_csv(path, index=False)
    return path


def test_table_format_frames_round_trip(sim_flight, tmp_path):
    data = DataConfig(
        format="table",
        segment="none",
        min_segment_s=5.0,
        resample_hz=25.0,
        cutoff_hz=0.0,
        downsample=1,
        rates_from="log",
    )
    ned = read_table_log(_write_table(sim_flight, tmp_path / "ned.csv", "NED/FRD"), data)
    enu = read_table_log(
        _write_table(sim_flight, tmp_path / "enu.csv", "ENU/FLU"),
        dataclasses.replace(data, frame="ENU/FLU"),
    )
    (a,), (b,) = ned, enu
    assert np.allclose(a.quat, b.quat, atol=1e-9) and np.allclose(a.vel, b.vel, atol=1e-9)
    assert np.allclose(a.rates, b.rates, atol=1e-9)
    n = len(a)
    assert np.allclose(a.rates, sim_flight.rates[:n], atol=1e-9)


def test_table_format_irregular_rows_and_degrees(sim_flight, tmp_path):
    df = sim_flight.to_frame().drop(columns=["x", "y", "z"], errors="ignore")
    rng = np.random.default_rng(2)
    df["t"] = df["t"] + rng.uniform(-0.005, 0.005, len(df))  # jittered clock: resampled
    path = tmp_path / "jitter.parquet"
    df.to_parquet(path)
    data = DataConfig(format="table", segment="none", min_segment_s=5.0)
    flights = read_table_log(path, data)
    assert flights and flights[0].dt == pytest.approx(0.04)  # 25 Hz file -> 100 Hz -> /4
    df[["p", "q", "r"]] = np.degrees(df[["p", "q", "r"]]) * 20
    df.to_parquet(path)
    with pytest.raises(GpquadError, match="degrees where radians"):
        read_table_log(path, data)


def test_table_rates_in_degrees_or_another_frame_are_one_line_errors(sim_flight, tmp_path):
    """The quaternion says how fast the craft turns: rates 57x larger, or of the opposite sign
    on q and r (FLU rates beside an FRD attitude), name the file and the mapped column."""
    df = sim_flight.to_frame().drop(columns=["x", "y", "z"], errors="ignore")
    df = df.rename(columns={"q": "gyro_y"})
    data = DataConfig(format="table", segment="none", min_segment_s=5.0, columns={"q": "gyro_y"})
    path = tmp_path / "deg.csv"
    df.assign(p=np.degrees(df["p"])).to_csv(path, index=False)
    with pytest.raises(GpquadError) as err:
        read_table_log(path, data)
    msg = str(err.value)
    assert "\n" not in msg and "57 times" in msg and msg.startswith(f"{path}, field 'p'")
    path = tmp_path / "flu.csv"
    df.assign(gyro_y=-df["gyro_y"], r=-df["r"]).to_csv(path, index=False)
    with pytest.raises(GpquadError) as err:
        read_table_log(path, data)
    msg = str(err.value)
    assert "opposite sign" in msg and msg.startswith(f"{path}, field 'gyro_y'")


def test_cli_check_prints_table_writes_png(capsys, tmp_path):
    png = tmp_path / "look.png"
    code = main(
        [
            "data",
            "check",
            str(FIXTURES / "px4_sample_20s.ulg"),
            "--plot",
            str(png),
            "--config",
            str(_cfg(tmp_path, 'segment = "none"\nmin_segment_s = 2.0\n')),
        ]
    )
    out = capsys.readouterr().out
    assert code == 0
    assert "vehicle_attitude" in out and "not measured (v_xy_valid = 0" in out
    assert "Integration check" in out and "verdict: PASS" in out
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000


def _cfg(tmp_path, data_lines: str) -> Path:
    path = tmp_path / "c.toml"
    path.write_text(f"[data]\n{data_lines}")
    return path


def test_cli_check_unusable_data_exits_nonzero_with_one_line(capsys, tmp_path):
    code = main(
        ["data", "check", str(FIXTURES / "px4_sample_20s.ulg"), "--plot", str(tmp_path / "x.png")]
    )
    err = capsys.readouterr().err.strip()
    assert code != 0
    assert err.count("\n") == 0 and "no usable flight" in err and "px4_sample_20s.ulg" in err
    code = main(["data", "check", str(tmp_path / "nothing.xyz")])
    assert code != 0 and "no such file" in capsys.readouterr().err
    (tmp_path / "f.xyz").write_text("1")
    code = main(["data", "check", str(tmp_path / "f.xyz")])
    assert code != 0 and "--format" in capsys.readouterr().err


def test_run_refuses_a_dataset_that_fails_the_check(sim_flight, tmp_path):
    bad = dataclasses.replace(sim_flight, meta=dict(sim_flight.meta))
    ref = np.hstack([euler_array(bad.quat), bad.vel, bad.rates])
    ref[:, 8] *= 2.0
    bad.meta["reference"] = ref
    register_reader("test-bad", lambda path, data: [bad])
    try:
        cfg = config_from_dict({"data": {"files": ["x"], "format": "test-bad"}})
        with pytest.raises(GpquadError, match="integration check failed: .* r "):
            load_dataset(cfg)
        ok = config_from_dict(
            {"data": {"files": ["x"], "format": "test-bad", "check_before_run": False}}
        )
        assert load_dataset(ok).n_samples == len(bad)
    finally:
        READERS.pop("test-bad")
        FORMATS.discard("test-bad")


@needs_shared
def test_gpquad_run_on_s250aq_gives_the_measured_equations(tmp_path, capsys):
    """The experiments/px4_s250.toml config with a tiny budget (1 iteration, 5 generations):
    the four equations of measured states; a_x and a_y (u, v not measured: no GPS) are not
    identified, and the model and the run's warnings say so."""
    import tomllib

    root = Path(__file__).resolve().parents[1]
    table = tomllib.loads((root / "experiments" / "px4_s250.toml").read_text())
    table["data"]["files"] = [str(S250)]
    table["evolution"].update(
        iterations=1, model_generations=5, test_generations=2, simplify_generations=2
    )
    table["output"] = {"progress": False}
    cfg = config_from_dict(table, "px4_s250.toml")
    from gpquad.study.runner import run_experiment

    model = run_experiment(cfg, tmp_path / "run", progress=False)
    assert sorted(model.equations) == sorted(["a_z", "p_dot", "q_dot", "r_dot"])
    assert "a_x: not identified: the log does not measure u" in model.text()
    assert "a_y: not identified" in capsys.readouterr().err
    saved = json.loads((tmp_path / "run" / "model.json").read_text())
    assert sorted(saved["targets"]) == sorted(model.equations)
    config = json.loads((tmp_path / "run" / "config.json").read_text())
    assert config["data"]["filter_taps"] == 200 and config["data"]["downsample"] == 4


@needs_shared
def test_run_of_only_unmeasured_targets_exits_with_one_line(tmp_path):
    """`gpquad run px4_s250.toml --target a_x --target a_y` (u, v not measured): exit code 2
    and one line naming evolution.targets and the states, before any search."""
    import os
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[1]
    env = {**os.environ, "PYTHONPATH": str(root) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    config = root / "experiments" / "px4_s250.toml"
    out = tmp_path / "r"
    command = [sys.executable, "-m", "gpquad", "run", str(config), "--out", str(out)]
    proc = subprocess.run(
        [*command, "--target", "a_x", "--target", "a_y"],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    errors = [line for line in proc.stderr.splitlines() if "error" in line]
    assert len(errors) == 1 and "evolution.targets" in errors[0] and "a_x: u" in errors[0]
    assert not (out / "checkpoints").exists() or not any((out / "checkpoints").iterdir())


def test_config_rejects_bad_pipeline_settings():
    for bad, field in (
        ({"segment": "sometimes"}, "data.segment"),
        ({"segment": "range"}, "data.time_range"),
        ({"cutoff_hz": 60.0}, "data.cutoff_hz"),
        ({"downsample": 0}, "data.downsample"),
        ({"rates_from": "magic"}, "data.rates_from"),
    ):
        with pytest.raises(GpquadError) as err:
            config_from_dict({"data": bad})
        assert field in str(err.value)
    assert Config().data.filter_taps == 200


def test_generic_frame_table_column_mapping(sim_flight, tmp_path):
    df = sim_flight.to_frame().rename(columns={"qw": "att_w", "u_T": "throttle"})
    df = df.drop(columns=["x", "y", "z"], errors="ignore")
    path = tmp_path / "mapped.csv"
    pd.DataFrame(df).to_csv(path, index=False)
    data = DataConfig(
        format="table",
        segment="range",
        time_range=(5.0, 60.0),
        columns={"qw": "att_w", "u_T": "throttle"},
        min_segment_s=5.0,
    )
    (f,) = read_table_log(path, data)
    assert f.t[0] >= 5.0 and f.t[-1] <= 60.0
    with pytest.raises(GpquadError, match="missing column 'nope'"):
        read_table_log(path, dataclasses.replace(data, columns={"qw": "nope"}))


def test_velocity_from_position_only(sim_flight, tmp_path):
    """A motion-capture-like table (pose only): body velocity from position differences."""
    df = sim_flight.to_frame()
    if "x" not in df:
        from gpquad.engine.kernels.integrator import body_accelerations
        from gpquad.engine.kernels.integrator import integrate as _integrate

        acc = body_accelerations(sim_flight.vel, sim_flight.rates, sim_flight.dt)
        _, _, _, pos = _integrate(
            sim_flight.quat[0].copy(),
            sim_flight.vel[0].copy(),
            sim_flight.rates[0].copy(),
            np.zeros(3),
            acc,
            sim_flight.dt,
        )
        df["x"], df["y"], df["z"] = pos[:, 0], pos[:, 1], pos[:, 2]
    df = df.drop(columns=["u", "v", "w"])
    path = tmp_path / "mocap.csv"
    df.to_csv(path, index=False)
    data = DataConfig(
        format="table",
        segment="none",
        min_segment_s=5.0,
        resample_hz=25.0,
        cutoff_hz=0.0,
        downsample=1,
    )
    (f,) = read_table_log(path, data)
    assert any("position differences" in s for s in f.meta["pipeline"])
    # the integrator's position update inverted exactly: the simulator's body velocity back
    assert np.allclose(f.vel, sim_flight.vel[: len(f)], atol=1e-6)
    assert integration_check([f], 750, 0.05).passed


def test_cli_align_two_logs_on_different_clocks(tmp_path, capsys):
    """The ULog fixture against a CSV copy of its gyro on a clock 2.5 s ahead."""
    from gpquad.data.ulog import read_ulog_log

    log = read_ulog_log(FIXTURES / "px4_sample_20s.ulg", DataConfig(segment="none"))
    cols = ["t", "qw", "qx", "qy", "qz", "p", "q", "r", "vx", "vy", "vz", *INPUTS]
    df = log.table[cols].copy()
    df["t"] += 2.5
    df.to_csv(tmp_path / "other.csv", index=False)
    code = main(
        [
            "data",
            "align",
            str(FIXTURES / "px4_sample_20s.ulg"),
            str(tmp_path / "other.csv"),
            "--signal",
            "p,q,r",
            "--max-lag",
            "5",
        ]
    )
    out = capsys.readouterr().out
    assert code == 0
    offset = float(out.split("clock offset (B - A): ")[1].split(" s")[0])
    assert offset == pytest.approx(2.5, abs=0.01)
    assert "residual RMSE of p, q, r" in out
    code = main(
        [
            "data",
            "align",
            str(FIXTURES / "px4_sample_20s.ulg"),
            str(tmp_path / "other.csv"),
            "--signal",
            "nope",
        ]
    )
    assert code != 0 and "no signal ['nope']" in capsys.readouterr().err


def test_check_reads_an_engine_ready_file_as_gpquad_run_does(capsys, tmp_path, short_flight):
    """A uniform generic CSV is checked as-is (no re-filtering), like `gpquad run` reads it."""
    from gpquad.data.flight import write_flight_file

    path = write_flight_file(short_flight, tmp_path / "sim.csv")
    assert main(["data", "check", str(path), "--plot", str(tmp_path / "s.png")]) == 0
    out = capsys.readouterr().out
    assert "(format generic)" in out and "verdict: PASS" in out


def test_a_failing_check_still_writes_its_figure(capsys, tmp_path):
    """When the integration check fails the figure is needed most: it is written, and the
    command still exits 2 with one error line."""
    png = tmp_path / "fail.png"
    strict = _cfg(tmp_path, 'segment = "none"\nmin_segment_s = 2.0\ncheck_max_rse = 1e-12\n')
    code = main(
        [
            "data",
            "check",
            str(FIXTURES / "px4_sample_20s.ulg"),
            "--plot",
            str(png),
            "--config",
            str(strict),
        ]
    )
    captured = capsys.readouterr()
    assert code == 2 and "integration check failed" in captured.err
    assert [line for line in captured.err.splitlines() if "error" in line][0].count("\n") == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and "quick-look plot" in captured.out


def test_quick_look_marks_unmeasured_signals(tmp_path, sim_flight):
    """u and v not measured: drawn apart and labelled so (the check can fail: a measured
    flight has no such label)."""
    import matplotlib

    matplotlib.use("Agg")
    from unittest import mock

    from gpquad.cli import data as cli_data

    labels = []
    real = matplotlib.axes.Axes.plot

    def spy(self, *args, **kwargs):
        labels.append(kwargs.get("label"))
        return real(self, *args, **kwargs)

    blind = dataclasses.replace(
        sim_flight,
        meta={
            **sim_flight.meta,
            "measured": {
                "u": "not measured (no GPS)",
                "v": "not measured (no GPS)",
                "w": "measured (baro)",
            },
        },
    )
    with mock.patch.object(matplotlib.axes.Axes, "plot", spy):
        cli_data.quick_look([blind], tmp_path / "a.png", "t")
    assert "u (not measured)" in labels and "w" in labels
    labels.clear()
    with mock.patch.object(matplotlib.axes.Axes, "plot", spy):
        cli_data.quick_look([sim_flight], tmp_path / "b.png", "t")
    assert not any(label and "not measured" in label for label in labels)
