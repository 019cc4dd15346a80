"""A search takes the cores its pool leaves idle as threads for its final choice
(gpquad.study.workers.CoreShare); the equations are the same for any number of threads."""

from __future__ import annotations

import dataclasses
import hashlib
import math
import os
import subprocess
import sys
import types

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_engine import tiny_config

from gpquad.data.io import load_dataset
from gpquad.engine.evolve import selection
from gpquad.engine.evolve.selection import bic, pruned_subtrees
from gpquad.engine.tree.encoding import Tree
from gpquad.engine.tree.variation import (
    VariationParams,
    fold_constants,
    random_tree,
    subtrees_as_constants,
)
from gpquad.study import fit, workers
from gpquad.study.config import preset_evolution
from gpquad.study.search import Progress, identify

#: The stub criterion: BIC over 10 window-steps, far above its floor.
N, FLOOR = 10, 1e-7


def _draw(tree: Tree, salt: bytes) -> float:
    """A number in [0, 1) that is a function of the tree's codes and values."""
    digest = hashlib.sha256(salt + tree.codes.tobytes() + tree.values.round(9).tobytes())
    return int.from_bytes(digest.digest()[:8], "little") / 2.0**64


def stub_fit(tree: Tree) -> tuple[Tree, float]:
    """A 'fit' whose result depends on where it starts: the same structure from other
    constants ends elsewhere (as an LM fit does)."""
    values = tree.values + np.where(tree.codes == 0, 0.5 * _draw(tree, b"step"), 0.0)
    fitted = Tree(tree.codes, values, tree.delays)
    start = 1.0 + 3.0 * _draw(tree, b"mse")
    return fitted, min(start, 0.5 + 3.0 * _draw(fitted, b"fitted"))


def tied_fit(tree: Tree) -> tuple[Tree, float]:
    """stub_fit with its errors on a coarse grid: a leaf made a constant keeps the tree's
    size, and with its error it often ties the BIC (taken: `<=`)."""
    fitted, error = stub_fit(tree)
    return fitted, 0.5 + 0.5 * round(error / 0.5 - 1.0)


def score_of(tree: Tree, error: float) -> float:
    return bic(error, N, tree.size, FLOOR)


def constant_of(tree, start, end):
    return round(0.1 * start - 0.05 * end, 6)


def one_by_one(model: Tree, score: float, fit) -> Tree:
    """The pruning passes as they were before their batches (the reference): every
    candidate fitted in turn, the first that scores no higher taken."""
    fitted: dict = {}
    changed = True
    while changed and model.size > 1:
        changed = False
        for candidate in subtrees_as_constants(model, constant_of):
            key = tuple(candidate.codes.tolist())
            if key not in fitted:
                fitted[key] = fit(candidate)
            candidate, cand_err = fitted[key]
            cand_score = score_of(candidate, cand_err)
            if cand_score <= score:
                model, score, changed = candidate, cand_score, True
                break
    return model


PARAMS = VariationParams(n_variables=13, n_inputs=4, max_depth=5, p_leaf=0.4)


def _start(seed: int, fit) -> tuple[Tree, float]:
    """A random tree, fitted, and its score: where the pruning passes start."""
    model, error = fit(fold_constants(random_tree(np.random.default_rng(seed), PARAMS)))
    return model, score_of(model, error)


@settings(max_examples=200, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    threads=st.lists(st.integers(1, 5), min_size=1, max_size=6),
)
@pytest.mark.parametrize("stub_fit", [stub_fit, tied_fit])
def test_pruning_in_batches_is_the_pruning_one_by_one(stub_fit, seed, threads):
    """Any number of threads, changing between batches, prunes to the same tree as one by
    one: the first candidate that passes is taken (ties too), and the fits made beside it
    and after it are not kept."""
    model, score = _start(seed, stub_fit)
    reference = one_by_one(model, score, stub_fit)
    cycle = iter(threads * 1000)
    batched = pruned_subtrees(
        model, score, score_of, constant_of, stub_fit, threads=lambda: next(cycle)
    )
    assert batched.codes.tolist() == reference.codes.tolist()
    assert batched.values.tolist() == reference.values.tolist()
    assert batched.delays.tolist() == reference.delays.tolist()


def test_the_stub_pruning_takes_several_passes():
    """The property above is not vacuous: its trees are pruned, over several passes, with
    candidates refused and taken."""
    cut = []
    for seed in range(20):
        model, score = _start(seed, stub_fit)
        cut.append(model.size - one_by_one(model, score, stub_fit).size)
    assert sum(c > 0 for c in cut) >= 5 and max(cut) >= 4


def test_the_share_tells_each_search_its_threads(tmp_path):
    share = workers.CoreShare(left=6)
    threads = workers.threads_of(share.path, 4)
    seen = []
    for left in (6, 4, 3, 2, 1, 0):
        share.set(left)
        seen.append(threads())
    assert seen == [1, 1, 1, 2, 4, 4]
    share.close()
    assert not os.path.exists(share.path)
    assert threads() == 1  # no file: one thread
    bad = tmp_path / "bad"
    bad.write_text("many")
    assert workers.threads_of(str(bad), 4)() == 1


def test_without_a_temporary_directory_each_search_keeps_one_thread(monkeypatch):
    def no_directory(*args, **kwargs):
        raise PermissionError("read-only file system")

    monkeypatch.setattr(workers.tempfile, "mkstemp", no_directory)
    with workers.CoreShare(left=1) as share:
        share.set(1)
        assert workers.threads_of(share.path, 4)() == 1


