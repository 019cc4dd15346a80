"""Hostile-input table: every class of user mistake ends in ONE line naming the file and the
field, with exit code 2 (never a traceback), before any long work.

Each case builds its bad input in a temporary folder, runs the command line in-process and
checks the exit code and that stderr is one `gpquad: error:` line holding the expected words.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from gpquad.cli.commands import main
from gpquad.engine.tree.export import from_sympy, parse_equation
from gpquad.models.equations import DiscoveredModel, Equation
from gpquad.study.config import MEDIAN_MODEL
from gpquad.study.store import write_json

INPUTS = ("u_P", "u_R", "u_Y", "u_T")
QUICK = (
    'preset = "paper"\n[evolution]\ntargets = ["p_dot"]\niterations = 1\n'
    "model_generations = 2\n"
    "test_generations = 2\nwindow_s = 2.4\n"
    "simplify_generations = 2\n[simulator]\nduration_s = 40.0\n"
)


def write_run(folder: Path, targets=tuple(MEDIAN_MODEL)) -> Path:
    """A run folder whose model.json holds the median model's true equations."""
    eqs = {}
    for target in targets:
        expr, delays = parse_equation(MEDIAN_MODEL[target], INPUTS)
        eqs[target] = Equation(target, from_sympy(expr, delays, INPUTS), INPUTS, 0.0, 0.0, {})
    write_json(folder / "model.json", DiscoveredModel(eqs, INPUTS, {}, 0.04, 0, {}).to_dict())
    return folder


def write_inputs(path: Path, dt: float = 0.04, n: int = 50) -> Path:
    rows = ["t,u_P,u_R,u_Y,u_T"] + [f"{k * dt},0,0,0,0" for k in range(n)]
    path.write_text("\n".join(rows) + "\n")
    return path


def case_missing_model(tmp):
    (tmp / "run").mkdir()
    return ["export", str(tmp / "run")], ["model.json", "run"]


def case_truncated_model(tmp):
    write_run(tmp / "run")
    text = (tmp / "run" / "model.json").read_text()
    (tmp / "run" / "model.json").write_text(text[:100])
    return ["export", str(tmp / "run")], ["model.json", "damaged"]


def case_model_not_a_model(tmp):
    (tmp / "run").mkdir()
    (tmp / "run" / "model.json").write_text('{"targets": 3}')
    return [
        "fly",
        str(tmp / "run"),
        "--inputs",
        str(write_inputs(tmp / "in.csv")),
        "--out",
        str(tmp / "o.csv"),
    ], ["model.json", "not a gpquad model"]


def case_fly_missing_equation(tmp):
    write_run(tmp / "run", targets=("p_dot",))
    return [
        "fly",
        str(tmp / "run"),
        "--inputs",
        str(write_inputs(tmp / "in.csv")),
        "--out",
        str(tmp / "o.csv"),
    ], ["no equation", "--zero-missing"]


def case_fly_wrong_clock(tmp):
    write_run(tmp / "run")
    return [
        "fly",
        str(tmp / "run"),
        "--inputs",
        str(write_inputs(tmp / "in.csv", dt=0.01)),
        "--out",
        str(tmp / "o.csv"),
    ], ["field 't'", "0.04"]


def case_fly_out_suffix(tmp):
    write_run(tmp / "run")
    return [
        "fly",
        str(tmp / "run"),
        "--inputs",
        str(write_inputs(tmp / "in.csv")),
        "--out",
        str(tmp / "o.txt"),
    ], ["--out", ".csv or .parquet"]


def case_out_under_a_file(tmp):
    (tmp / "afile").write_text("x")
    return ["simulate", "--out", str(tmp / "afile" / "x.csv")], ["afile", "writable folder"]


def case_negative_seed(tmp):
    (tmp / "c.toml").write_text(QUICK)
    return ["run", str(tmp / "c.toml"), "--seed", "-3", "--out", str(tmp / "r")], ["'seed'"]


def case_duplicate_target(tmp):
    (tmp / "c.toml").write_text(QUICK)
    return [
        "run",
        str(tmp / "c.toml"),
        "--target",
        "p_dot",
        "--target",
        "p_dot",
        "--out",
        str(tmp / "r"),
    ], ["evolution.targets", "twice"]


def case_duplicate_data(tmp):
    (tmp / "c.toml").write_text(QUICK)
    assert main(["simulate", str(tmp / "c.toml"), "--out", str(tmp / "f.csv")]) == 0
    return [
        "run",
        str(tmp / "c.toml"),
        "--data",
        str(tmp / "f.csv"),
        "--data",
        str(tmp / "f.csv"),
        "--out",
        str(tmp / "r"),
    ], ["data.files", "twice"]


def case_empty_files(tmp):
    (tmp / "c.toml").write_text("[data]\nfiles = []\n")
    return ["run", str(tmp / "c.toml")], ["data.files", "c.toml"]


