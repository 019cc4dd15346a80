"""`gpquad run` leaves the process without the interpreter's teardown, and leaves nothing behind:
its exit code, its files, no temporary folder of the worker processes, no leak warning."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

TINY = """
name = "exit"
seed = 3
[data]
trim = "mean"
[simulator]
duration_s = 60.0
[evolution]
targets = ["a_z", "p_dot"]
iterations = 1
model_generations = 20
input_taps = 1
"""


def _joblib_folders(pid: int) -> list[str]:
    shm = Path("/dev/shm")
    if not shm.is_dir():
        return []
    return [p.name for p in shm.iterdir() if p.name.startswith(f"joblib_memmapping_folder_{pid}_")]


@pytest.mark.skipif(sys.platform != "linux", reason="joblib's folders are in /dev/shm on Linux")
def test_run_in_two_processes_exits_clean(tmp_path):
    config = tmp_path / "exit.toml"
    config.write_text(TINY)
    root = str(Path(__file__).resolve().parents[1])
    env = {**os.environ, "PYTHONPATH": root + os.pathsep + os.environ.get("PYTHONPATH", "")}
    cmd = [sys.executable, "-m", "gpquad", "run", str(config), "--jobs", "2", "--no-figures"]
    proc = subprocess.Popen(
        [*cmd, "--out", str(tmp_path / "run"), "--quiet"],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    out, err = proc.communicate(timeout=600)
    assert proc.returncode == 0, err
    assert "leaked" not in err and "Traceback" not in err, err
    assert "p_dot =" in out
    assert (tmp_path / "run" / "model.json").is_file()
    assert _joblib_folders(proc.pid) == []


def test_exit_code_of_a_user_mistake_survives_the_fast_exit(tmp_path):
    """The fast exit keeps main()'s code: 2 for a bad config, with its one line."""
    config = tmp_path / "bad.toml"
    config.write_text("[evolution]\niterations = -1\n")
    root = str(Path(__file__).resolve().parents[1])
    env = {**os.environ, "PYTHONPATH": root + os.pathsep + os.environ.get("PYTHONPATH", "")}
    proc = subprocess.run(
        [sys.executable, "-m", "gpquad", "run", str(config), "--out", str(tmp_path / "r")],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 2
    assert "iterations" in proc.stderr and "Traceback" not in proc.stderr


@pytest.mark.parametrize("jobs", ["1", "2"])
def test_figures_drawn_by_a_worker_or_the_run_are_the_same_files(tmp_path, jobs):
    """After a search in worker processes or in the run's own, both figures are written
    and listed, and they are the bytes make_run_report draws from the run folder
    afterwards (the run passes it the data it has loaded)."""
    config = tmp_path / "exit.toml"
    config.write_text(TINY)
    root = str(Path(__file__).resolve().parents[1])
    env = {**os.environ, "PYTHONPATH": root + os.pathsep + os.environ.get("PYTHONPATH", "")}
    run = tmp_path / "run"
    cmd = [sys.executable, "-m", "gpquad", "run", str(config), "--jobs", jobs, "--out", str(run)]
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    figures = [run / "report" / "convergence.png", run / "report" / "prediction.png"]
    assert all(f.stat().st_size > 1000 for f in figures)
    assert f"Figures: {figures[0]}, {figures[1]}" in proc.stdout
    from gpquad.report.builder import make_run_report

    again = tmp_path / "again"
    shutil.copytree(run, again, ignore=shutil.ignore_patterns("report"))
    redrawn = make_run_report(again, formats=("png",))
    assert [f.name for f in redrawn] == [f.name for f in figures]
    assert [f.read_bytes() for f in redrawn] == [f.read_bytes() for f in figures]


def test_bad_data_after_the_workers_started_exits_with_its_line(tmp_path):
    """The workers start before the data loads; a missing file still ends the run with its
    one line and code 2 (the workers are stopped, not waited for)."""
    config = tmp_path / "bad.toml"
    config.write_text('name = "bad"\n[data]\nfiles = ["missing.ulg"]\n')
    root = str(Path(__file__).resolve().parents[1])
    env = {**os.environ, "PYTHONPATH": root + os.pathsep + os.environ.get("PYTHONPATH", "")}
    cmd = [sys.executable, "-m", "gpquad", "run", str(config), "--jobs", "2"]
    proc = subprocess.run(
        [*cmd, "--out", str(tmp_path / "r")], env=env, capture_output=True, text=True, timeout=300
    )
    assert proc.returncode == 2
    assert "missing.ulg" in proc.stderr and "Traceback" not in proc.stderr
