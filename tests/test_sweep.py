"""Sweeps: seeding, bit-identical results whatever the jobs or backend, progress modes."""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np
import pytest

from gpquad.engine.variables import TARGET_NAMES
from gpquad.errors import GpquadError
from gpquad.study.config import config_from_dict
from gpquad.study.progress import SweepProgress
from gpquad.study.seeding import assembly_seed, run_seed
from gpquad.study.sweep import run_sweep
from gpquad.study.sweep_folders import RunKey, fingerprint, grid, run_dir

#: A tiny study: 2 equations x 2 repetitions on a 60 s simulated flight.
TINY = {
    "name": "tiny",
    "seed": 5,
    "data": {"trim": "mean", "validation_fraction": 0.3},
    "simulator": {"duration_s": 60.0},
    "evolution": {
        "targets": ["a_z", "p_dot"],
        "iterations": 2,
        "model_generations": 8,
        "test_generations": 3,
        "simplify_generations": 3,
        "window_s": 2.0,
    },
    "preset": "paper",
    "sweep": {"runs": 2, "full_models": 3, "horizons_s": [1.0, 3.0]},
}


def tiny_config(**changes):
    table = json.loads(json.dumps(TINY))
    for section, values in changes.items():
        table[section].update(values)
    return config_from_dict(table, "tiny")


def result_files(out: Path) -> dict[str, bytes]:
    """Every deterministic output of a sweep folder (not timings or status)."""
    names = (
        "model.json",
        "assembly.json",
        "predictions.npz",
        "result.json",
        "history.csv",
        "equations.tex",
    )
    return {
        str(p.relative_to(out)): p.read_bytes() for p in sorted(out.rglob("*")) if p.name in names
    }


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """An uninterrupted single-job sweep of TINY."""
    out = tmp_path_factory.mktemp("ref")
    run_sweep(tiny_config(), out, jobs=1)
    return out


def test_run_seed_is_a_spawned_child_independent_of_grid():
    for t in TARGET_NAMES:
        for k in (0, 3, 29):
            seq = run_seed(11, t, k)
            expected = np.random.SeedSequence(11, spawn_key=(TARGET_NAMES.index(t), k))
            assert seq.spawn_key == expected.spawn_key
            assert np.array_equal(seq.generate_state(4), expected.generate_state(4))
    states = {
        run_seed(11, t, k).generate_state(2).tobytes() for t in TARGET_NAMES for k in range(30)
    }
    assert len(states) == 180  # every run of the paper grid gets its own stream
    assembly = {assembly_seed(11, k).generate_state(2).tobytes() for k in range(30)}
    assert not assembly & states


def test_grid_is_target_major():
    cfg = tiny_config()
    assert grid(cfg) == [RunKey("a_z", 0), RunKey("a_z", 1), RunKey("p_dot", 0), RunKey("p_dot", 1)]


def test_reference_sweep_writes_every_file(reference):
    for key in grid(tiny_config()):
        d = run_dir(reference, key)
        res = json.loads((d / "result.json").read_text())
        assert res["iterations"] == 2 and res["target"] == key.target
        rows = (d / "history.csv").read_text().splitlines()
        assert len(rows) == 1 + 2 * 8  # header + iterations x model generations
    model = json.loads((reference / "model.json").read_text())
    assert set(model["targets"]) == {"a_z", "p_dot"}
    assembly = json.loads((reference / "assembly.json").read_text())
    assert len(assembly["full_models"]) == 3
    # the best model takes the run with the lowest validation error, per equation
    for t, rep in assembly["best"]["members"].items():
        errs = [r["validation_error"] for r in assembly["runs_errors"][t]]
        assert rep == int(np.argmin(errs))
        assert model["targets"][t]["validation_error"] == errs[rep]


def test_two_jobs_give_identical_results(reference, tmp_path):
    run_sweep(tiny_config(), tmp_path, jobs=2)
    ours, ref = result_files(tmp_path), result_files(reference)
    assert ours.keys() == ref.keys() and len(ours) > 10
    for name in ref:
        assert ours[name] == ref[name], name


def test_dask_local_cluster_equals_loky(reference, tmp_path):
    pytest.importorskip("distributed")
    run_sweep(tiny_config(), tmp_path, jobs=2, backend="dask")
    assert result_files(tmp_path) == result_files(reference)


def test_finished_runs_are_skipped(reference, tmp_path):
    import shutil

    shutil.copytree(reference, tmp_path / "s")
    mtime = (run_dir(tmp_path / "s", RunKey("a_z", 0)) / "result.json").stat().st_mtime_ns
    out = run_sweep(tiny_config(), tmp_path / "s", jobs=1)
    assert all(s["skipped"] for s in out["runs"])
    assert (run_dir(tmp_path / "s", RunKey("a_z", 0)) / "result.json").stat().st_mtime_ns == mtime