@pytest.mark.parametrize("name", ["E", "I", "N", "S", "pi", "lambda", "beta"])
def test_sympy_names_are_refused_as_inputs(tmp_path, capsys, name):
    (tmp_path / "c.toml").write_text(f'[data]\ninputs = ["{name}", "u_R", "u_Y", "u_T"]\n')
    assert main(["run", str(tmp_path / "c.toml")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "data.inputs" in err[0] and f"'{name}'" in err[0]


def case_function_in_truth(tmp):
    (tmp / "c.toml").write_text('[simulator.equations]\np_dot = "sin(p) - u_R"\n')
    return ["simulate", str(tmp / "c.toml"), "--out", str(tmp / "f.csv")], [
        "simulator.equations.p_dot",
        "no functions",
    ]


def case_exp_in_truth(tmp):
    (tmp / "c.toml").write_text('[simulator.equations]\na_z = "exp(u_T)"\n')
    return ["simulate", str(tmp / "c.toml"), "--out", str(tmp / "f.csv")], [
        "simulator.equations.a_z",
        "no functions",
    ]


def case_too_short_simulation(tmp):
    (tmp / "c.toml").write_text("[simulator]\nduration_s = 0.01\n")
    return ["simulate", str(tmp / "c.toml"), "--out", str(tmp / "f.csv")], [
        "simulator.duration_s",
        "c.toml",
    ]


def case_corrupt_config_json(tmp):
    (tmp / "c.toml").write_text(QUICK)
    (tmp / "r").mkdir()
    (tmp / "r" / "config.json").write_text("garbage")
    return ["run", str(tmp / "c.toml"), "--out", str(tmp / "r"), "--quiet"], [
        "config.json",
        "damaged",
    ]


def case_compare_of_damaged_run_json(tmp):
    write_run(tmp / "run")
    (tmp / "run" / "run.json").write_text("{")
    return ["compare", str(tmp / "run"), "--out", str(tmp / "cmp")], ["run.json", "damaged"]


def case_table_time_in_microseconds(tmp):
    (tmp / "c.toml").write_text(QUICK)
    assert main(["simulate", str(tmp / "c.toml"), "--out", str(tmp / "f.csv")]) == 0
    text = (tmp / "f.csv").read_text().splitlines()
    rows = [text[0]] + [
        ",".join([repr(float(r.split(",")[0]) * 1e6)] + r.split(",")[1:]) for r in text[1:]
    ]
    (tmp / "us.csv").write_text("\n".join(rows) + "\n")
    return ["data", "check", str(tmp / "us.csv"), "--format", "table"], [
        "us.csv",
        "field 't'",
        "microseconds",
    ]


def case_px4_topic_with_only_a_header(tmp):
    from px4_reset_edit import SHARED_S250, make_yaw_reset_log

    if not SHARED_S250.is_dir():
        pytest.skip("../shared/data is not present")
    log = make_yaw_reset_log(tmp / "px4")
    att = log / "log1_vehicle_attitude_0.csv"
    att.write_text(att.read_text().splitlines()[0] + "\n")
    return ["data", "check", str(log)], ["vehicle_attitude", "no rows"]


def case_pem_unseen_as_short_as_its_windows(tmp):
    text = (Path(__file__).parents[1] / "experiments" / "baseline_pem.toml").read_text()
    text = text.replace("unseen_s = [120.0, 120.0]", "unseen_s = [10.0, 10.0]")
    assert "unseen_s = [10.0, 10.0]" in text
    (tmp / "pem.toml").write_text(text)
    return ["baseline", "pem", str(tmp / "pem.toml"), "--out", str(tmp / "o")], [
        "simulator.unseen_s",
        "pem.toml",
    ]


CASES = [v for k, v in sorted(globals().items()) if k.startswith("case_")]


@pytest.mark.parametrize("case", CASES, ids=[c.__name__[5:] for c in CASES])
def test_one_line_and_exit_2(case, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    argv, words = case(tmp_path)
    capsys.readouterr()
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith("gpquad: error: ")
    for word in words:
        assert word in err[0], (word, err[0])


def test_a_damaged_finished_record_is_identified_again(tmp_path, capsys):
    """A corrupt checkpoints/<target>.json warns and re-identifies that target."""
    (tmp_path / "c.toml").write_text(QUICK)
    run = tmp_path / "r"
    assert main(["run", str(tmp_path / "c.toml"), "--out", str(run), "--quiet"]) == 0
    first = (run / "model.json").read_bytes()
    (run / "checkpoints" / "p_dot.json").write_text("{not json")
    capsys.readouterr()
    assert main(["run", str(tmp_path / "c.toml"), "--out", str(run), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "damaged record" in err and "identifying p_dot again" in err
    assert (run / "model.json").read_bytes() == first


def test_closed_pipe_is_quiet(tmp_path):
    """`gpquad export RUN | head -1`: no traceback when the reader stops early."""
    write_run(tmp_path / "run")
    proc = subprocess.run(
        f"{sys.executable} -m gpquad export {tmp_path / 'run'} --format json | head -c 10",
        shell=True,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert (
        proc.stdout
        == json.dumps(json.loads((tmp_path / "run" / "model.json").read_text()), indent=2)[:10]
    )
    assert "Traceback" not in proc.stderr and proc.stderr == ""