def test_a_worker_search_is_given_its_pool_share(monkeypatch):
    """_identify_in_worker hands the search the threads its pool's share allows."""
    seen = []

    def spy(dataset, target, cfg, rows, threads=None, seconds=None):
        seen.append(threads())
        return types.SimpleNamespace(target=target), None

    monkeypatch.setattr(fit, "identify", spy)
    with workers.CoreShare(left=1) as share:
        fit._identify_in_worker(None, "p_dot", None, False, share.path, 3)
        share.set(3)
        fit._identify_in_worker(None, "q_dot", None, False, share.path, 3)
    assert seen == [3, 1]


@pytest.mark.parametrize("inside, expected", [(False, 3), (True, 1)])
def test_a_search_in_this_process_takes_the_fits_cores(monkeypatch, inside, expected):
    """One equation searched in this process gets `jobs` threads, unless this process is
    itself a worker of another (a benchmark's parallel cells)."""
    seen = []

    def spy(dataset, target, cfg, history, report, threads=None, **kwargs):
        seen.append(threads())
        raise KeyboardInterrupt  # enough: the search was started with its threads

    monkeypatch.setattr(fit, "identify", spy)
    monkeypatch.setattr(fit.workers, "inside_worker", lambda: inside)
    cfg = recommended("p_dot")
    with pytest.raises(KeyboardInterrupt):
        fit.search_equations(None, cfg, Progress(False, 1), jobs=3)
    assert seen == [expected]


def test_the_pool_has_at_most_one_process_per_equation():
    assert workers.processes(8, 6) == 6
    assert workers.processes(2, 6) == 2
    assert workers.processes(4, 1) == 1


def test_the_default_counts_the_cores_this_process_may_use():
    """CPU affinity (taskset, a batch scheduler) limits the default, as a container's quota
    does: os.cpu_count() would count every core of the host."""
    if not hasattr(os, "sched_setaffinity"):
        pytest.skip("no CPU affinity on this platform")
    code = (
        "import os; os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]}); "
        "from gpquad.study.workers import default_jobs; print(default_jobs())"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "1"
    assert workers.default_jobs() >= 1


def test_no_threads_asked_is_one_thread():
    """threads() <= 0 prunes as one thread does (it must never skip the pruning)."""
    model, score = _start(7, stub_fit)
    one = pruned_subtrees(model, score, score_of, constant_of, stub_fit, lambda: 1)
    none = pruned_subtrees(model, score, score_of, constant_of, stub_fit, lambda: 0)
    assert none.codes.tolist() == one.codes.tolist() and none.values.tolist() == one.values.tolist()
    assert one.size < model.size


def recommended(target: str):
    """The default engine (BIC choice, RK4) on a small budget."""
    small = preset_evolution(
        "recommended",
        targets=(target,),
        iterations=1,
        model_generations=15,
        test_generations=5,
        window_s=2.4,
        simplify_generations=5,
    )
    return dataclasses.replace(tiny_config(), evolution=small)


@pytest.fixture(scope="module")
def quick_dataset():
    return load_dataset(tiny_config())


@pytest.mark.parametrize("target", ["a_y", "p_dot"])
def test_a_search_finds_the_same_equation_with_more_threads(quick_dataset, target):
    cfg = recommended(target)
    calls = []

    def two():
        calls.append(2)
        return 2

    batches = []
    real_map = selection.thread_map

    def recorded(func, items, workers):
        batches.append(len(items))
        return real_map(func, items, workers)

    one, _ = identify(quick_dataset, target, cfg)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(selection, "thread_map", recorded)
        more, _ = identify(quick_dataset, target, cfg, threads=two)
    assert calls, "the search never asked for its threads"
    assert max(batches) > 1, "no fits were made side by side"
    assert more.to_dict() == one.to_dict()
    assert math.isfinite(more.error)


def test_in_process_searches_take_the_fits_cores(monkeypatch):
    """in_process (gpquad.fit into a run_dir): every target searched here, one after the
    other, each with `jobs` threads."""
    from export_models import HAND_TRIM, equation

    seen = {}

    def spy(dataset, target, cfg, history, report, threads=None, **kwargs):
        seen[target] = threads()
        return equation(target, ("*", 2.0, "p"), [0, 0, 0, 0], HAND_TRIM), None

    monkeypatch.setattr(fit, "identify", spy)
    monkeypatch.setattr(fit.workers, "inside_worker", lambda: False)
    cfg = dataclasses.replace(
        recommended("p_dot"),
        evolution=dataclasses.replace(recommended("p_dot").evolution, targets=("p_dot", "q_dot")),
    )
    found, _ = fit.search_equations(None, cfg, Progress(False, 2), jobs=3, in_process=True)
    assert seen == {"p_dot": 3, "q_dot": 3} and set(found) == {"p_dot", "q_dot"}


def test_a_fit_into_a_run_folder_searches_here_on_every_core(monkeypatch, tmp_path):
    import gpquad
    from gpquad.study import runner

    asked = {}

    class Stop(Exception):
        pass

    def spy(cfg, run_dir, **kwargs):
        asked.update(kwargs)
        raise Stop

    monkeypatch.setattr(runner, "run_experiment", spy)
    flight = gpquad.reference_flight(seed=0, duration_s=20.0)
    with pytest.raises(Stop):
        gpquad.fit(flight, run_dir=tmp_path / "r", targets=["p_dot"], iterations=1)
    assert asked["in_process"] is True and asked["jobs"] == workers.default_jobs()
    with pytest.raises(Stop):
        gpquad.fit(flight, run_dir=tmp_path / "r", targets=["p_dot"], iterations=1, jobs=2)
    assert asked["in_process"] is False and asked["jobs"] == 2
