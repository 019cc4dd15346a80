"""Checkpoints: exact round trip, damage detection, recovery inside a sweep."""

from __future__ import annotations

import dataclasses
import json
import shutil

import numpy as np
import pytest
from test_sweep import result_files, tiny_config

from gpquad.data.io import load_dataset
from gpquad.engine.evolve.coevolution import Coevolution, RunState
from gpquad.study import checkpoint
from gpquad.study.progress import SweepProgress
from gpquad.study.sweep import run_sweep
from gpquad.study.sweep_folders import RunKey, run_dir


@pytest.fixture(scope="module")
def engine():
    cfg = tiny_config()
    dataset = load_dataset(cfg)
    return Coevolution(dataset, "p_dot", cfg.evolution)


def _same(a: RunState, b: RunState) -> None:
    assert a.iteration == b.iteration and a.inserted == b.inserted and a.target == b.target
    assert len(a.models) == len(b.models)
    for x, y in zip(a.models, b.models, strict=True):
        assert np.array_equal(x.codes, y.codes) and np.array_equal(x.delays, y.delays)
        assert np.array_equal(x.values, y.values)
    for name in ("model_errors", "tests", "suite", "suite_age"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert a.rng_state == b.rng_state


def test_round_trip_then_continue_equals_uninterrupted(engine, tmp_path):
    state = engine.init_state(np.random.SeedSequence(3))
    engine.iterate(state)
    state.history.clear()
    checkpoint.save(tmp_path / "c.bin", state, {"history_bytes": 123})
    loaded, meta = checkpoint.load(tmp_path / "c.bin")
    assert meta == {"history_bytes": 123}
    _same(loaded, state)
    engine.iterate(state)
    engine.iterate(loaded)
    _same(loaded, state)
    assert loaded.history == state.history


def test_every_runstate_field_but_history_is_stored(engine):
    state = engine.init_state(np.random.SeedSequence(4))
    blob = checkpoint.encode(state, {})
    payload = json.loads(blob[checkpoint._HEADER.size :])
    names = {f.name for f in dataclasses.fields(RunState)} - {"history"}
    assert set(payload["state"]) == names


@pytest.mark.parametrize("damage", ["truncate", "flip", "magic", "empty", "extra"])
def test_damaged_checkpoint_is_detected(engine, tmp_path, damage):
    state = engine.init_state(np.random.SeedSequence(5))
    blob = bytearray(checkpoint.encode(state, {}))
    if damage == "truncate":
        blob = blob[: len(blob) // 2]
    elif damage == "flip":
        blob[-10] ^= 0xFF
    elif damage == "magic":
        blob[:8] = b"NOTCKPT!"
    elif damage == "empty":
        blob = bytearray()
    else:
        blob += b"\0"
    (tmp_path / "c.bin").write_bytes(bytes(blob))
    with pytest.raises(checkpoint.CorruptCheckpoint):
        checkpoint.load(tmp_path / "c.bin")


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    out = tmp_path_factory.mktemp("ref")
    run_sweep(tiny_config(), out, jobs=1, assemble=False)
    return out


def test_truncated_checkpoint_restarts_the_run_with_a_warning(reference, tmp_path):
    import io

    out = tmp_path / "s"
    shutil.copytree(reference, out)
    folder = run_dir(out, RunKey("a_z", 1))
    (folder / "result.json").unlink()
    blob = (folder / "checkpoint.bin").read_bytes()
    (folder / "checkpoint.bin").write_bytes(blob[: len(blob) - 7])
    (folder / "history.csv").write_text("garbage\n")  # must be thrown away, not appended to
    stream = io.StringIO()
    res = run_sweep(
        tiny_config(), out, jobs=1, assemble=False, progress=SweepProgress("quiet", stream=stream)
    )
    assert any("corrupt checkpoint" in w and "a_z" in w for w in res["warnings"])
    assert "corrupt checkpoint" in stream.getvalue()
    again = {s["repetition"] for s in res["runs"] if not s["skipped"]}
    assert again == {1}
    assert result_files(out) == result_files(reference)


def test_crash_between_history_and_checkpoint_does_not_duplicate_rows(
    reference, tmp_path, monkeypatch
):
    out = tmp_path / "s"
    shutil.copytree(reference, out)
    key = RunKey("p_dot", 0)
    folder = run_dir(out, key)
    for p in folder.iterdir():
        p.unlink()
    real_save = checkpoint.save
    calls = []

    def crash_on_second(path, state, meta):
        calls.append(state.iteration)
        if len(calls) == 2:  # iteration 2's rows are on disk, its checkpoint is not
            raise KeyboardInterrupt
        return real_save(path, state, meta)

    monkeypatch.setattr(checkpoint, "save", crash_on_second)
    with pytest.raises(KeyboardInterrupt):
        run_sweep(tiny_config(), out, jobs=1, assemble=False)
    monkeypatch.setattr(checkpoint, "save", real_save)
    rows = (folder / "history.csv").read_text().splitlines()
    assert len(rows) == 1 + 2 * 8  # both iterations written; checkpoint says 1
    with open(folder / "history.csv", "a") as fh:
        fh.write("p_dot,2,0,0.1")  # and a torn line, as a kill mid-write leaves
    state, meta = checkpoint.load(folder / "checkpoint.bin")
    assert state.iteration == 1
    run_sweep(tiny_config(), out, jobs=1, assemble=False)
    assert (folder / "history.csv").read_bytes() == (
        run_dir(reference, key) / "history.csv"
    ).read_bytes()
    assert json.loads((folder / "result.json").read_text()) == json.loads(
        (run_dir(reference, key) / "result.json").read_text()
    )
