"""The Python API (gpquad.fit, load, read_log, reference_flight and Model): one fit path
with `gpquad run`, DataFrames in and out, one-line errors for user mistakes."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import gpquad
from gpquad.data.dataset import build_dataset
from gpquad.data.flight import flight_from_frame
from gpquad.models.analysis import compare_to_truth
from gpquad.study.config import MEDIAN_MODEL, Config, config_from_dict
from gpquad.study.runner import run_experiment

INPUTS = ("u_P", "u_R", "u_Y", "u_T")
FAST = {"iterations": 1, "input_taps": 1, "targets": ["p_dot", "q_dot"]}


@pytest.fixture(scope="module")
def flight() -> pd.DataFrame:
    return gpquad.reference_flight(seed=0, duration_s=80.0)


@pytest.fixture(scope="module")
def other() -> pd.DataFrame:
    return gpquad.reference_flight(seed=7, duration_s=40.0)


@pytest.fixture(scope="module")
def model(flight) -> gpquad.Model:
    return gpquad.fit(flight, seed=1, **FAST)


def test_fit_recovers_the_truth_and_describes_itself(model, flight):
    assert model.targets == ("p_dot", "q_dot") and model.dt == pytest.approx(0.04)
    dataset = build_dataset([flight_from_frame(flight, INPUTS)], validation_fraction=0.15)
    for t in model.targets:
        assert compare_to_truth(model.discovered.equations[t], MEDIAN_MODEL[t], dataset)[
            "passed"
        ], t
    assert str(model).startswith("dt = 0.04 s") and "p_dot = " in str(model)
    assert repr(model).startswith("<gpquad.Model 2 equations (p_dot, q_dot), dt=0.04 s")
    forms = model.equations["p_dot"]
    assert forms.delays == {"u_R": 1} and forms.lag == 0.0
    assert {s.name for s in forms.sympy.rhs.free_symbols} == {"p", "u_R(t-1)"}
    assert "u_R(t-1)" in forms.text and r"\dot" in forms.latex


def test_printed_equation_is_the_ode_the_vehicle_flies(model, flight):
    """The reference flight flies p_dot = -4.15 p + 10.3 u_R(t-1) as an ODE (RK4): the default
    fit prints those coefficients, though its generations fly eq. 2; a fit by eq. 2 alone (the
    paper's scheme) prints eq. 2's discrete equivalent, (exp(-4.15 dt) - 1) / dt = -3.82."""
    import sympy as sp

    p = sp.Symbol("p", real=True)
    rhs = sp.expand(model.equations["p_dot"].sympy.rhs)
    assert model.discovered.integrator == "rk4"
    assert float(rhs.coeff(p)) == pytest.approx(-4.15, rel=1e-3)
    euler = gpquad.fit(flight, seed=1, **{**FAST, "targets": ["p_dot"]}, integrator="euler")
    assert euler.discovered.integrator == "euler"
    discrete = (np.exp(-4.15 * 0.04) - 1.0) / 0.04
    assert float(sp.expand(euler.equations["p_dot"].sympy.rhs).coeff(p)) == pytest.approx(
        discrete, rel=2e-3
    )


def test_fit_is_the_run_path_bit_for_bit(flight, tmp_path, model):
    """gpquad.fit and `gpquad run` share one fit path: the same config and data give the
    same model.json bytes, and fit(run_dir=) writes the folder `gpquad run` writes."""
    path = tmp_path / "flight.csv"
    flight.to_csv(path, index=False, float_format="%.17g")
    cfg = config_from_dict(
        {
            "seed": 1,
            "data": {"files": [str(path)]},
            "evolution": {"iterations": 1, "input_taps": 1, "targets": ["p_dot", "q_dot"]},
        }
    )
    run_experiment(cfg, tmp_path / "run", progress=False)
    again = gpquad.fit(path, seed=1, run_dir=tmp_path / "api", **FAST)
    from_run = json.loads((tmp_path / "run" / "model.json").read_text())
    from_api = json.loads((tmp_path / "api" / "model.json").read_text())
    assert from_run["targets"] == from_api["targets"]
    assert again.discovered.to_dict()["targets"] == model.discovered.to_dict()["targets"]
    loaded = gpquad.load(tmp_path / "api")
    assert str(loaded) == str(again)


def test_score_predict_simulate_and_fly(model, other):
    score = model.score(other, horizon_s=7.0)
    assert list(score.index) == ["model", "zero"]
    assert score.loc["model", ["p", "q"]].max() < 1e-6 < score.loc["zero", ["p", "q"]].min()
    assert score.loc["model", "windows"] == 5 and score.loc["model", "diverged"] == 0
    pred = model.predict(other)
    assert list(pred.columns) == ["t", "flight", "p_dot", "q_dot"]
    flown = model.simulate(other, horizon_s=4.0)
    assert set(flown["window"]) == set(range(9)) and "p_data" in flown.columns
    assert np.abs(flown["p"] - flown["p_data"]).max() < 1e-9
    inputs = other[["t", *INPUTS]]
    trace = model.fly(inputs, {"phi": 0.01})
    assert len(trace) == len(other) and trace.loc[0, "phi"] == pytest.approx(0.01)
    # the columns are taken by name, not by position
    reordered = model.fly(inputs[["t", "u_T", "u_Y", "u_R", "u_P"]], {"phi": 0.01})
    assert np.array_equal(reordered.to_numpy(), trace.to_numpy())


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda m, d: m.fly(d[["u_P", "u_R", "u_Y"]]), r"lack the columns \['u_T'\]"),
        (lambda m, d: m.fly(d[["u_P", "u_R", "u_Y", "u_T"]].to_numpy()), "named"),
        (lambda m, d: m.fly(d.assign(t=d["t"] * 2)[["t", "u_P", "u_R", "u_Y", "u_T"]]), "dt"),
        (lambda m, d: m.fly(d[list(INPUTS)], {"alpha": 1.0}), "unknown states"),
        (lambda m, d: m.score(d, horizon_s=0.0), "horizon_s"),
        (lambda m, d: m.score(d.rename(columns={"u_T": "thrust"})), "u_T"),
        (lambda m, d: m.score([3]), "DataFrames"),
        (lambda m, d: m.export("pdf"), "unknown export format"),
    ],
)
def test_user_mistakes_are_one_line_errors(model, other, call, message):
    with pytest.raises(gpquad.GpquadError, match=message) as info:
        call(model, other)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"iteratons": 2}, "did you mean 'iterations'"),
        ({"targets": ["x_dot"]}, "unknown target"),
        ({"config": 3}, "config must be"),
        ({"config": "fastest"}, "config file not found"),
        ({"window_s": -1.0}, "window_s"),
    ],
)
def test_bad_settings_fail_before_any_work(flight, kwargs, message):
    with pytest.raises(gpquad.GpquadError, match=message):
        gpquad.fit(flight, **kwargs)


def test_config_forms_and_presets():
    from gpquad.api import _config

    assert _config(None) == Config()
    assert _config("paper").evolution.constant_fit == "none"
    assert _config("recommended") == config_from_dict({})
    assert gpquad.Config is Config


def test_read_log_gives_flights(tmp_path, flight):
    path = tmp_path / "f.csv"
    flight.to_csv(path, index=False, float_format="%.17g")
    flights = gpquad.read_log(path)
    assert len(flights) == 1 and flights[0].input_names == INPUTS
    assert np.allclose(flights[0].rates, flight[["p", "q", "r"]].to_numpy())
    with pytest.raises(gpquad.GpquadError, match="no such file"):
        gpquad.read_log(tmp_path / "missing.csv")


def test_help_documents_the_api():
    import pydoc

    text = pydoc.render_doc(gpquad.fit, renderer=pydoc.plaintext)
    for word in ("Parameters", "data", "config", "seed", "run_dir", "overrides", "Returns"):
        assert word in text
    for name in ("predict", "simulate", "score", "fly", "export"):
        assert getattr(gpquad.Model, name).__doc__


@pytest.mark.slow
def test_default_fit_recovers_the_six_equations_of_the_quickstart_flight():
    """gpquad.fit(df) with every default on the quickstart's simulated flight (a few
    minutes on 2 cores)."""
    df = gpquad.reference_flight()
    model = gpquad.fit(df, seed=1)
    dataset = build_dataset([flight_from_frame(df, INPUTS)], validation_fraction=0.15)
    assert all(
        compare_to_truth(model.discovered.equations[t], MEDIAN_MODEL[t], dataset)["passed"]
        for t in MEDIAN_MODEL
    )


EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "notebook_workflow.py"


def test_the_example_runs_from_dataframe_to_compiled_c(tmp_path):
    """examples/notebook_workflow.py, as a user copies it: fit, score, simulate, export C,
    compile, fly; the C model flies as model.fly does."""
    import importlib.util
    import shutil

    spec = importlib.util.spec_from_file_location("notebook_workflow", EXAMPLE)
    example = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(example)
    difference = example.main(tmp_path)
    if shutil.which("cc") or shutil.which("gcc"):
        assert difference < 1e-9
    else:
        pytest.skip("no C compiler: the export was written, not compiled")
    assert (tmp_path / "quad_model.h").is_file()


def test_time_left_leaves_out_the_first_iteration():
    """The first iteration compiles the kernels: the estimate starts after it."""
    import io

    from gpquad.study.search import Progress

    progress = Progress(True, 4, stream=io.StringIO())
    progress.done, progress.first = 1, 60.0
    assert progress.time_left(60.0) == "estimating"
    progress.done = 2
    assert progress.time_left(62.0) == "~4.0 s"  # 2 s per iteration, 2 to go; not 31 s each


def _blind(flight, states=("u", "v")):
    """The flight's dataset with `states` marked as not measured (a PX4 log without GPS)."""
    import dataclasses

    dataset = build_dataset([flight_from_frame(flight, INPUTS)], validation_fraction=0.15)
    info = [
        dict(f, measured={s: "not measured (no GPS)" for s in states}) for f in dataset.flight_info
    ]
    return dataclasses.replace(dataset, flight_info=info)


