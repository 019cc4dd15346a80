"""Mistakes that used to end in a traceback, a hang or a silent wrong result: each is one
`gpquad: error:` line (exit 2) naming the field, or a warning where the result is still
right, and creates no file beyond the command's own."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
from test_hostile_inputs import QUICK, write_inputs
from test_trust_code import gp_folder, one_error_line

from gpquad.cli.commands import main
from gpquad.data.simulator import simulate
from gpquad.study.config import MEDIAN_MODEL, SimulatorConfig

INPUTS = ("u_P", "u_R", "u_Y", "u_T")


@pytest.fixture(scope="module")
def flight_csv(tmp_path_factory):
    path = tmp_path_factory.mktemp("flight") / "f.csv"
    assert main(["simulate", "--out", str(path)]) == 0
    return path


# ---------------------------------------------------------------- configs
@pytest.mark.parametrize("encoding", ["latin-1", "utf-16", "binary"])
@pytest.mark.parametrize("command", ["run", "simulate", "sweep"])
def test_config_that_is_not_utf8(tmp_path, capsys, encoding, command):
    text = QUICK.replace("[simulator]", "# caf\xe9\n[simulator]")
    blob = bytes(range(256)) if encoding == "binary" else text.encode(encoding)
    (tmp_path / "c.toml").write_bytes(blob)
    argv = {
        "run": ["run", tmp_path / "c.toml", "--out", tmp_path / "r"],
        "simulate": ["simulate", tmp_path / "c.toml", "--out", tmp_path / "f.csv"],
        "sweep": ["sweep", tmp_path / "c.toml", "--out", tmp_path / "s"],
    }[command]
    line = one_error_line(capsys, argv)
    assert "c.toml" in line and "not UTF-8" in line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.toml"]


SIMULATOR = {
    "duration-huge": ("duration_s = 1e12", "simulator.duration_s"),
    "rate-huge": ("rate_hz = 1e9", "simulator.rate_hz"),
    "duration-nan": ("duration_s = nan", "simulator.rate_hz"),
    "duration-inf": ("duration_s = inf", "simulator.rate_hz"),
    "rate-negative-duration-negative": ("rate_hz = -1.0\nduration_s = -1.0", "simulator.rate_hz"),
    "stick-negative": ("stick_sd = {u_P = -0.1}", "simulator.stick_sd.u_P"),
    "stick-nan": ("stick_sd = {u_R = nan}", "simulator.stick_sd.u_R"),
    "noise-huge": ("measurement_noise = {attitude = 1e6}", "simulator.measurement_noise.attitude"),
    "noise-negative": ("measurement_noise = {rates = -1.0}", "simulator.measurement_noise"),
    "noise-unknown": ("measurement_noise = {altitude = 0.1}", "simulator.measurement_noise"),
    "input-limit-zero": ("input_limit = 0.0", "simulator.input_limit"),
    "time-constant-zero": ("stick_time_constant_s = 0.0", "simulator.stick_time_constant_s"),
    "motionless": (
        "stick_sd = {u_P = 0.0, u_R = 0.0, u_Y = 0.0, u_T = 0.0}\npilot_gains = {}",
        "simulator.stick_sd",
    ),
    "delay-huge": ('equations = {p_dot = "u_R(t-100000000) - p"}', "simulator.equations.p_dot"),
    "power-huge": ('equations = {p_dot = "p**100000"}', "simulator.equations.p_dot"),
    "one-input-still": (
        "stick_sd = {u_Y = 0.0}\npilot_gains = {u_R = {phi = -0.6}}",
        "simulator.stick_sd.u_Y",
    ),
}


@pytest.mark.parametrize("case", sorted(SIMULATOR))
@pytest.mark.parametrize("command", ["simulate", "run"])
def test_simulator_settings(tmp_path, capsys, case, command):
    line_in_toml, field = SIMULATOR[case]
    text = (
        QUICK.replace("duration_s = 40.0\n", "" if "duration" in case else "duration_s = 40.0\n")
        + line_in_toml
        + "\n"
    )
    (tmp_path / "c.toml").write_text(text)
    argv = (
        ["simulate", tmp_path / "c.toml", "--out", tmp_path / "f.csv"]
        if command == "simulate"
        else ["run", tmp_path / "c.toml", "--out", tmp_path / "r", "--quiet"]
    )
    line = one_error_line(capsys, argv)
    assert field in line, line
    assert not (tmp_path / "f.csv").exists() and not (tmp_path / "r" / "model.json").exists()


def test_a_partial_equations_table_changes_one_equation():
    """equations = {p_dot = ...} replaces p_dot only; the other five keep the truth."""
    flight = simulate(SimulatorConfig(duration_s=20.0, equations={"p_dot": "-2.0*p + u_R"}), INPUTS)
    assert flight.meta["equations"] == {**MEDIAN_MODEL, "p_dot": "-2.0*p + u_R"}
    assert np.std(flight.vel[:, 0]) > 1e-3 and np.std(flight.vel[:, 2]) > 1e-3


def test_a_partial_stick_table_moves_every_input():
    flight = simulate(SimulatorConfig(duration_s=20.0, stick_sd={"u_P": 0.2}), INPUTS)
    assert all(np.ptp(flight.inputs[:, j]) > 0.01 for j in range(4))


@pytest.mark.parametrize(
    "line,field",
    [
        ("const_variance = inf", "evolution.gp.const_variance"),
        ("const_low = -inf", "evolution.gp.const_low"),
    ],
)
def test_constant_settings_must_be_finite(tmp_path, capsys, line, field):
    (tmp_path / "c.toml").write_text(QUICK.replace("[simulator]", f"{line}\n[simulator]"))
    out = one_error_line(capsys, ["run", tmp_path / "c.toml", "--out", tmp_path / "r", "--quiet"])
    assert f"'{field}'" in out


def test_exclude_leaves_of_every_variable(tmp_path, capsys):
    names = '["phi", "theta", "psi", "u", "v", "w", "p", "q", "r", "u_P", "u_R", "u_Y", "u_T"]'
    (tmp_path / "c.toml").write_text(
        QUICK.replace("[simulator]", f"exclude_leaves = {names}\n[simulator]")
    )
    line = one_error_line(capsys, ["run", tmp_path / "c.toml", "--out", tmp_path / "r", "--quiet"])
    assert "evolution.exclude_leaves" in line


# ---------------------------------------------------------------- hand-edited model.json
def _prefix(codes, values):
    return lambda m: m["targets"]["p_dot"].__setitem__("prefix", {"codes": codes, "values": values})


def _set(key, value):
    return lambda m: m["targets"]["p_dot"].__setitem__(key, value)


MODEL_EDITS = {
    "bad-code": (_prefix([99, 4, 4], [0.0, 1.0, 2.0]), "prefix.codes[0]"),
    "negative-code": (_prefix([-1], [0.0]), "prefix.codes[0]"),
    "short-values": (_prefix([2, 4, 11], [1.0]), "prefix.values"),
    "incomplete-tree": (_prefix([2, 4], [1.0, 2.0]), "prefix.codes"),
    "empty-prefix": (_prefix([], []), "prefix"),
    "huge-tree": (_prefix([0] * 5000 + [4] * 5001, [1.0] * 10001), "prefix"),
    "deep-tree": (_prefix([0, 4] * 100 + [4], [1.0] * 201), "prefix.codes"),
    "nan-constant": (_prefix([2, 4, 11], [float("nan"), 0.0, 0.0]), "prefix.values[0]"),
    "huge-constant": (_prefix([2, 4, 11], [1e308, 0.0, 0.0]), "prefix.values[0]"),
    "string-codes": (_prefix("abc", [1.0]), "prefix"),
    "huge-delay": (_set("delays", {"u_R": 10**9}), "delays.u_R"),
    "negative-delay": (_set("delays", {"u_R": -3}), "delays.u_R"),
    "delay-of-unknown": (_set("delays", {"u_Q": 2}), "delays.u_Q"),
    "expr-disagrees": (_set("expr", "42*q"), "targets.p_dot.expr"),
    "empty-inputs": (lambda m: m.__setitem__("input_names", []), "input_names"),
    "payload-input-name": (
        lambda m: m.__setitem__(
            "input_names", ["__import__('os').system('x')", "u_R", "u_Y", "u_T"]
        ),
        "input_names[0]",
    ),
    "renamed-target": (
        lambda m: m["targets"].__setitem__("x_dot", m["targets"].pop("p_dot")),
        "targets.x_dot",
    ),
    "dt-zero": (lambda m: m.__setitem__("dt", 0.0), "'dt'"),
    "dt-nan": (lambda m: m.__setitem__("dt", float("nan")), "'dt'"),
    "targets-list": (lambda m: m.__setitem__("targets", []), "'targets'"),
}


@pytest.mark.parametrize("case", sorted(MODEL_EDITS))
@pytest.mark.parametrize("command", ["export", "fly", "score"])
def test_hand_edited_model(tmp_path, capsys, flight_csv, case, command):
    edit, field = MODEL_EDITS[case]
    run = gp_folder(tmp_path)
    model = json.loads((run / "model.json").read_text())
    edit(model)
    (run / "model.json").write_text(json.dumps(model))
    argv = {
        "export": ["export", run, "--format", "json"],
        "fly": [
            "fly",
            run,
            "--inputs",
            write_inputs(tmp_path / "in.csv"),
            "--out",
            tmp_path / "o.csv",
        ],
        "score": ["score", run, "--data", flight_csv],
    }[command]
    line = one_error_line(capsys, argv)
    assert "model.json" in line and field in line, line
    assert not (tmp_path / "o.csv").exists()


@pytest.mark.parametrize("command", ["export", "fly"])
def test_an_interrupted_model_is_flown_with_a_warning(tmp_path, capsys, command):
    run = gp_folder(tmp_path)
    model = json.loads((run / "model.json").read_text())
    model["interrupted"] = True
    (run / "model.json").write_text(json.dumps(model))
    argv = (
        ["export", str(run)]
        if command == "export"
        else [
            "fly",
            str(run),
            "--inputs",
            str(write_inputs(tmp_path / "in.csv")),
            "--out",
            str(tmp_path / "o.csv"),
        ]
    )
    capsys.readouterr()
    assert main(argv) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "warning" in err[0] and "interrupted" in err[0]


# ---------------------------------------------------------------- command arguments
@pytest.mark.parametrize("horizon", ["0", "-5", "1000000000"])
def test_compare_horizon(tmp_path, capsys, horizon):
    run = gp_folder(tmp_path)
    line = one_error_line(capsys, ["compare", run, "--horizon", horizon, "--out", tmp_path / "c"])
    assert "--horizon" in line
    assert not (tmp_path / "c.md").exists()


@pytest.mark.parametrize("horizon", ["inf", "nan", "-1", "0"])
def test_score_horizon(tmp_path, capsys, flight_csv, horizon):
    line = one_error_line(
        capsys, ["score", gp_folder(tmp_path), "--data", flight_csv, "--horizon-s", horizon]
    )
    assert "--horizon-s" in line


def test_score_at_another_sample_rate(tmp_path, capsys, flight_csv):
    """A model of 50 Hz scored on a 25 Hz log would read every delay as twice as long."""
    run = gp_folder(tmp_path)
    model = json.loads((run / "model.json").read_text())
    model["dt"] = 0.02
    (run / "model.json").write_text(json.dumps(model))
    line = one_error_line(capsys, ["score", run, "--data", flight_csv])
    assert "50 Hz" in line and "25 Hz" in line and "field 'dt'" in line


FLY_INPUTS = {
    "empty": b"",
    "garbage": b"\x00\xff garbage \x01\n1,2\n",
    "utf16": "t,u_P,u_R,u_Y,u_T\n0,0,0,0,0\n0.04,0,0,0,0\n".encode("utf-16"),
    "header-only": b"t,u_P,u_R,u_Y,u_T\n",
    "one-row": b"t,u_P,u_R,u_Y,u_T\n0,0,0,0,0\n",
    "text-values": b"t,u_P,u_R,u_Y,u_T\n0,a,0,0,0\n0.04,b,0,0,0\n",
    "nan": b"t,u_P,u_R,u_Y,u_T\n0,nan,0,0,0\n0.04,0,0,0,0\n0.08,0,0,0,0\n",
}


@pytest.mark.parametrize("case", sorted(FLY_INPUTS))
def test_fly_inputs(tmp_path, capsys, case):
    (tmp_path / "in.csv").write_bytes(FLY_INPUTS[case])
    line = one_error_line(
        capsys,
        ["fly", gp_folder(tmp_path), "--inputs", tmp_path / "in.csv", "--out", tmp_path / "o.csv"],
    )
    assert "in.csv" in line
    assert not (tmp_path / "o.csv").exists()


@pytest.mark.parametrize("command", ["check", "score"])
def test_a_named_pipe_is_refused_without_blocking(tmp_path, capsys, command):
    os.mkfifo(tmp_path / "pipe.csv")
    argv = (
        ["data", "check", tmp_path / "pipe.csv", "--plot", tmp_path / "p.png"]
        if command == "check"
        else ["score", gp_folder(tmp_path), "--data", tmp_path / "pipe.csv"]
    )
    line = one_error_line(capsys, argv)
    assert "pipe" in line


@pytest.fixture(scope="module")
def sweep_folder(tmp_path_factory):
    folder = tmp_path_factory.mktemp("sweep")
    (folder / "c.toml").write_text(QUICK + "[sweep]\nruns = 1\nfull_models = 1\n")
    assert main(["sweep", str(folder / "c.toml"), "--out", str(folder / "s"), "--quiet"]) == 0
    return folder / "s"


@pytest.mark.parametrize(
    "target",
    [
        "runs/p_dot/rep000/history.csv",
        "sweep.json",
        "runs/p_dot/rep000/result.json",
        "assembly.json",
    ],
)
@pytest.mark.parametrize("blob", [b"\x00\xffnot it", b"", b"[1, 2]"])
def test_report_of_a_damaged_sweep(tmp_path, capsys, sweep_folder, target, blob):
    import shutil

    folder = tmp_path / "s"
    shutil.copytree(sweep_folder, folder)
    (folder / target).write_bytes(blob)
    line = one_error_line(capsys, ["report", folder, "--format", "png"])
    assert os.path.basename(target) in line, line


def test_a_log_whose_inputs_never_change_is_refused(tmp_path):
    """Every log reader gets the generic reader's excitation check (constant set-points)."""
    import dataclasses

    from gpquad.data.io import _read_file
    from gpquad.errors import GpquadError
    from gpquad.study.config import Config

    flight = simulate(SimulatorConfig(duration_s=10.0), INPUTS)
    still = dataclasses.replace(flight, inputs=np.ones_like(flight.inputs))
    assert _read_file(Config(), lambda path, data: [flight], tmp_path / "log.ulg") == [flight]
    with pytest.raises(GpquadError, match="never change") as info:
        _read_file(Config(), lambda path, data: [still, still], tmp_path / "log.ulg")
    assert "log.ulg" in str(info.value) and "data.inputs" in str(info.value)


