"""Files: run names are file names, nothing is written through a link or outside the folder
a file names, a run folder is locked and never taken over from a user or a sweep, and a
resume checks what it reads before it cuts or writes history.csv."""

from __future__ import annotations

import fcntl
import json
import os
import shutil

import pytest
from test_hostile_inputs import QUICK
from test_trust_code import gp_folder, one_error_line

from gpquad.cli.commands import main
from gpquad.study import checkpoint


def listing(folder) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*")}


@pytest.mark.parametrize(
    "name",
    [
        "../../..",
        "..",
        "a/../../b",
        "/tmp/gpquad-trust-abs",
        "x/y",
        "",
        ".hidden",
        "a\\u0000b",
        "n" * 101,
    ],
)
@pytest.mark.parametrize("command", ["run", "sweep"])
def test_run_name_is_a_file_name(tmp_path, capsys, monkeypatch, name, command):
    work = tmp_path / "a" / "b" / "work"
    work.mkdir(parents=True)
    monkeypatch.chdir(work)
    (work / "c.toml").write_text(f'name = "{name}"\n' + QUICK)
    before = listing(tmp_path)
    line = one_error_line(capsys, [command, work / "c.toml", "--quiet"])
    assert "field 'name'" in line and "not a run name" in line
    assert listing(tmp_path) == before
    assert not os.path.exists("/tmp/gpquad-trust-abs-seed0")


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("finished")
    (folder / "c.toml").write_text(QUICK)
    assert main(["run", str(folder / "c.toml"), "--out", str(folder / "run"), "--quiet"]) == 0
    return folder


def copy_of(finished_run, tmp_path):
    run = tmp_path / "run"
    shutil.copytree(finished_run / "run", run)
    return run


@pytest.mark.parametrize("link", ["history.csv", "model.json", "checkpoints"])
def test_run_files_that_are_links_are_refused(finished_run, tmp_path, capsys, link):
    run = copy_of(finished_run, tmp_path)
    victim = tmp_path / "victim"
    if link == "checkpoints":
        victim.mkdir()
        (victim / "mine.txt").write_text("mine\n")
        shutil.rmtree(run / link)
    else:
        victim.write_text("the user's file\n")
        (run / link).unlink()
    (run / link).symlink_to(victim)
    before = listing(victim) if victim.is_dir() else victim.read_bytes()
    line = one_error_line(capsys, ["run", finished_run / "c.toml", "--out", run, "--quiet"])
    assert link in line and "link" in line
    assert (listing(victim) if victim.is_dir() else victim.read_bytes()) == before


def test_a_checkpoint_that_is_a_link_is_not_read_nor_written_through(
    finished_run, tmp_path, capsys
):
    run = copy_of(finished_run, tmp_path)
    victim = tmp_path / "victim"
    shutil.copy(run / "checkpoints" / "p_dot.ckpt", victim)
    (run / "checkpoints" / "p_dot.json").unlink()
    (run / "checkpoints" / "p_dot.ckpt").unlink()
    (run / "checkpoints" / "p_dot.ckpt").symlink_to(victim)
    before = victim.read_bytes()
    capsys.readouterr()
    assert main(["run", str(finished_run / "c.toml"), "--out", str(run), "--quiet"]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not a regular file" in err[0] and "restarting p_dot" in err[0]
    assert victim.read_bytes() == before


@pytest.mark.parametrize(
    "files",
    [
        ["../secret.csv"],
        ["sub/../../secret.csv"],
        "absolute",
        ["flights/../../secret.csv"],
        "link",
        [],
        "text",
    ],
)
def test_scoring_data_stays_inside_the_run_folder(tmp_path, capsys, files):
    run = gp_folder(tmp_path)
    secret = tmp_path / "secret.csv"
    secret.write_text("t,u_P\n0,0\n")
    if files == "absolute":
        files = [str(secret)]
    elif files == "link":
        (run / "inside.csv").symlink_to(secret)
        files = ["inside.csv"]
    elif files == "text":
        files = "flight.csv"
    info = json.loads((run / "run.json").read_text())
    info["scoring_data"] = {
        "files": files,
        "inputs": ["u_P", "u_R", "u_Y", "u_T"],
        "validation_fraction": 0.5,
    }
    (run / "run.json").write_text(json.dumps(info))
    line = one_error_line(capsys, ["compare", run, "--out", tmp_path / "cmp"])
    assert "run.json" in line and "scoring_data.files" in line


# ---------------------------------------------------------------- data that can be lost
def test_a_locked_run_folder_is_refused(finished_run, tmp_path, capsys):
    """A second command on a folder another process is writing (its .lock held) stops."""
    run = copy_of(finished_run, tmp_path)
    history = (run / "history.csv").read_bytes()
    fd = os.open(run / ".lock", os.O_WRONLY | os.O_CREAT)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        line = one_error_line(capsys, ["run", finished_run / "c.toml", "--out", run, "--quiet"])
    finally:
        os.close(fd)
    assert "another gpquad command is writing" in line
    assert (run / "history.csv").read_bytes() == history


def test_a_folder_of_user_files_is_refused(tmp_path, capsys):
    (tmp_path / "c.toml").write_text(QUICK)
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "model.json").write_text('{"mine": 1}\n')
    (mine / "equations.tex").write_text("my thesis\n")
    before = {p.name: p.read_bytes() for p in mine.iterdir()}
    line = one_error_line(capsys, ["run", tmp_path / "c.toml", "--out", mine, "--quiet"])
    assert "not a gpquad run" in line and "--out" in line
    assert {p.name: p.read_bytes() for p in mine.iterdir()} == before