def test_targets_of_unmeasured_states_are_not_identified(flight, capsys):
    """A log without horizontal velocity: a_x and a_y are not searched (their placeholder
    values are no measurement), each left out with one warning, and the model says why
    in its text, Markdown and model.json; its flights take the log's a_x. The check can
    fail: on the measured dataset every target is searched and nothing is marked."""
    from gpquad.models.equations import DiscoveredModel
    from gpquad.study.fit import fit_dataset, measured_targets, unmeasured_notes

    cfg = config_from_dict(
        {
            "evolution": {
                "iterations": 1,
                "input_taps": 1,
                "targets": ["a_x", "a_y", "p_dot"],
                "finish": [],
            }
        }
    )
    measured = build_dataset([flight_from_frame(flight, INPUTS)], validation_fraction=0.15)
    assert unmeasured_notes(measured, ["a_x", "p_dot"]) is None
    assert measured_targets(cfg, measured) is cfg
    blind = _blind(flight)
    kept = measured_targets(cfg, blind)
    assert kept.evolution.targets == ("p_dot",)
    err = capsys.readouterr().err
    assert "a_x: not identified: the log does not measure u" in err and "p_dot" not in err

    seconds: dict = {}
    found = fit_dataset(blind, cfg, seconds=seconds)
    assert set(found.equations) == {"p_dot"} and set(seconds["search"]) == {"p_dot"}
    assert found.note("a_x") == "not identified: the log does not measure u"
    assert "a_x: not identified" in found.text() and "a_y: not identified" in found.text()
    assert "| a_x | - | - | - | not identified" in found.markdown()
    assert DiscoveredModel.from_dict(found.to_dict()).unmeasured == found.unmeasured
    start = blind.train[0][0] + 10
    flown = found.simulate(blind, np.array([start]), 50)
    logged = blind.arrays.states[start : start + 51, 3]
    # u follows the log's a_x (rotated by the flown attitude), not a fitted equation
    assert np.max(np.abs(flown[0, :, 3] - logged)) < 0.02 * np.max(np.abs(logged))

    whole = fit_dataset(measured, cfg)
    assert set(whole.equations) == {"a_x", "a_y", "p_dot"}
    assert "not identified" not in whole.text() + whole.markdown()


