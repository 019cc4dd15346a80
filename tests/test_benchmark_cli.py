"""`gpquad benchmark`: bad input is one line and exit 2; a rerun resumes; --jobs 2 gives the
same table as --jobs 1; the engine settings are gpquad's defaults unless --engine names a
config."""

import json
import shutil
from pathlib import Path
from types import SimpleNamespace

import pytest

from gpquad.benchmark import table
from gpquad.benchmark.engine import ENGINE_SOURCE, engine_config, load_engine
from gpquad.benchmark.runner import collect, done_line, run_benchmark, run_order
from gpquad.cli.benchmark import write_report
from gpquad.cli.commands import main

TINY_ENGINE = """
preset = "paper"
[evolution]
iterations = 1
model_generations = 4
test_generations = 2
n_models = 3
n_tests = 2
suite_size = 2
window_s = 2.0
simplify_generations = 2
"""

USER_CONFIG = """
name = "tiny"
seed = 1
[data]
trim = "mean"
validation_fraction = 0.3
[simulator]
duration_s = 40.0
"""


@pytest.mark.parametrize(
    "argv, field",
    [
        (["benchmark", "no-such-scenario"], "scenario"),
        (["benchmark", "median", "--peers", "zero,lasso"], "--peers"),
        (["benchmark", "median", "--seeds", "0"], "--seeds"),
        (["benchmark", "median", "--jobs", "0"], "--jobs"),
        (["benchmark", "median", "--horizons", "1,abc"], "--horizons"),
        (["benchmark", "median", "--horizons", "0"], "--horizons"),
        (["benchmark", "median", "median"], "scenario"),
        (["benchmark", "missing.toml"], None),
    ],
)
def test_bad_arguments_are_one_line_and_exit_2(argv, field, capsys, tmp_path):
    assert main(argv + ["--out", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("gpquad: error:") and "\n" not in err
    assert (f"field '{field}'" in err) if field else "missing.toml" in err
    assert not (tmp_path / "b").exists()  # refused before any work


def test_bad_user_config_is_one_line(tmp_path, capsys):
    path = tmp_path / "bad.toml"
    path.write_text("[data]\ntrim = 'sometimes'\n")
    assert main(["benchmark", str(path), "--out", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err.strip()
    assert "bad.toml" in err and "data.trim" in err and "\n" not in err


def test_engine_settings_are_the_package_defaults_unless_named(tmp_path):
    """An installed gpquad knows its engine: no file of the checkout is read."""
    cfg, source = load_engine()
    assert source == ENGINE_SOURCE and cfg.evolution == engine_config(1).evolution
    assert engine_config(1).evolution.constant_fit == "lm"
    (tmp_path / "engine.toml").write_text(TINY_ENGINE)
    cfg, source = load_engine(tmp_path / "engine.toml")
    assert source.endswith("engine.toml") and cfg.evolution.iterations == 1
    # every target is identified whatever the engine config's targets say
    assert engine_config(1, cfg).evolution.targets == engine_config(1).evolution.targets


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    base = tmp_path_factory.mktemp("bench")
    (base / "engine").mkdir()
    (base / "engine" / "engine.toml").write_text(TINY_ENGINE)
    (base / "tiny.toml").write_text(USER_CONFIG)
    return base


def _run(tiny, out, jobs=1):
    return run_benchmark(
        [str(tiny / "tiny.toml")],
        ["zero", "ols"],
        2,
        out,
        jobs=jobs,
        horizons_s=(1.0, 2.0),
        engine=tiny / "engine" / "engine.toml",
        log=lambda s: None,
    )


def test_resume_skips_finished_cells_and_jobs_2_gives_the_same_table(tiny):
    out = tiny / "run1"
    info = _run(tiny, out)
    cells = sorted((out / "cells").rglob("*.json"))
    # gpquad seeds 1 and 2, zero and ols once each (deterministic)
    assert [c.relative_to(out / "cells").as_posix() for c in cells] == [
        "tiny/gpquad/seed1.json",
        "tiny/gpquad/seed2.json",
        "tiny/ols/seed0.json",
        "tiny/zero/seed0.json",
    ]
    first = {c: c.read_bytes() for c in cells}
    agg = table.aggregate(collect(out, info))
    assert agg["tiny"]["gpquad"]["recovery"] is not None  # the simulator's truth is known
    assert agg["tiny"]["zero"]["horizons"]["2s"]["mean"]["mean"] > 0.1
    # a killed run: one cell never finished, another left a damaged file
    cells[0].unlink()
    cells[3].write_text('{"scenario": ')
    info = _run(tiny, out)
    for c in (cells[1], cells[2]):  # finished cells are not recomputed
        assert c.read_bytes() == first[c]
    again = table.aggregate(collect(out, info))
    assert table.comparable(again) == table.comparable(agg)

    out2 = tiny / "run2"
    info2 = _run(tiny, out2, jobs=2)
    assert table.comparable(table.aggregate(collect(out2, info2))) == table.comparable(agg)
    write_report(out2, info2)
    assert (out2 / "figures" / "tiny.png").is_file()
    text = (out2 / "benchmark.md").read_text()
    assert "| gpquad | 1s |" in text and "| zero | 2s |" in text
    summary = text[text.index("## Summary") : text.index("## Per state")]
    assert "| tiny | gpquad |" in summary and "| tiny | zero |" in summary
    assert "/6, " in summary  # exact equations of each gpquad seed (the truth is known)
    assert "| parameters | fit s |" in summary
    # the zero model fits no number; gpquad's count is its cells' (fitted numbers of the
    # printed equations), shown in the summary beside the fit time
    assert agg["tiny"]["zero"]["parameters"]["mean"] == 0
    counts = [json.loads(c.read_text())["n_parameters"] for c in cells[:2]]
    assert all(n > 0 for n in counts)
    assert agg["tiny"]["gpquad"]["parameters"]["mean"] == sum(counts) / 2
    # where the fit's time went: each equation's search and each finishing step
    profile = json.loads(cells[0].read_text())["fit_profile_s"]
    assert set(profile["search"]) == set(json.loads(cells[0].read_text())["equations"])
    assert profile["finish"] == {}  # the paper preset has no finishing step
    assert set(profile["phases"]) == set(profile["search"])
    assert "| scenario | generations s |" in text and "final choice s" in text
    old = {**json.loads(cells[0].read_text()), "fit_profile_s": {"search": {}, "finish": {}}}
    assert table.phase_markdown([old]) == ""  # a cell fitted before the phases were kept
    assert "## Where gpquad's fit time went" in text and "| tiny | " in text.split("went")[1]
    assert table.fit_profile({"method": "zero"}) is None
    grouped = {"fit_profile_s": {"a": profile, "b": profile}}  # a per-vehicle cell
    assert table.fit_profile(grouped)["searches"] == 2 * sum(profile["search"].values())
    assert table.parameters({"n_parameters": {"a": 3, "b": 4}}) == 7
    assert table.parameters({"n_parameters": {"a": 3, "b": None}}) is None
    assert table.parameters({}) is None
    saved = json.loads((out2 / "results.json").read_text())
    assert saved["benchmark"]["engine_config"].endswith("engine.toml")
    # every cell's printed equations flown by RK4 x 8 beside their own scheme
    fid = saved["fidelity"]["tiny"]
    assert set(fid) == {"gpquad", "ols", "zero"} and fid["gpquad"]["seeds"] == [1, 2]
    assert fid["gpquad"]["rk4"]["2s"]["rse"]["p"]["n"] == 2
    assert fid["gpquad"]["text_matches_stored"] == 2
    assert "## Fidelity" in text and "| gpquad (euler) |" in text


def test_folder_scored_at_other_horizons_is_refused(tiny, capsys):
    out = tiny / "run3"
    shutil.copytree(tiny / "run1", out)
    with pytest.raises(Exception, match="other horizons"):
        run_benchmark(
            [str(tiny / "tiny.toml")],
            ["zero"],
            1,
            out,
            horizons_s=(1.0,),
            engine=tiny / "engine" / "engine.toml",
            log=lambda s: None,
        )
    assert Path(out / "benchmark.json").is_file()


def test_changed_engine_config_recomputes_only_gpquad_cells(tiny):
    out = tiny / "run4"
    shutil.copytree(tiny / "run1", out)
    engine = tiny / "engine2"
    engine.mkdir()
    (engine / "engine.toml").write_text(TINY_ENGINE.replace("iterations = 1", "iterations = 2"))
    before = {c: c.read_bytes() for c in (out / "cells").rglob("*.json")}
    # peers only: gpquad's cells (made with the old engine) are not touched
    run_benchmark(
        [str(tiny / "tiny.toml")],
        ["zero", "ols"],
        2,
        out,
        horizons_s=(1.0, 2.0),
        engine=engine / "engine.toml",
        log=lambda s: None,
        with_gpquad=False,
    )
    assert {c: c.read_bytes() for c in before} == before
    info = run_benchmark(
        [str(tiny / "tiny.toml")],
        ["zero", "ols"],
        2,
        out,
        horizons_s=(1.0, 2.0),
        engine=engine / "engine.toml",
        log=lambda s: None,
    )
    changed = sorted(
        c.relative_to(out / "cells").as_posix() for c in before if c.read_bytes() != before[c]
    )
    assert changed == ["tiny/gpquad/seed1.json", "tiny/gpquad/seed2.json"]
    cell = json.loads((out / "cells/tiny/gpquad/seed1.json").read_text())
    assert cell["settings"]["evolution"]["iterations"] == 2
    assert cell["fingerprint"] == info["fingerprints"]["tiny"]["gpquad"]


def test_a_comment_in_the_engine_config_recomputes_nothing(tiny):
    """The fingerprint holds the parsed settings, not the file's text."""
    out = tiny / "run5"
    shutil.copytree(tiny / "run1", out)
    engine = tiny / "engine3"
    engine.mkdir()
    (engine / "engine.toml").write_text("# a note on the settings\n" + TINY_ENGINE)
    before = {c: c.read_bytes() for c in (out / "cells").rglob("*.json")}
    run_benchmark(
        [str(tiny / "tiny.toml")],
        ["zero", "ols"],
        2,
        out,
        horizons_s=(1.0, 2.0),
        engine=engine / "engine.toml",
        log=lambda s: None,
    )
    assert {c: c.read_bytes() for c in before} == before


def test_report_flies_the_stored_cells_of_an_older_folder_without_fitting(tiny, capsys):
    """A folder made by another gpquad (its cells' fingerprints are not today's): --report
    refits nothing and adds the fidelity of every stored cell."""
    out = tiny / "run6"
    shutil.copytree(tiny / "run1", out)
    shutil.rmtree(out / "fidelity")
    info = json.loads((out / "benchmark.json").read_text())
    info["fingerprints"]["tiny"]["gpquad"] = "made-by-an-older-gpquad"
    (out / "benchmark.json").write_text(json.dumps(info))
    for path in (out / "cells" / "tiny" / "gpquad").glob("*.json"):
        cell = json.loads(path.read_text())
        cell["fingerprint"] = "made-by-an-older-gpquad"
        path.write_text(json.dumps(cell))
    before = {c: c.read_bytes() for c in (out / "cells").rglob("*.json")}
    assert main(["benchmark", "--report", "--out", str(out)]) == 0
    assert {c: c.read_bytes() for c in before} == before
    assert len(list((out / "fidelity").rglob("*.json"))) == 4
    saved = json.loads((out / "results.json").read_text())
    assert saved["fidelity"]["tiny"]["gpquad"]["seeds"] == [1, 2]
    assert "## Fidelity" in (out / "benchmark.md").read_text()


def test_the_progress_line_says_when_windows_diverged():
    """The mean RSE leaves diverged windows out, so a cell whose model diverges can show a
    lower mean (px4-s250 seed 2 with a pole in a_z): the line says how many it left out."""
    metrics = {"7s": {"mean": 0.2588, "windows": 12, "diverged": 7}}
    cell = {"scenario": "px4-s250", "method": "gpquad", "seed": 2, "metrics": metrics}
    cell["cost"] = {"fit_time_s": 29.8}
    assert "mean RSE 7s 0.2588 (7 of 12 windows diverged, left out)" in done_line(cell, 153)
    metrics["7s"]["diverged"] = 0
    assert "diverged" not in done_line(cell, 153)  # the check can fail
    cell["metrics"] = {"7s": {"mean": None, "windows": 12, "diverged": 12}}
    assert "no score" in done_line(cell, 153)


def test_one_job_runs_each_scenarios_cells_back_to_back():
    """With --jobs 1 a scenario's methods run one after the other, so that a machine that
    drifts in speed over the run slows a scenario's gpquad and PySINDy cells alike; in
    parallel the longest method's cells go first."""

    a, b = SimpleNamespace(name="a"), SimpleNamespace(name="b")
    missing = [(b, "zero", 0), (a, "sindy", 0), (b, "gpquad", 1), (a, "gpquad", 2)]
    missing += [(a, "gpquad", 1), (b, "sindy", 0)]
    one = [(c[0].name, c[1], c[2]) for c in run_order(missing, 1)]
    assert one == [
        ("a", "gpquad", 1),
        ("a", "gpquad", 2),
        ("a", "sindy", 0),
        ("b", "gpquad", 1),
        ("b", "sindy", 0),
        ("b", "zero", 0),
    ]
    two = [(c[0].name, c[1], c[2]) for c in run_order(missing, 2)]
    assert [m for _, m, _ in two] == ["gpquad"] * 3 + ["sindy"] * 2 + ["zero"]
    assert two != one  # the method-major order fails the first check: it can fail