def test_a_sweep_folder_is_not_taken_for_a_run(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "c.toml").write_text(QUICK)
    assert (
        main(
            [
                "sweep",
                str(tmp_path / "c.toml"),
                "--runs",
                "1",
                "--out",
                str(tmp_path / "s"),
                "--quiet",
                "--no-assemble",
            ]
        )
        == 0
    )
    (tmp_path / "s" / "model.json").write_text('{"the sweep best": 1}\n')
    before = listing(tmp_path / "s")
    line = one_error_line(capsys, ["run", tmp_path / "c.toml", "--out", tmp_path / "s", "--quiet"])
    assert "sweep folder" in line
    assert listing(tmp_path / "s") == before
    assert (tmp_path / "s" / "model.json").read_text() == '{"the sweep best": 1}\n'


@pytest.mark.parametrize("value", [100_000_000, -5, "12", 1.5, None])
@pytest.mark.parametrize("record", ["finished", "checkpoint"])
def test_resume_checks_history_bytes_before_cutting(finished_run, tmp_path, capsys, value, record):
    """A damaged history_bytes (the finished record's or the checkpoint's) restarts the
    target with one warning; history.csv never grows past what was written."""
    run = copy_of(finished_run, tmp_path)
    done = run / "checkpoints" / "p_dot.json"
    if record == "finished":
        saved = json.loads(done.read_text())
        saved["history_bytes"] = value
        done.write_text(json.dumps(saved))
    else:
        done.unlink()
        state, meta = checkpoint.load(run / "checkpoints" / "p_dot.ckpt")
        checkpoint.save(run / "checkpoints" / "p_dot.ckpt", state, {"history_bytes": value})
    capsys.readouterr()
    assert main(["run", str(finished_run / "c.toml"), "--out", str(run), "--quiet"]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "warning" in err[0] and "p_dot" in err[0], err
    assert ("damaged record" if record == "finished" else "records a history") in err[0]
    size = (run / "history.csv").stat().st_size
    assert size <= 2 * (finished_run / "run" / "history.csv").stat().st_size
    assert b"\0" not in (run / "history.csv").read_bytes()


def test_a_valid_checkpoint_resumes_without_a_word(finished_run, tmp_path, capsys):
    """The checks accept the checkpoints gpquad writes (the fitting case of the above)."""
    run = copy_of(finished_run, tmp_path)
    (run / "checkpoints" / "p_dot.json").unlink()
    capsys.readouterr()
    assert main(["run", str(finished_run / "c.toml"), "--out", str(run), "--quiet"]) == 0
    assert capsys.readouterr().err == ""
    assert (run / "model.json").read_bytes() == (finished_run / "run" / "model.json").read_bytes()


def _forge(state_dict: dict, change) -> bytes:
    import copy
    import hashlib
    import struct

    fields = copy.deepcopy(state_dict)
    change(fields)
    payload = json.dumps({"state": fields, "meta": {"history_bytes": 0}}).encode()
    return (
        struct.pack("<8sQ32s", checkpoint.MAGIC, len(payload), hashlib.sha256(payload).digest())
        + payload
    )


FORGERIES = {
    "object-dtype": lambda f: f["model_errors"].update(dtype="object"),
    "string-values": lambda f: f["suite"].update(data=["x"] * len(f["suite"]["data"])),
    "bad-shape": lambda f: f["tests"].update(shape=[999]),
    "incomplete-tree": lambda f: f["models"][0].update(codes=[0]),
    "negative-code": lambda f: f["models"][0].update(codes=[-1], values=[0.0]),
    "bit-generator-not-a-class": lambda f: f["rng_state"].update(bit_generator="default_rng"),
    "bit-generator-unknown": lambda f: f["rng_state"].update(bit_generator="os"),
    "rng-state-nested-deep": lambda f: f["rng_state"].update(state={"a": {"b": {"c": {}}}}),
    "extra-field": lambda f: f.update(payload="__import__('os')"),
    "missing-field": lambda f: f.pop("suite"),
    "population-mismatch": lambda f: f["model_errors"].update(shape=[1], data=[0.0]),
}


@pytest.mark.parametrize("case", sorted(FORGERIES))
def test_a_forged_data_checkpoint_is_refused(finished_run, tmp_path, case):
    """A checkpoint is data: anything but the numbers, names and trees of a RunState is
    refused as damaged (and the run restarts that target)."""
    state, _ = checkpoint.load(finished_run / "run" / "checkpoints" / "p_dot.ckpt")
    (tmp_path / "c.ckpt").write_bytes(_forge(checkpoint.state_to_dict(state), FORGERIES[case]))
    with pytest.raises(checkpoint.CorruptCheckpoint):
        checkpoint.load(tmp_path / "c.ckpt")


def test_the_forger_unchanged_writes_a_readable_checkpoint(finished_run, tmp_path):
    """The forgeries above differ from a good checkpoint only by their change."""
    state, _ = checkpoint.load(finished_run / "run" / "checkpoints" / "p_dot.ckpt")
    (tmp_path / "c.ckpt").write_bytes(_forge(checkpoint.state_to_dict(state), lambda f: None))
    loaded, meta = checkpoint.load(tmp_path / "c.ckpt")
    assert meta == {"history_bytes": 0} and loaded.iteration == state.iteration