def test_whole_model_steps_run_without_the_unmeasured_targets(flight):
    """The stability repair and the joint refit fly the full model: they run on a model
    that lacks only the targets of unmeasured states (those fly the log's accelerations),
    and leave out a model that lacks a measured one (the check can fail: on the measured
    dataset the same model is partial)."""
    import dataclasses

    from gpquad.models.finish import finish_model
    from gpquad.models.joint_fit import is_whole
    from gpquad.study.fit import fit_dataset

    cfg = config_from_dict(
        {"evolution": {"iterations": 1, "input_taps": 1, "finish": ["repair", "joint_fit"]}}
    )
    blind = _blind(flight)
    found = fit_dataset(blind, cfg)
    assert set(found.equations) == {"a_z", "p_dot", "q_dot", "r_dot"}
    assert is_whole(found, blind) and found.stability is not None
    assert found.joint_fit is not None and found.joint_fit["states"] == ["w", "p", "q", "r"]
    measured = build_dataset([flight_from_frame(flight, INPUTS)], validation_fraction=0.15)
    bare = dataclasses.replace(found, stability=None, joint_fit=None)
    assert not is_whole(bare, measured)
    again = finish_model(bare, measured, cfg.evolution)
    assert again.stability is None and again.joint_fit is None


def test_a_fit_of_only_unmeasured_states_fails_before_searching(flight, capsys):
    """Every target's state unmeasured: one line naming evolution.targets, before any
    search (the check can fail: with p_dot among the targets the fit goes on)."""
    from gpquad.errors import GpquadError
    from gpquad.study.fit import measured_targets

    cfg = config_from_dict({"evolution": {"targets": ["a_x", "a_y"]}})
    with pytest.raises(GpquadError, match="evolution.targets"):
        measured_targets(cfg, _blind(flight))
    both = config_from_dict({"evolution": {"targets": ["a_x", "p_dot"]}})
    assert measured_targets(both, _blind(flight)).evolution.targets == ("p_dot",)


