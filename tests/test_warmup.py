"""The warm-up groups compile every kernel that a search and the finishing steps call, with
the same types: afterwards a fit adds no signature to any of gpquad's kernels."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from gpquad.study.warmup import GROUPS, warm

PROBE = textwrap.dedent(
    """
    import json, sys
    from numba.core.registry import CPUDispatcher

    def signatures():
        out = {}
        for name, mod in list(sys.modules.items()):
            if not name.startswith("gpquad"):
                continue
            for obj in vars(mod).values():
                if isinstance(obj, CPUDispatcher):
                    key = obj.py_func.__module__ + "." + obj.py_func.__qualname__
                    out.setdefault(key, set()).update(str(s) for s in obj.signatures)
        return out

    from gpquad.study.warmup import warm
    import gpquad.study.fit, gpquad.models.finish  # every kernel module imported
    for group in sys.argv[1].split(","):
        if group:
            warm(group)
    from gpquad.data.io import load_dataset
    from gpquad.study.config import load_config
    from gpquad.study.fit import fit_dataset

    cfg = load_config(sys.argv[2])
    dataset = load_dataset(cfg)  # the data kernels: the main process's
    before = signatures()
    fit_dataset(dataset, cfg, jobs=1)
    after = signatures()
    new = {k: sorted(v - before.get(k, set())) for k, v in after.items()}
    print(json.dumps({k: v for k, v in new.items() if v}))
    """
)


CONFIG = """
seed = 1
[data]
trim = "mean"
[simulator]
duration_s = 60.0
[evolution]
targets = ["a_x", "p_dot"]
iterations = 1
model_generations = 15
input_taps = 1
"""


def _probe(script: str, *args: str) -> dict:
    """The kernel signatures that `script` (run in a fresh process) reports as added."""
    root = str(Path(__file__).resolve().parents[1])
    env = {**os.environ, "PYTHONPATH": root + os.pathsep + os.environ.get("PYTHONPATH", "")}
    proc = subprocess.run(
        [sys.executable, "-c", script, *args],
        env=env,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _new_signatures(tmp_path: Path, groups: str) -> dict:
    config = tmp_path / "tiny.toml"
    config.write_text(CONFIG)
    return _probe(PROBE, groups, str(config))


def test_after_the_warm_up_a_fit_compiles_nothing(tmp_path):
    """Every kernel that a fit calls on loaded data (the main process loads it) was compiled
    by a warm-up group with the fit's own types. Without the warm-up (the bad
    case) the same fit adds the search's kernels."""
    new = _new_signatures(tmp_path, ",".join(GROUPS))
    assert new == {}
    cold = _new_signatures(tmp_path, "")
    assert "gpquad.engine.kernels.fitness.euler_population_window_errors" in cold
    assert "gpquad.engine.kernels.sensitivity_rk4.rk4_window_residuals" in cold


JOINT_PROBE = PROBE.split("from gpquad.data.io import load_dataset")[0] + textwrap.dedent(
    """
    import dataclasses
    from gpquad.models.joint_fit import joint_refit
    from gpquad.models.reference_models import setpoint_model
    from gpquad.study.warmup import synthetic_dataset

    dataset = synthetic_dataset(seed=3)
    model = setpoint_model(dataset.input_names, dataset.dt)
    model = dataclasses.replace(model, integrator="rk4", substeps=2)
    before = signatures()
    joint_refit(model, dataset, horizons_s=(0.5,))
    after = signatures()
    new = {k: sorted(v - before.get(k, set())) for k, v in after.items()}
    print(json.dumps({k: v for k, v in new.items() if v}))
    """
)


def test_after_the_warm_up_the_joint_refit_compiles_nothing():
    """The joint refit of a continuous-time model (its sensitivity flight, rollouts and LM)
    finds every kernel compiled by the warm-up groups; without them (the bad case) it adds
    the sensitivity flight."""
    assert _probe(JOINT_PROBE, ",".join(GROUPS)) == {}
    cold = _probe(JOINT_PROBE, "")
    assert "gpquad.engine.kernels.rollout_sensitivity.rk4_rollout_sensitivities" in cold


def test_an_unknown_group_is_refused():
    with pytest.raises(ValueError, match="euler"):
        warm("gpu")


def test_the_wait_for_the_warm_up_is_kept_and_printed(monkeypatch):
    """submit_all records how long the searches waited for the workers' warm-up (a cold
    cache's compilation), warm_up_wait hands it out once, and the run's time line shows it
    where it is 0.1 s or more."""
    import threading
    from concurrent.futures import Future

    from gpquad.study import workers
    from gpquad.study.runner import time_profile

    warm_up: Future = Future()
    threading.Timer(0.3, warm_up.set_result, (0.3,)).start()

    class Executor:
        def submit(self, func, *args):
            done: Future = Future()
            done.set_result(func(*args))
            return done

    monkeypatch.setattr(workers, "_pool", {"jobs": 1, "executor": Executor(), "warm": [warm_up]})
    workers.warm_up_wait()
    futures = workers.submit_all(1, abs, [(-2,)])
    assert [f.result() for f in futures] == [2]
    waited = workers.warm_up_wait()
    assert 0.25 <= waited < 5.0
    assert workers.warm_up_wait() == 0.0  # handed out once
    line = time_profile(30.0, 7.0, {"p_dot": 2.0}, {"refine": 1.0}, waited)
    assert "loading 7.0, compiling the kernels 0.3, p_dot 2.0" in line
    assert "compiling" not in time_profile(5.0, 0.3, {"p_dot": 2.0}, {}, 0.05)
