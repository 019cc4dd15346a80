"""The coevolution engine: windows, suite, determinism, run folders and the CLI."""

import dataclasses
import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gpquad.cli.commands import main
from gpquad.engine.evolve.coevolution import Coevolution, disagreement
from gpquad.engine.evolve.windows import WindowSpace, tile
from gpquad.engine.tree.operators import VAR_BASE
from gpquad.engine.tree.random_stream import RandomStream
from gpquad.models.equations import DiscoveredModel
from gpquad.study.config import Config, DataConfig, SimulatorConfig, preset_evolution
from gpquad.study.runner import run_experiment

TINY = preset_evolution(
    targets=("p_dot",),
    iterations=2,
    model_generations=15,
    test_generations=5,
    window_s=2.4,
    simplify_generations=5,
)


def tiny_config(**evolution) -> Config:
    sim = dataclasses.replace(SimulatorConfig(), duration_s=40.0)
    return Config(
        seed=3,
        simulator=sim,
        data=DataConfig(trim="mean"),
        evolution=dataclasses.replace(TINY, **evolution),
    )


def test_windows_never_span_flights_or_the_split():
    ranges = [(0, 100), (100, 180), (180, 400)]
    space = WindowSpace(ranges, n_steps=70, max_delay=5)
    starts = space.starts(np.arange(space.size))
    for s in starts:
        inside = [a + 5 <= s and s + 70 <= b - 1 for a, b in ranges]
        assert sum(inside) == 1
    # every valid start is reachable exactly once
    # starts 5..29, 105..109 and 185..329
    assert len(set(starts.tolist())) == space.size == 25 + 5 + 145
    rng = np.random.default_rng(0)
    mutated = space.mutate(rng, space.random(rng, 50), 1000)
    assert ((mutated >= 0) & (mutated < space.size)).all()
    tiles, steps = tile(ranges, 70, 5)
    assert steps == 70 and all(
        any(a + 5 <= s and s + 70 <= b - 1 for a, b in ranges) for s in tiles
    )


def test_window_space_refuses_short_data():
    from gpquad.errors import GpquadError

    with pytest.raises(GpquadError, match="window_s"):
        WindowSpace([(0, 50)], n_steps=750, max_delay=5)


def test_suite_insertion_replaces_overlapping_then_oldest(short_dataset):
    co = Coevolution(short_dataset, "p_dot", dataclasses.replace(TINY, suite_size=3))
    state = co.init_state(0)
    state.suite[:] = [100, 400, 700]
    state.suite_age[:] = [0, 1, 2]
    state.inserted = 3
    co.insert_test(state, 430)  # overlaps 400
    assert state.suite.tolist() == [100, 430, 700]
    co.insert_test(state, 1000)  # overlaps none: replaces the oldest (100)
    assert state.suite.tolist() == [1000, 430, 700]


def test_test_fitness_is_variance_with_diverged_models_capped():
    errors = np.array([[1.0, 1.0], [3.0, np.inf]])
    f = disagreement(errors)
    assert f[0] == pytest.approx(1.0)
    assert f[1] == pytest.approx(np.var([1.0, 6.0]))


def test_hill_climbers_never_get_worse(short_dataset):
    co = Coevolution(short_dataset, "p_dot", TINY)
    state = co.init_state(1)
    rng = RandomStream(np.random.default_rng(2))
    before = co.evaluator.mean_errors(state.models, state.suite)
    co.model_phase(state, rng)
    after = co.evaluator.mean_errors(state.models, state.suite)
    assert (after <= before + 1e-15).all()
    best = [row["best_suite_error"] for row in state.history]
    assert all(b2 <= b1 for b1, b2 in zip(best, best[1:]))


def test_same_seed_same_model_json(tmp_path):
    cfg = tiny_config(targets=("p_dot", "a_x"))
    run_experiment(cfg, tmp_path / "a", progress=False)
    run_experiment(cfg, tmp_path / "b", progress=False)
    a = (tmp_path / "a" / "model.json").read_bytes()
    assert a == (tmp_path / "b" / "model.json").read_bytes()
    other = run_experiment(dataclasses.replace(cfg, seed=4), tmp_path / "c", progress=False)
    assert json.loads(a)["targets"] != other.to_dict()["targets"]