def test_score_of_an_interrupted_run_warns(tmp_path, capsys, flight_csv):
    run = gp_folder(tmp_path)
    model = json.loads((run / "model.json").read_text())
    model["interrupted"] = True
    (run / "model.json").write_text(json.dumps(model))
    capsys.readouterr()
    assert main(["score", str(run), "--data", str(flight_csv)]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "interrupted" in err[0]


def test_older_dataflash_timestamps_in_milliseconds():
    """2015-era DataFlash logs stamp messages TimeMS; neither stamp is one line naming it."""
    from gpquad.data.ardupilot import seconds
    from gpquad.errors import GpquadError

    assert np.allclose(seconds({"TimeMS": [1000, 1040]}, "ATT", "x.bin"), [1.0, 1.04])
    assert np.allclose(seconds({"TimeUS": [1_000_000]}, "ATT", "x.bin"), [1.0])
    with pytest.raises(GpquadError, match="neither TimeUS nor TimeMS") as info:
        seconds({"Roll": [0.0]}, "ATT", "x.bin")
    assert "x.bin" in str(info.value) and "ATT" in str(info.value)


def test_sweep_with_an_unreachable_dask_scheduler(tmp_path, capsys, monkeypatch):
    pytest.importorskip("dask.distributed")
    from gpquad.study import sweep

    monkeypatch.setattr(sweep, "SCHEDULER_TIMEOUT_S", 1)
    (tmp_path / "c.toml").write_text(QUICK)
    line = one_error_line(
        capsys,
        [
            "sweep",
            tmp_path / "c.toml",
            "--backend",
            "dask",
            "--address",
            "tcp://127.0.0.1:1",
            "--out",
            tmp_path / "s",
            "--quiet",
        ],
    )
    assert "--address" in line and "no Dask scheduler" in line


def test_a_full_disk_is_one_line(tmp_path, capsys, monkeypatch):
    import errno

    from gpquad.models import equations

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(equations.DiscoveredModel, "load", full)
    line = one_error_line(capsys, ["export", gp_folder(tmp_path)])
    assert "no space left" in line


def test_an_error_quoting_a_line_break_stays_one_line(tmp_path, capsys):
    (tmp_path / "c.toml").write_text(QUICK + '[simulator.equations]\np_dot = "p\\n+ q$"\n')
    line = one_error_line(capsys, ["simulate", tmp_path / "c.toml", "--out", tmp_path / "f.csv"])
    assert "simulator.equations.p_dot" in line