def test_more_runs_extend_a_sweep_without_changing_earlier_runs(reference, tmp_path):
    import shutil

    shutil.copytree(reference, tmp_path / "s")
    out = run_sweep(tiny_config(), tmp_path / "s", jobs=1, runs=3, assemble=False)
    done = {(s["target"], s["repetition"]): s["skipped"] for s in out["runs"]}
    assert done == {
        ("a_z", 0): True,
        ("a_z", 1): True,
        ("a_z", 2): False,
        ("p_dot", 0): True,
        ("p_dot", 1): True,
        ("p_dot", 2): False,
    }


def test_other_config_in_same_folder_is_refused(reference, tmp_path):
    import shutil

    shutil.copytree(reference, tmp_path / "s")
    other = tiny_config(evolution={"model_generations": 9})
    assert fingerprint(other) != fingerprint(tiny_config())
    with pytest.raises(GpquadError, match="different config"):
        run_sweep(other, tmp_path / "s", jobs=1)


def test_bad_arguments_fail_before_work(tmp_path):
    with pytest.raises(GpquadError, match="--backend"):
        run_sweep(tiny_config(), tmp_path, backend="mpi")
    with pytest.raises(GpquadError, match="window"):
        run_sweep(tiny_config(evolution={"window_s": 200.0}), tmp_path)
    assert not (tmp_path / "sweep.json").exists()


def test_jsonl_progress_events(reference, tmp_path):
    import shutil

    shutil.copytree(reference, tmp_path / "s")
    for key in (RunKey("p_dot", 1),):  # one run to do again
        for p in run_dir(tmp_path / "s", key).iterdir():
            p.unlink()
    stream = io.StringIO()
    run_sweep(
        tiny_config(),
        tmp_path / "s",
        jobs=1,
        progress=SweepProgress("jsonl", stream=stream, interval=0.05, interval_log=0.0),
    )
    events = [json.loads(line) for line in stream.getvalue().splitlines()]
    kinds = [e["event"] for e in events]
    assert kinds[0] == "start" and kinds[-1] == "sweep_done"
    done = [e for e in events if e["event"] == "run_done"]
    assert sorted((e["target"], e["repetition"], e["skipped"]) for e in done) == [
        ("a_z", 0, True),
        ("a_z", 1, True),
        ("p_dot", 0, True),
        ("p_dot", 1, False),
    ]
    ref = json.loads((run_dir(reference, RunKey("p_dot", 1)) / "result.json").read_text())
    again = [e for e in done if not e["skipped"]][0]
    assert again["validation_error"] == ref["validation_error"]
    final = events[-1]
    assert final["best_validation_error"]["p_dot"] == min(
        json.loads((run_dir(reference, RunKey("p_dot", k)) / "result.json").read_text())[
            "validation_error"
        ]
        for k in range(2)
    )


def test_live_progress_line_reports_counts_and_eta(reference):
    prog = SweepProgress("live", stream=io.StringIO())
    prog.out, prog.keys, prog.iterations = Path(reference), grid(tiny_config()), 2
    prog.t0 = 0.0
    prog.done_at_start = 0
    snap = prog.snapshot()
    assert (snap["done"], snap["running"], snap["total"]) == (4, 0, 4)
    assert snap["iterations_done"] == snap["iterations_total"] == 8
    line = prog.line(snap)
    assert line.startswith("[4/4 done, 0 running, 8/8 iterations") and "ETA 0m00s" in line
    assert "a_z" in line and "p_dot" in line


EXPERIMENTS = Path(__file__).resolve().parents[1] / "experiments"


def test_paper_config_has_the_papers_numbers_each_line_documented():
    from gpquad.study.config import load_config

    cfg = load_config(EXPERIMENTS / "paper.toml")
    ev, sw = cfg.evolution, cfg.sweep
    assert (sw.runs, sw.full_models, ev.iterations) == (30, 30, 30)
    assert (ev.model_generations, ev.test_generations) == (600, 80)
    assert (ev.n_models, ev.n_tests, ev.suite_size, ev.window_steps(0.04)) == (14, 5, 6, 750)
    assert (ev.max_depth, ev.max_delay, ev.gp.p_leaf, ev.gp.p_delay) == (5, 5, 0.7, 0.1)
    assert (sw.input_noise, sw.window_s, sw.horizons_s) == (0.1, 7.0, (1.0, 7.0, 30.0))
    assert round(cfg.data.validation_fraction * 13800) == 2000
    assert cfg.simulator.duration_s * cfg.simulator.rate_hz == 13800
    for line in (EXPERIMENTS / "paper.toml").read_text().splitlines():
        if "=" in line and not line.lstrip().startswith("#"):
            assert "#" in line, f"undocumented setting: {line}"


def test_smoke_and_px4_sweep_configs_load():
    from gpquad.study.config import load_config

    assert load_config(EXPERIMENTS / "smoke.toml").sweep.runs >= 2
    px4 = load_config(EXPERIMENTS / "px4_s250_sweep.toml")
    assert "a_x" not in px4.evolution.targets  # horizontal velocity not measured in this log
    assert px4.data.format == "px4-csv"
