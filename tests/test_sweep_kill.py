"""A sweep killed with SIGKILL mid-run and run again equals an uninterrupted sweep."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from test_sweep import result_files

from gpquad.study.checkpoint import load
from gpquad.study.sweep_folders import grid, run_dir

#: Long enough per run (about 1 s) that the kill lands inside the grid.
KILL_TOML = """
name = "kill"
seed = 9
preset = "paper"
[data]
trim = "mean"
validation_fraction = 0.3
[simulator]
duration_s = 60.0
[evolution]
targets = ["a_z", "p_dot"]
iterations = 6
model_generations = 60
test_generations = 5
simplify_generations = 5
window_s = 2.4
[sweep]
runs = 2
full_models = 3
horizons_s = [1.0, 3.0]
"""


def _sweep_cmd(config: Path, out: Path, jobs: int) -> list[str]:
    return [
        sys.executable,
        "-m",
        "gpquad",
        "sweep",
        str(config),
        "--jobs",
        str(jobs),
        "--out",
        str(out),
        "--quiet",
    ]


def _env():
    root = str(Path(__file__).resolve().parents[1])
    return {**os.environ, "PYTHONPATH": root + os.pathsep + os.environ.get("PYTHONPATH", "")}


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """Config file and an uninterrupted sweep of it (one job)."""
    root = tmp_path_factory.mktemp("kill")
    config = root / "kill.toml"
    config.write_text(KILL_TOML)
    done = subprocess.run(
        _sweep_cmd(config, root / "ref", 1), env=_env(), capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr
    return config, root / "ref"


@pytest.mark.parametrize("victim", ["group", "parent"])
def test_sigkill_then_resume_equals_uninterrupted(reference, tmp_path, victim):
    """victim 'group': the sweep and its workers die; 'parent': only the sweep process dies,
    its loky workers are orphaned (they stop at their next checkpoint, and the run-folder
    lock keeps them from writing alongside the resumed sweep)."""
    config, ref = reference
    jobs = 2
    out = tmp_path / "killed"
    proc = subprocess.Popen(
        _sweep_cmd(config, out, jobs),
        env=_env(),
        start_new_session=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    keys = None
    deadline = time.time() + 240
    try:
        while time.time() < deadline:  # kill once some run has checkpointed an iteration
            if keys is None and (out / "config.json").exists():
                from gpquad.study.assemble import load_sweep_config

                keys = grid(load_sweep_config(out))
            if keys and any((run_dir(out, k) / "checkpoint.bin").exists() for k in keys):
                break
            time.sleep(0.01)
        else:
            pytest.fail("no checkpoint appeared")
    finally:
        if victim == "group":
            os.killpg(proc.pid, signal.SIGKILL)
        else:
            os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    try:
        finished = [k for k in keys if (run_dir(out, k) / "result.json").exists()]
        partial = [
            k for k in keys if (run_dir(out, k) / "checkpoint.bin").exists() and k not in finished
        ]
        assert len(finished) < len(keys) and partial, "the kill did not land mid-sweep"
        assert not (out / "model.json").exists()
        for k in partial:  # a checkpoint that survived the kill is valid and mid-run
            state, _ = load(run_dir(out, k) / "checkpoint.bin")
            assert 1 <= state.iteration <= 6

        again = subprocess.run(
            _sweep_cmd(config, out, jobs), env=_env(), capture_output=True, text=True, timeout=300
        )
        assert again.returncode == 0, again.stderr
    finally:
        try:  # orphaned workers, if any are left
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    ours, theirs = result_files(out), result_files(ref)
    assert ours.keys() == theirs.keys()
    for name in theirs:
        assert ours[name] == theirs[name], name
    model = json.loads((out / "model.json").read_text())
    assert set(model["targets"]) == {"a_z", "p_dot"}