def test_fit_reports_where_its_time_went(model, tmp_path):
    """model.profile: each searched equation's seconds and each finishing step's, the same
    keys whether the fit kept a run folder or not."""
    assert set(model.profile["search"]) == set(FAST["targets"])
    assert set(model.profile["finish"]) == {"symmetrize", "refine", "repair", "joint_fit"}
    assert all(s > 0 for s in model.profile["search"].values())
    assert gpquad.Model(model.discovered).profile is None  # a loaded model was not timed here
    two = gpquad.fit(
        gpquad.reference_flight(seed=0, duration_s=40.0),
        seed=1,
        run_dir=tmp_path / "r",
        progress=False,
        **{**FAST, "targets": ["p_dot"]},
    )
    assert set(two.profile["search"]) == {"p_dot"} and set(two.profile["finish"]) <= {
        "symmetrize",
        "refine",
        "repair",
        "joint_fit",
    }
    run = json.loads((tmp_path / "r" / "run.json").read_text())
    assert run["search_phase_time_s"] == two.profile["phases"]


def test_a_search_profile_splits_its_time_into_phases(model):
    """Each search's phases (coevolution.PHASES): every phase the default engine runs is
    there and took time, and together they are most of the search's own seconds and not
    more (phases timed inside one another would add up to more than the search)."""
    from gpquad.engine.evolve.coevolution import PHASES
    from gpquad.study.runner import phase_profile

    phases = model.profile["phases"]
    assert set(phases) == set(FAST["targets"])
    for target, seconds in phases.items():
        assert set(seconds) == set(PHASES) and all(s > 0 for s in seconds.values())
        assert 0.5 * model.profile["search"][target] < sum(seconds.values())
        assert sum(seconds.values()) <= model.profile["search"][target]
    line = phase_profile(phases)
    assert line.startswith("searches, summed: ") and "final choice" in line