def test_run_folder_contents(tmp_path):
    model = run_experiment(tiny_config(), tmp_path / "run", progress=False)
    run = tmp_path / "run"
    for name in (
        "model.json",
        "equations.tex",
        "equations.md",
        "history.csv",
        "run.json",
        "config.json",
    ):
        assert (run / name).is_file(), name
    info = json.loads((run / "run.json").read_text())
    assert info["seed"] == 3 and "numba" in info["versions"] and info["git_revision"]
    data = json.loads((run / "model.json").read_text())
    p_dot = data["targets"]["p_dot"]
    assert set(p_dot) >= {"expr", "delays", "error", "validation_error"}
    assert np.isfinite(p_dot["validation_error"])
    from gpquad.engine.tree.arithmetic import parse_in_symbols

    parse_in_symbols(p_dot["expr"], None)  # parsable by the equations' own parser
    front = p_dot["candidates"]  # size/error Pareto front: bigger only if more accurate
    assert front and all(
        a["size"] < b["size"] and a["error"] > b["error"] for a, b in zip(front, front[1:])
    )
    assert front[-1]["error"] == pytest.approx(p_dot["error"])  # no pruning: the best climber
    history = (run / "history.csv").read_text().splitlines()
    assert len(history) == 1 + TINY.iterations * TINY.model_generations
    loaded = DiscoveredModel.load(run)
    assert (
        loaded.equations["p_dot"].tree.codes.tolist()
        == model.equations["p_dot"].tree.codes.tolist()
    )


def test_model_simulate_reproduces_the_data_with_the_true_equations(short_dataset):
    """A DiscoveredModel holding the simulator's equations flies the data back exactly."""
    from gpquad.engine.tree.export import from_sympy, parse_equation
    from gpquad.models.equations import Equation
    from gpquad.study.config import MEDIAN_MODEL

    trim = short_dataset.trim
    eqs = {}
    for target, text in MEDIAN_MODEL.items():
        expr, delays = parse_equation(text, short_dataset.input_names)
        expr = expr.subs({s: s + trim[str(s)] for s in expr.free_symbols if str(s) in trim})
        eqs[target] = Equation(
            target,
            from_sympy(expr, delays, short_dataset.input_names),
            short_dataset.input_names,
            0.0,
            0.0,
            trim,
        )
    model = DiscoveredModel(eqs, short_dataset.input_names, trim, short_dataset.dt, 0, {})
    starts = np.array([20, 500], dtype=np.int64)
    states = model.simulate(short_dataset, starts, 300)
    truth = np.stack([short_dataset.arrays.states[s : s + 301] for s in starts])
    assert np.abs(states - truth).max() < 1e-8


