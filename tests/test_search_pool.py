"""The search's worker pool: forked from a process without other threads (Linux), fresh
interpreters otherwise, the same equations either way, and Ctrl-C that stops every process
of a run at once."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import pytest

from gpquad.study import workers

ROOT = str(Path(__file__).resolve().parents[1])
ENV = {**os.environ, "PYTHONPATH": ROOT + os.pathsep + os.environ.get("PYTHONPATH", "")}

CONFIG = """
name = "pool"
seed = 5
[data]
trim = "mean"
[simulator]
duration_s = 60.0
[evolution]
targets = ["a_z", "p_dot", "q_dot"]
iterations = {iterations}
model_generations = 20
input_taps = 1
{extra}
"""

#: A Python thread started before gpquad: the pool of a notebook's kernel (fresh workers).
WITH_A_THREAD = """
import sys, threading
threading.Thread(target=threading.Event().wait, daemon=True).start()
sys.argv = ["gpquad", *sys.argv[1:]]
from gpquad.cli.commands import entry
entry()
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="workers are forked on Linux")
def test_fork_only_without_other_python_threads():
    assert workers.fork_context() is not None or threading.active_count() > 1
    stop = threading.Event()
    thread = threading.Thread(target=stop.wait)
    thread.start()
    try:
        assert workers.fork_context() is None
    finally:
        stop.set()
        thread.join()


def test_no_fork_off_linux(monkeypatch):
    monkeypatch.setattr(sys, "platform", "darwin")
    assert workers.fork_context() is None


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="workers are forked on Linux")
def test_forked_and_fresh_workers_find_the_same_equations(tmp_path):
    """One clean process runs the same fit with forked workers and with fresh ones."""
    config = tmp_path / "pool.toml"
    config.write_text(CONFIG.format(iterations=1, extra=""))
    script = textwrap.dedent(
        f"""
        import json, sys
        from gpquad.study import workers
        from gpquad.study.config import load_config
        from gpquad.study.runner import run_experiment

        cfg = load_config({str(config)!r})
        found = {{}}
        for arm in ("fork", "fresh"):
            if arm == "fresh":
                workers.fork_context = lambda: None
            model = run_experiment(cfg, None, progress=False, jobs=2)
            kind = type(workers._pool["executor"]).__module__
            workers.release(wait=True)
            found[arm] = {{"pool": kind, "equations": model.text()}}
        print(json.dumps(found))
        """
    )
    proc = subprocess.run(
        [sys.executable, "-c", script], env=ENV, capture_output=True, text=True, timeout=600
    )
    assert proc.returncode == 0, proc.stderr
    found = json.loads(proc.stdout.strip().splitlines()[-1])
    assert found["fork"]["pool"] == "concurrent.futures.process"
    assert "loky" in found["fresh"]["pool"]
    assert found["fork"]["equations"] == found["fresh"]["equations"]
    assert "p_dot =" in found["fork"]["equations"]


def _printed_json(script: str, *args: str) -> dict:
    """The JSON that `script` prints last, run in a clean process with `args`."""
    proc = subprocess.run(
        [sys.executable, "-c", script, *args], env=ENV, capture_output=True, text=True, timeout=300
    )
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


#: Each worker of a fresh pool raises SIGINT in itself; prints the pool's kind and results.
RAISE_SIGINT = """
import json, signal, sys
from gpquad.study import workers

if sys.argv[1] == "fresh":
    workers.fork_context = lambda: None
futures = workers.submit_all(2, signal.raise_signal, [(signal.SIGINT,)] * 2)
try:
    results = [f.result(timeout=120) for f in futures]
except BaseException as exc:  # the worker's KeyboardInterrupt, or a broken pool
    results = repr(exc)
kind = type(workers._pool["executor"]).__module__
workers.release(wait=True, kill=True)
print(json.dumps({"pool": kind, "results": results}))
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="SIGINT; forked on Linux")
@pytest.mark.parametrize("pool", ["forked", "fresh"])
def test_workers_ignore_ctrl_c(pool):
    """A worker that receives SIGINT (Ctrl-C reaches the whole process group) keeps
    running: the run stops it. A worker that died of it mid-message left the run's pool
    hung or its manager thread failing. In a clean process, where a pool is forked."""
    found = _printed_json(RAISE_SIGINT, pool)
    assert found["results"] == [None, None], found
    assert ("loky" in found["pool"]) == (pool == "fresh")


#: Starts a pool and reads, before the warm-up ends, whether its processes ignore SIGINT.
BORN_IGNORING = """
import json, signal, sys
from gpquad.study import workers

if sys.argv[1] == "fresh":
    workers.fork_context = lambda: None
before = signal.getsignal(signal.SIGINT)
workers.start(2)
pids = [p.pid for p in workers._pool["executor"]._processes.values()]
ignored = []
for pid in pids:
    with open(f"/proc/{pid}/status") as fh:
        mask = next(line for line in fh if line.startswith("SigIgn:")).split()[1]
    ignored.append(bool(int(mask, 16) & (1 << (signal.SIGINT - 1))))