def test_parallel_searches_give_the_same_equations(flight):
    """jobs = 1 and jobs = 2 (two worker processes) give the same bits; jobs = 0 is refused."""
    one = gpquad.fit(flight, seed=3, jobs=1, **FAST)
    two = gpquad.fit(flight, seed=3, jobs=2, **FAST)
    assert one.discovered.to_dict()["targets"] == two.discovered.to_dict()["targets"]
    with pytest.raises(gpquad.GpquadError, match="jobs"):
        gpquad.fit(flight, jobs=0, **FAST)


def test_model_json_has_a_schema_and_old_files_load(model, tmp_path):
    """model.json says its layout; a file without one (gpquad 0.1) loads, a newer one is
    refused in one line."""
    import json

    from gpquad.models.equations import SCHEMA

    path = model.save(tmp_path)
    saved = json.loads(path.read_text())
    assert saved["schema"] == SCHEMA
    old = {k: v for k, v in saved.items() if k != "schema"}
    (tmp_path / "old").mkdir()
    (tmp_path / "old" / "model.json").write_text(json.dumps(old))
    assert str(gpquad.load(tmp_path / "old")) == str(model)
    (tmp_path / "new").mkdir()
    (tmp_path / "new" / "model.json").write_text(json.dumps({**saved, "schema": SCHEMA + 1}))
    with pytest.raises(gpquad.GpquadError, match="newer gpquad") as info:
        gpquad.load(tmp_path / "new")
    assert "\n" not in str(info.value)


def test_run_with_two_processes_writes_the_same_folder(tmp_path):
    """`gpquad run --jobs 2`: the same equations and history.csv bytes as one process, and
    a second command on the finished folder resumes every target from its record."""
    from gpquad.cli.commands import main

    cfg = tmp_path / "c.toml"
    cfg.write_text(
        'seed = 2\npreset = "paper"\n[simulator]\nduration_s = 40.0\n[evolution]\n'
        'targets = ["a_z", "p_dot", "q_dot"]\niterations = 1\nmodel_generations = 5\n'
        "test_generations = 2\nwindow_s = 2.4\nsimplify_generations = 2\n"
    )
    for jobs, out in ((1, "one"), (2, "two")):
        assert (
            main(
                [
                    "run",
                    str(cfg),
                    "--out",
                    str(tmp_path / out),
                    "--quiet",
                    "--no-figures",
                    "--jobs",
                    str(jobs),
                ]
            )
            == 0
        )
    one, two = (json.loads((tmp_path / o / "model.json").read_text()) for o in ("one", "two"))
    assert one["targets"] == two["targets"]
    assert (tmp_path / "one" / "history.csv").read_bytes() == (
        tmp_path / "two" / "history.csv"
    ).read_bytes()
    assert (
        main(
            [
                "run",
                str(cfg),
                "--out",
                str(tmp_path / "two"),
                "--quiet",
                "--no-figures",
                "--jobs",
                "2",
            ]
        )
        == 0
    )
    assert json.loads((tmp_path / "two" / "model.json").read_text())["targets"] == one["targets"]
    assert main(["run", str(cfg), "--out", str(tmp_path / "x"), "--jobs", "0"]) == 2