def test_cli_run_and_errors(tmp_path, capsys):
    cfg = tmp_path / "exp.toml"
    cfg.write_text(
        'seed = 2\npreset = "paper"\n[simulator]\nduration_s = 40.0\n[evolution]\n'
        'targets = ["r_dot"]\niterations = 1\nmodel_generations = 5\n'
        "test_generations = 2\nwindow_s = 2.4\n"
        "simplify_generations = 2\n"
    )
    out = tmp_path / "run"
    assert main(["run", str(cfg), "--out", str(out), "--quiet"]) == 0
    assert "r_dot =" in capsys.readouterr().out
    assert (out / "model.json").is_file()
    assert main(["export", str(out), "--format", "latex"]) == 0
    assert "\\dot{r}" in capsys.readouterr().out
    # bad input: one line on stderr, exit code 2, no traceback
    assert main(["run", str(cfg), "--data", str(tmp_path / "none.csv")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("gpquad: error:") and "none.csv" in err and "\n" not in err
    bad = tmp_path / "bad.toml"
    bad.write_text("[evolution]\nwindow_step = 3\n")
    assert main(["run", str(bad)]) == 2
    assert "evolution.window_step" in capsys.readouterr().err


def test_interrupt_writes_partial_results_and_the_same_command_resumes(tmp_path, monkeypatch):
    from gpquad.engine.evolve import coevolution

    cfg = tiny_config(targets=("p_dot", "a_y", "r_dot"))
    reference = run_experiment(cfg, tmp_path / "straight", progress=False)

    calls = {"n": 0}
    original = coevolution.Coevolution.iterate

    def iterate_then_interrupt(self, state):
        calls["n"] += 1
        if calls["n"] == 4:  # second iteration of the second target
            raise KeyboardInterrupt
        return original(self, state)

    monkeypatch.setattr(coevolution.Coevolution, "iterate", iterate_then_interrupt)
    with pytest.raises(KeyboardInterrupt):
        run_experiment(cfg, tmp_path / "run", progress=False)
    data = json.loads((tmp_path / "run" / "model.json").read_text())
    assert data["interrupted"] is True and set(data["targets"]) == {"p_dot", "a_y"}
    monkeypatch.setattr(coevolution.Coevolution, "iterate", original)
    calls["n"] = 0
    resumed = run_experiment(cfg, tmp_path / "run", progress=False)
    for name in ("model.json", "history.csv", "equations.tex"):
        assert (tmp_path / "run" / name).read_bytes() == (
            tmp_path / "straight" / name
        ).read_bytes(), name
    assert resumed.to_dict() == reference.to_dict()
    # a different config in the same folder is refused, not mixed
    from gpquad.errors import GpquadError

    with pytest.raises(GpquadError, match="different config"):
        run_experiment(dataclasses.replace(cfg, seed=99), tmp_path / "run", progress=False)


def test_cli_simulate_then_run_on_the_file(tmp_path, capsys):
    cfg = tmp_path / "exp.toml"
    cfg.write_text(
        'seed = 5\npreset = "paper"\n[simulator]\nduration_s = 40.0\n[evolution]\n'
        'targets = ["q_dot"]\niterations = 1\nmodel_generations = 5\n'
        "test_generations = 2\nwindow_s = 2.4\n"
        "simplify_generations = 2\n"
    )
    flight = tmp_path / "flight.parquet"
    assert main(["simulate", str(cfg), "--out", str(flight)]) == 0
    assert "1000 samples at 25 Hz" in capsys.readouterr().out
    assert (
        main(["run", str(cfg), "--data", str(flight), "--out", str(tmp_path / "run"), "--quiet"])
        == 0
    )
    info = json.loads((tmp_path / "run" / "run.json").read_text())
    assert info["dataset"]["flights"] == ["flight.parquet"]
    assert info["dataset"]["train_samples"] + info["dataset"]["validation_samples"] == 1000


def test_fly_reproduces_the_simulator_with_the_true_equations(short_flight, tmp_path):
    """DiscoveredModel.fly with the simulator's own equations and inputs gives its flight."""
    from gpquad.data.flight import write_flight_file
    from gpquad.engine.tree.export import from_sympy, parse_equation
    from gpquad.models.equations import Equation
    from gpquad.study.config import MEDIAN_MODEL
    from gpquad.study.store import write_json

    names = short_flight.input_names
    eqs = {}
    for target, text in MEDIAN_MODEL.items():
        expr, delays = parse_equation(text, names)
        eqs[target] = Equation(target, from_sympy(expr, delays, names), names, 0.0, 0.0, {})
    model = DiscoveredModel(eqs, names, {}, short_flight.dt, 0, {})
    flown = model.fly(short_flight.inputs)
    assert np.abs(flown.vel - short_flight.vel).max() < 1e-9
    assert np.abs(flown.rates - short_flight.rates).max() < 1e-9
    assert np.abs(flown.pos - short_flight.pos).max() < 1e-9
    # the same through the command line
    write_json(tmp_path / "run" / "model.json", model.to_dict())
    write_flight_file(short_flight, tmp_path / "inputs.csv")
    out = tmp_path / "flown.csv"
    assert (
        main(
            [
                "fly",
                str(tmp_path / "run"),
                "--inputs",
                str(tmp_path / "inputs.csv"),
                "--out",
                str(out),
            ]
        )
        == 0
    )
    from gpquad.data.flight import read_flight_file

    again = read_flight_file(out, names)
    assert np.abs(again.vel - short_flight.vel).max() < 1e-9
    assert (
        main(
            [
                "fly",
                str(tmp_path / "run"),
                "--inputs",
                str(tmp_path / "none.csv"),
                "--out",
                str(out),
            ]
        )
        == 2
    )


def test_report_of_a_run_folder(tmp_path):
    from gpquad.report.builder import make_report

    run_experiment(tiny_config(targets=("p_dot", "a_y")), tmp_path / "run", progress=False)
    written = make_report(tmp_path / "run", formats=("png",))
    names = sorted(p.name for p in written)
    assert names == ["convergence.png", "prediction.png"]
    for p in written:
        assert p.read_bytes()[:4] == b"\x89PNG" and p.stat().st_size > 20_000


def test_no_validation_data_gives_null_not_nan(tmp_path):
    cfg = dataclasses.replace(tiny_config(), data=DataConfig(validation_fraction=0.0))
    run_experiment(cfg, tmp_path / "run", progress=False)
    text = (tmp_path / "run" / "model.json").read_text()
    assert "NaN" not in text  # strict JSON for other tools
    assert json.loads(text)["targets"]["p_dot"]["validation_error"] is None
    assert np.isnan(DiscoveredModel.load(tmp_path / "run").equations["p_dot"].validation_error)


def test_damaged_checkpoint_restarts_that_target(tmp_path, monkeypatch, capsys):
    from gpquad.engine.evolve import coevolution

    cfg = tiny_config(targets=("p_dot", "a_y"))
    run_experiment(cfg, tmp_path / "straight", progress=False)
    original = coevolution.Coevolution.iterate
    calls = {"n": 0}

    def iterate_then_interrupt(self, state):
        calls["n"] += 1
        if calls["n"] == 4:
            raise KeyboardInterrupt
        return original(self, state)

    monkeypatch.setattr(coevolution.Coevolution, "iterate", iterate_then_interrupt)
    with pytest.raises(KeyboardInterrupt):
        run_experiment(cfg, tmp_path / "run", progress=False)
    ckpt = tmp_path / "run" / "checkpoints" / "a_y.ckpt"
    ckpt.write_bytes(ckpt.read_bytes()[:50])  # truncated, as by a crash mid-copy
    monkeypatch.setattr(coevolution.Coevolution, "iterate", original)
    run_experiment(cfg, tmp_path / "run", progress=False)
    assert "restarting a_y" in capsys.readouterr().err
    for name in ("model.json", "history.csv"):
        assert (tmp_path / "run" / name).read_bytes() == (
            tmp_path / "straight" / name
        ).read_bytes(), name


@pytest.mark.parametrize("prune_tolerance", [0.0, 0.5])
def test_reported_equation_is_not_beaten_by_a_candidate_of_the_run(tmp_path, prune_tolerance):
    """A heavy prune (0.5 of a constant model's error) makes the pruned equation worse than
    smaller climbers on the front; the run then reports the better candidate instead."""
    cfg = tiny_config(targets=("p_dot", "a_z"), iterations=2, prune_tolerance=prune_tolerance)
    model = run_experiment(cfg, tmp_path / "run", progress=False)
    for eq in model.equations.values():
        size = eq.tree.size
        beaten = [
            c for c in eq.candidates if c["size"] <= size and c["error"] < eq.error * (1 - 1e-12)
        ]
        assert beaten == [], (eq.text(), beaten)


def test_unmeasured_states_are_never_leaves(short_flight):
    """A log that does not measure u and v (PX4 without GPS) keeps them out of every tree."""
    from gpquad.data.dataset import build_dataset
    from gpquad.engine.evolve.coevolution import Coevolution
    from gpquad.engine.variables import terminal_names

    flight = dataclasses.replace(
        short_flight,
        meta={**short_flight.meta, "measured": {"u": "not measured (test)", "v": "not measured"}},
    )
    dataset = build_dataset([flight], validation_fraction=0.2, trim="mean")
    assert dataset.unmeasured("u") and not dataset.unmeasured("w")
    co = Coevolution(dataset, "p_dot", TINY)
    names = terminal_names(dataset.input_names)
    allowed = {names[i] for i in co.params.variables}
    assert allowed == set(names) - {"u", "v"} and "w" in allowed and "u_R" in allowed
    state = co.init_state(np.random.SeedSequence(1))
    co.iterate(state)
    read = {names[c - VAR_BASE] for t in state.models for c in t.codes[: t.size] if c >= VAR_BASE}
    assert read and not read & {"u", "v"}
    # the same data with every state measured offers all of them
    assert (
        Coevolution(
            build_dataset([short_flight], validation_fraction=0.2, trim="mean"), "p_dot", TINY
        ).params.variables
        is None
    )


def test_excluded_leaves_are_never_read_and_unknown_names_are_refused(short_dataset):
    from gpquad.engine.evolve.coevolution import Coevolution
    from gpquad.engine.variables import terminal_names
    from gpquad.errors import GpquadError
    from gpquad.study.config import config_from_dict

    co = Coevolution(short_dataset, "r_dot", dataclasses.replace(TINY, exclude_leaves=("psi",)))
    names = terminal_names(short_dataset.input_names)
    assert "psi" not in {names[i] for i in co.params.variables}
    state = co.init_state(np.random.SeedSequence(2))
    co.iterate(state)
    assert all(names.index("psi") + VAR_BASE not in t.codes[: t.size] for t in state.models)
    with pytest.raises(GpquadError, match=r"exclude_leaves\[0\]"):
        config_from_dict({"evolution": {"exclude_leaves": ["heading"]}})


@settings(max_examples=200, deadline=None)
@given(
    st.lists(
        st.one_of(
            st.floats(0.0, 1e6, allow_nan=False),
            st.just(float("inf")),
            st.just(float("nan")),
        ),
        min_size=1,
        max_size=20,
    )
)
def test_median_is_numpys_median_to_the_bit(values):
    """The generations' median of the climbers' errors is np.median's, inf and NaN alike."""
    from gpquad.engine.evolve.coevolution import median

    a = np.array(values)
    want = float(np.median(a))
    got = median(a)
    assert (got == want) or (np.isnan(got) and np.isnan(want))