here = signal.getsignal(signal.SIGINT) is before
workers.release(wait=True, kill=True)
print(json.dumps({"ignored": ignored, "here": here}))
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc; forked on Linux")
@pytest.mark.parametrize("pool", ["forked", "fresh"])
def test_workers_ignore_ctrl_c_from_birth(pool):
    """A fresh interpreter imports for a second or two before its initializer runs: the
    workers are started with SIGINT ignored, which they inherit, and this process gets
    its own handler back."""
    found = _printed_json(BORN_IGNORING, pool)
    assert found["ignored"] == [True, True] and found["here"], found


def _in_own_group(cmd: list[str]) -> subprocess.Popen:
    """`cmd` started in a process group of its own (killed or interrupted as one), its
    output piped as text, with SIGINT's default action (a test run started in the
    background of a shell inherits it ignored, as a terminal's Ctrl-C never is)."""
    return subprocess.Popen(
        cmd,
        env=ENV,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )


#: completed()'s error path (every future cancelled, then release(kill=True)) while one
#: search waits behind a full call queue (six searches on two workers, 1 MB each).
STOPPED_WITH_ONE_PENDING = """
import time
import numpy as np
from gpquad.study import workers

def search(payload, seconds):
    time.sleep(seconds)

payload = np.zeros(1_000_000 // 8)
futures = workers.submit_all(2, search, [(payload, 30.0)] * 2)
time.sleep(0.5)
executor = workers._pool["executor"]
futures += [executor.submit(search, payload, 30.0) for _ in range(4)]
del executor
time.sleep(0.5)
print("pending", [f._state for f in futures].count("PENDING"), flush=True)
for future in futures:
    future.cancel()
workers.release(kill=True)
print("released", flush=True)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the forked pool")
def test_a_pool_stopped_with_a_search_pending_lets_the_process_exit():
    """A failed search or Ctrl-C stops the pool while a search still waits to be sent; the
    process then exits at once. Without the pool's manager thread joined, it hung at exit."""
    proc = _in_own_group([sys.executable, "-c", STOPPED_WITH_ONE_PENDING])
    try:
        out, err = proc.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        pytest.fail("the process did not exit after its pool was stopped")
    assert proc.returncode == 0, err
    assert "pending 1" in out and "released" in out
    assert "InvalidStateError" not in err, err


def _group_alive(pgid: int) -> bool:
    try:
        os.killpg(pgid, 0)
    except ProcessLookupError:
        return False
    return True


def _searching_run(tmp_path, pool: str, iterations: int) -> subprocess.Popen:
    """`gpquad run` of CONFIG on two workers (forked, or fresh: a thread runs first) in a
    process group of its own, returned once its searches are under way. Every iteration
    runs (no stall rule): the noise-free searches would stop once exact."""
    config = tmp_path / "pool.toml"
    config.write_text(CONFIG.format(iterations=iterations, extra="stall_iterations = 0"))
    head = ["-m", "gpquad"] if pool == "forked" else ["-c", WITH_A_THREAD]
    cmd = [sys.executable, *head, "run", str(config), "--jobs", "2", "--no-figures"]
    proc = _in_own_group([*cmd, "--out", str(tmp_path / "run")])
    assert proc.stdout is not None
    for line in proc.stdout:
        if "searching" in line:
            break
    time.sleep(1.0)  # the searches are under way (each takes seconds)
    if proc.poll() is not None:
        proc.communicate()
        pytest.fail("the run ended before the test could stop it")
    return proc


def _wait_for_group_end(pgid: int, seconds: float = 10.0) -> bool:
    """Whether every process of the group is gone within `seconds`."""
    deadline = time.monotonic() + seconds
    while _group_alive(pgid) and time.monotonic() < deadline:
        time.sleep(0.1)
    return not _group_alive(pgid)


@pytest.mark.skipif(sys.platform == "win32", reason="process groups and SIGINT")
@pytest.mark.parametrize("pool", ["forked", "fresh"])
def test_ctrl_c_during_the_searches_stops_every_process(tmp_path, pool):
    """Ctrl-C in a terminal reaches every process of the run's group: the run says it was
    interrupted and exits with 130 at once, without a traceback or a process left."""
    proc = _searching_run(tmp_path, pool, iterations=4)
    try:
        os.killpg(proc.pid, signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    finally:
        if _group_alive(proc.pid):
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "Traceback" not in out, err
    assert "interrupted" in out + err
    assert _wait_for_group_end(proc.pid), "a worker outlived the run"


@pytest.mark.skipif(sys.platform == "win32", reason="process groups and SIGKILL")
@pytest.mark.parametrize("pool", ["forked", "fresh"])
def test_workers_exit_when_the_run_is_killed(tmp_path, pool):
    """A run killed outright (SIGKILL: the out-of-memory killer, a job's time limit) cannot
    stop its workers; they see it gone and exit, mid-search, instead of living on."""
    proc = _searching_run(tmp_path, pool, iterations=8)
    try:
        os.kill(proc.pid, signal.SIGKILL)  # the run alone, not its group
        proc.wait(timeout=60)  # (its pipes stay open while a worker lives)
        assert _wait_for_group_end(proc.pid), "a worker outlived the killed run"
    finally:
        if _group_alive(proc.pid):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
