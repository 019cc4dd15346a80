"""No code runs from a file a user was sent: every payload, in every field that holds an
expression or a checkpoint, under every command that reads it, creates no file and ends in
one `gpquad: error:` line with exit 2 (or, for a resumable record, one warning line and a
clean restart).

Each payload would create the file MARKER in tmp_path if it were evaluated as Python.
"""

from __future__ import annotations

import hashlib
import json
import os
import pickle
import shutil
import struct

import pytest
from test_hostile_inputs import QUICK, write_inputs, write_run

from gpquad.cli.commands import main
from gpquad.study import checkpoint
from gpquad.study.config import config_from_dict, folder_config_dict


def payloads(marker) -> dict[str, str]:
    """The issue's payloads, each creating `marker` if evaluated."""
    return {
        "import": f"__import__('os').system('touch {marker}')",
        "globals": (
            "0*Integer.__new__.__globals__['__builtins__']['__import__']('os')"
            f".system('touch {marker}')"
        ),
        "lambda": f"(lambda: open('{marker}', 'w'))()",
    }


PAYLOADS = sorted(payloads("m"))


def one_error_line(capsys, argv) -> str:
    capsys.readouterr()
    assert main([str(a) for a in argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("gpquad: error: "), err
    return err[0]


def gp_folder(tmp_path, equation: str | None = None, where: str = "config.json"):
    """A run folder (model.json of the true equations, run.json, config.json) whose
    config.json or run.json holds `equation` as the simulator's p_dot."""
    run = write_run(tmp_path / "run")
    cfg = config_from_dict({}, "test")
    table = folder_config_dict(cfg)
    info = {"seed": 0, "config": cfg.to_dict()}
    if equation is not None:
        target = table if where == "config.json" else info["config"]
        target["simulator"]["equations"]["p_dot"] = equation
    (run / "config.json").write_text(json.dumps(table))
    (run / "run.json").write_text(json.dumps(info))
    rows = [f"{t},0,0,1.0,1.0,3" for t in ("a_x", "a_y", "a_z", "p_dot", "q_dot", "r_dot")]
    (run / "history.csv").write_text(
        "target,iteration,generation,best_suite_error,"
        "median_suite_error,best_size\n" + "\n".join(rows) + "\n"
    )
    return run


@pytest.mark.parametrize("payload", PAYLOADS)
@pytest.mark.parametrize("command", ["simulate", "run", "sweep"])
def test_simulator_equation_in_a_config(tmp_path, capsys, monkeypatch, payload, command):
    monkeypatch.chdir(tmp_path)
    marker = tmp_path / "MARKER"
    text = QUICK + f'[simulator.equations]\np_dot = "{payloads(marker)[payload]}"\n'
    (tmp_path / "c.toml").write_text(text)
    argv = {
        "simulate": ["simulate", tmp_path / "c.toml", "--out", tmp_path / "f.csv"],
        "run": ["run", tmp_path / "c.toml", "--out", tmp_path / "r", "--quiet"],
        "sweep": ["sweep", tmp_path / "c.toml", "--out", tmp_path / "s", "--quiet"],
    }[command]
    line = one_error_line(capsys, argv)
    assert "simulator.equations.p_dot" in line and "cannot parse" in line
    assert not marker.exists()


@pytest.mark.parametrize("payload", PAYLOADS)
@pytest.mark.parametrize(
    "where,command",
    [("run.json", "compare"), ("config.json", "control"), ("config.json", "report")],
)
def test_simulator_equation_in_a_run_folder(tmp_path, capsys, monkeypatch, payload, where, command):
    monkeypatch.chdir(tmp_path)
    marker = tmp_path / "MARKER"
    run = gp_folder(tmp_path, payloads(marker)[payload], where)
    argv = {
        "compare": ["compare", run, "--out", tmp_path / "cmp"],
        "control": ["control", "pid", run, "--out", tmp_path / "pid", "--no-figures", "--json"],
        "report": ["report", run, "--format", "png"],
    }[command]
    line = one_error_line(capsys, argv)
    assert "simulator.equations.p_dot" in line and "cannot parse" in line
    assert not marker.exists()


@pytest.mark.parametrize("payload", PAYLOADS)
@pytest.mark.parametrize("field", ["expr", "candidates"])
@pytest.mark.parametrize("command", ["export", "fly", "score"])
def test_expression_in_model_json(tmp_path, capsys, monkeypatch, payload, field, command):
    monkeypatch.chdir(tmp_path)
    marker = tmp_path / "MARKER"
    run = gp_folder(tmp_path)
    model = json.loads((run / "model.json").read_text())
    text = payloads(marker)[payload]
    if field == "expr":
        model["targets"]["p_dot"]["expr"] = text
    else:
        model["targets"]["p_dot"]["candidates"] = [{"expr": text, "delays": {}, "error": 0.1}]
    (run / "model.json").write_text(json.dumps(model))
    if command == "score":
        assert main(["simulate", "--out", str(tmp_path / "f.csv")]) == 0
    argv = {
        "export": ["export", run, "--format", "sympy"],
        "fly": [
            "fly",
            run,
            "--inputs",
            write_inputs(tmp_path / "in.csv"),
            "--out",
            tmp_path / "o.csv",
        ],
        "score": ["score", run, "--data", tmp_path / "f.csv"],
    }[command]
    line = one_error_line(capsys, argv)
    assert f"targets.p_dot.{field}" in line and "model.json" in line and "cannot parse" in line
    assert not marker.exists()


# ---------------------------------------------------------------- resumed records
@pytest.fixture(scope="module")
def finished_run(tmp_path_factory):
    """A finished one-target run (p_dot) of QUICK and its config."""
    folder = tmp_path_factory.mktemp("finished")
    (folder / "c.toml").write_text(QUICK)
    assert main(["run", str(folder / "c.toml"), "--out", str(folder / "run"), "--quiet"]) == 0
    return folder


def pickled_checkpoint(marker) -> bytes:
    """A checkpoint of the old pickled layout whose payload creates `marker`."""

    class Payload:
        def __reduce__(self):
            return (os.system, (f"touch {marker}",))

    blob = pickle.dumps({"state": Payload(), "meta": {"history_bytes": 0}})
    return struct.pack("<8sQ32s", b"GPQCKPT1", len(blob), hashlib.sha256(blob).digest()) + blob


@pytest.mark.parametrize("record", ["candidates-import", "candidates-globals", "pickle"])
def test_resumed_run_runs_no_code(finished_run, tmp_path, capsys, record):
    """A run folder's records: a finished target's candidates (checkpoints/<t>.json) and a
    checkpoint of the old pickled layout (checkpoints/<t>.ckpt). Each is refused with one
    warning line naming it and the target is identified again."""
    marker = tmp_path / "MARKER"
    run = tmp_path / "run"
    shutil.copytree(finished_run / "run", run)
    done = run / "checkpoints" / "p_dot.json"
    if record == "pickle":
        done.unlink()
        (run / "checkpoints" / "p_dot.ckpt").write_bytes(pickled_checkpoint(marker))
    else:
        saved = json.loads(done.read_text())
        text = payloads(marker)[record.split("-")[1]]
        saved["equation"]["candidates"] = [{"expr": text, "delays": {}, "error": 0.1}]
        done.write_text(json.dumps(saved))
    capsys.readouterr()
    assert main(["run", str(finished_run / "c.toml"), "--out", str(run), "--quiet"]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "warning" in err[0] and "p_dot" in err[0], err
    assert ("pickled" in err[0]) if record == "pickle" else ("damaged record" in err[0])
    assert not marker.exists()


def test_pickled_checkpoint_is_refused_unread(tmp_path, monkeypatch):
    """checkpoint.load never unpickles: the payload's call is not made."""
    calls = []
    monkeypatch.setattr(pickle, "loads", lambda *a, **k: calls.append(a))
    (tmp_path / "c.ckpt").write_bytes(pickled_checkpoint(tmp_path / "MARKER"))
    with pytest.raises(checkpoint.CorruptCheckpoint, match="pickled"):
        checkpoint.load(tmp_path / "c.ckpt")
    assert not calls and not (tmp_path / "MARKER").exists()


def test_sweep_result_candidates_run_no_code(tmp_path, capsys, monkeypatch):
    """A sweep's result.json with a payload candidate: the assembly refuses it in one line."""
    monkeypatch.chdir(tmp_path)
    marker = tmp_path / "MARKER"
    (tmp_path / "c.toml").write_text(QUICK + "[sweep]\nruns = 1\nfull_models = 1\n")
    assert (
        main(
            [
                "sweep",
                str(tmp_path / "c.toml"),
                "--out",
                str(tmp_path / "s"),
                "--quiet",
                "--no-assemble",
            ]
        )
        == 0
    )
    result = tmp_path / "s" / "runs" / "p_dot" / "rep000" / "result.json"
    saved = json.loads(result.read_text())
    saved["equation"]["candidates"] = [{"expr": payloads(marker)["import"], "delays": {}}]
    result.write_text(json.dumps(saved))
    line = one_error_line(capsys, ["report", tmp_path / "s", "--reassemble", "--format", "png"])
    assert "candidates[0].expr" in line and "cannot parse" in line
    assert not marker.exists()
