"""Scenario registry: the rotorpy scenarios through a stand-in generator module, and their
skip when the generator or rotorpy is missing."""

import dataclasses
import sys
import types

import numpy as np
import pytest

from gpquad.benchmark import scenarios
from gpquad.data.flight import write_flight_file
from gpquad.data.simulator import simulate
from gpquad.study.config import SimulatorConfig

INPUTS = ("u_P", "u_R", "u_Y", "u_T")


#: vehicle b's roll loop differs from vehicle a's (the median model's 10.3 u_R(t-1) - 4.15 p)
OTHER_ROLL = "20.0*u_R(t-1) - 8.0*p"


def _fake_module(tmp_path, calls):
    """Stands in for gpquad.benchmark.rotorpy_flights: two vehicles a and b whose roll
    equations differ, 2 training, 1 validation and 1 test flight each."""

    def ensure_flights(mode, noisy, cache_dir, fleet="tuned", **scale):
        calls.append(
            (mode, noisy, str(cache_dir))
            + (() if fleet == "tuned" else (fleet,))
            + tuple(scale.values())
        )
        paths, flights = {"train": [], "validation": [], "test": []}, []
        for vehicle in ("a", "b"):
            sim = SimulatorConfig(duration_s=20.0)
            if vehicle == "b":
                sim = dataclasses.replace(sim, equations={**sim.equations, "p_dot": OTHER_ROLL})
            for part, seeds in (("train", (1, 2)), ("validation", (3,)), ("test", (4,))):
                for s in seeds:
                    path = write_flight_file(
                        simulate(dataclasses.replace(sim, seed=s), INPUTS),
                        tmp_path / f"{vehicle}_{part}{s}.parquet",
                    )
                    paths[part].append(path)
                    flights.append({"path": str(path), "vehicle": vehicle, "role": part, "seed": s})
        return {
            **paths,
            "input_names": INPUTS,
            "config": {"format": "generic", "trim": "none", "inputs": list(INPUTS)},
            "vehicles": ["a", "b"],
            "seeds": [1, 2, 3, 4],
            "flights": flights,
        }

    module = types.ModuleType("gpquad.benchmark.rotorpy_flights")
    module.ensure_flights = ensure_flights
    return module


def test_rotorpy_scenario_is_fitted_per_vehicle(tmp_path, monkeypatch):
    calls = []
    monkeypatch.setitem(
        sys.modules, "gpquad.benchmark.rotorpy_flights", _fake_module(tmp_path, calls)
    )
    sc = scenarios.build_scenario("rotorpy-angle-noisy", tmp_path / "cache")
    assert calls == [("angle", True, str(tmp_path / "cache"))]
    assert sc.name == "rotorpy-angle-noisy" and sc.truth is None
    assert list(sc.groups) == ["a", "b"]
    for g in sc.groups.values():
        assert len(g.fit.train) == 2 and len(g.fit.validation) == 1
        assert g.fit.n_samples == 1500 and g.test.n_samples == 500
        assert g.test.validation == [(0, 500)] and g.test.trim == g.fit.trim
    assert sc.test.n_samples == 1000 and sc.group_offsets() == {"a": (0, 500), "b": (500, 1000)}
    assert sc.source["vehicles"] == ["a", "b"] and sc.source["fitted"] == "per vehicle"

    # OLS holds both vehicles' equations exactly, so fitted per vehicle and flown on each
    # vehicle's own test flight it reproduces the data; one model of both vehicles cannot.
    from gpquad.benchmark import cells, evaluate

    simulate, _, record = cells._fit("ols", sc, 0, tmp_path)
    assert set(record["equations"]) == {"a", "b"}
    per_vehicle = evaluate.score(simulate, sc.test, sc.measured, (2.0,))["2s"]
    pooled = dataclasses.replace(sc, groups={})
    simulate, _, _ = cells._fit("ols", pooled, 0, tmp_path)
    one_model = evaluate.score(simulate, sc.test, sc.measured, (2.0,))["2s"]
    assert per_vehicle["windows"] == one_model["windows"] > 0
    assert per_vehicle["rse"]["p"] < 1e-12 < 1e-4 < one_model["rse"]["p"]


def test_rotorpy_scenario_is_skipped_when_generator_or_rotorpy_missing(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "gpquad.benchmark.rotorpy_flights", None)
    with pytest.raises(scenarios.Skipped, match="rotorpy_flights unavailable"):
        scenarios.build_scenario("rotorpy-rate", tmp_path)
    module = types.ModuleType("gpquad.benchmark.rotorpy_flights")

    def no_rotorpy(mode, noisy, cache_dir, fleet="tuned"):
        raise ModuleNotFoundError("No module named 'rotorpy'")

    module.ensure_flights = no_rotorpy
    monkeypatch.setitem(sys.modules, "gpquad.benchmark.rotorpy_flights", module)
    with pytest.raises(scenarios.Skipped, match="rotorpy is not installed"):
        scenarios.build_scenario("rotorpy-rate", tmp_path)


def test_unknown_scenario_is_a_user_error(tmp_path):
    from gpquad.errors import GpquadError

    with pytest.raises(GpquadError, match="unknown scenario"):
        scenarios.build_scenario("median-loud", tmp_path)


def test_every_rotorpy_scenario_asks_for_its_mode_and_noise(tmp_path, monkeypatch):
    calls = []
    monkeypatch.setitem(
        sys.modules, "gpquad.benchmark.rotorpy_flights", _fake_module(tmp_path, calls)
    )
    names = (
        "rotorpy-angle",
        "rotorpy-angle-noisy",
        "rotorpy-rate",
        "rotorpy-rate-noisy",
        "rotorpy-heldout-angle",
        "rotorpy-heldout-angle-noisy",
        "rotorpy-heldout-rate",
        "rotorpy-heldout-rate-noisy",
    )
    for name in names:
        assert name in scenarios.SCENARIOS
        assert scenarios.build_scenario(name, tmp_path / "cache").source.get("fleet") == (
            "heldout" if "heldout" in name else None
        )
    assert [(c[0], c[1]) + c[3:] for c in calls] == [
        ("angle", False),
        ("angle", True),
        ("rate", False),
        ("rate", True),
        ("angle", False, "heldout"),
        ("angle", True, "heldout"),
        ("rate", False, "heldout"),
        ("rate", True, "heldout"),
    ]


@pytest.mark.skipif(
    not (scenarios.repo_root().parent / "shared" / "data" / "betaflight").is_dir(),
    reason="../shared/data/betaflight is not present",
)
def test_betaflight_scenario_tests_on_another_flight(tmp_path):
    """betaflight-gecko: every training segment comes from btfl_002.bbl, every test segment
    from btfl_all.bbl (the config's data.validation file, another flight of the quad), and
    only the gyro's p, q, r are measured."""
    scenario = scenarios.build_scenario("betaflight-gecko", tmp_path)
    assert scenario.fit.n_samples > 1000 and scenario.test.n_samples > 1000
    assert {info["name"].split(".")[0] for info in scenario.fit.flight_info} == {"btfl_002"}
    assert {info["name"].split(".")[0] for info in scenario.test.flight_info} == {"btfl_all"}
    assert scenario.measured == {
        "u": False,
        "v": False,
        "w": False,
        "p": True,
        "q": True,
        "r": True,
    }


def test_user_config_with_validation_files_tests_on_them(tmp_path):
    """A user's config that holds b.parquet out whole (data.validation) is tested on b
    alone and trained on a alone; before, each file's last validation_fraction tested."""
    for name, seed in (("a", 1), ("b", 2)):
        write_flight_file(
            simulate(SimulatorConfig(duration_s=30.0, seed=seed), INPUTS),
            tmp_path / f"{name}.parquet",
        )
    config = tmp_path / "mine.toml"
    config.write_text(
        'name = "mine"\nseed = 1\n[data]\nfiles = ["a.parquet"]\n'
        'validation = ["b.parquet"]\ntrim = "none"\n'
    )
    scenario = scenarios.user_scenario(config)
    assert [f["name"] for f in scenario.fit.flight_info] == ["a.parquet"]
    assert [f["name"] for f in scenario.test.flight_info] == ["b.parquet"]
    assert scenario.fit.n_samples == scenario.test.n_samples == 750


def test_named_log_scenario_without_its_log_is_skipped(tmp_path, monkeypatch):
    """A clone without ../shared/data skips px4-s250 and betaflight-gecko (as it skips the
    rotorpy scenarios without rotorpy) instead of stopping the whole benchmark; a user's own
    config with a missing file stays an error."""
    config = tmp_path / "experiments" / "px4_s250.toml"
    config.parent.mkdir()
    config.write_text(
        'name = "x"\nseed = 1\n[data]\nfiles = ["nowhere/S250"]\nformat = "px4-csv"\n'
    )
    monkeypatch.setattr(scenarios, "repo_root", lambda: tmp_path)
    with pytest.raises(scenarios.Skipped, match="not on this machine"):
        scenarios.build_scenario("px4-s250", tmp_path)
    from gpquad.errors import GpquadError

    config.write_text(config.read_text() + 'validation = ["nowhere/other"]\n')
    with pytest.raises(GpquadError):
        scenarios.user_scenario(config)


def test_noise_family_and_third_vehicle_ask_for_their_fleet_and_noise_multiple(
    tmp_path, monkeypatch
):
    """The 2x and 4x noise family exists for the tuned fleet, the third vehicle (px4sih) and
    the median simulator, not for the held-out fleet or rigid-body; each rotorpy member asks
    the generator for its fleet and noise multiple and records the multiple."""
    calls = []
    monkeypatch.setitem(
        sys.modules, "gpquad.benchmark.rotorpy_flights", _fake_module(tmp_path, calls)
    )
    family = [n for n in scenarios.SCENARIOS if n.endswith(("-noisy2x", "-noisy4x"))]
    assert sorted(family) == sorted(
        f"{base}-noisy{k}x"
        for base in (
            "median",
            "rotorpy-angle",
            "rotorpy-rate",
            "rotorpy-px4sih-angle",
            "rotorpy-px4sih-rate",
        )
        for k in (2, 4)
    )
    for base in ("rotorpy-px4sih-angle", "rotorpy-px4sih-rate"):
        assert base in scenarios.SCENARIOS and f"{base}-noisy" in scenarios.SCENARIOS
    expected = {
        "rotorpy-angle-noisy2x": ("angle", True, 2),
        "rotorpy-rate-noisy4x": ("rate", True, 4),
        "rotorpy-px4sih-angle": ("angle", False, "px4sih"),
        "rotorpy-px4sih-rate-noisy": ("rate", True, "px4sih"),
        "rotorpy-px4sih-angle-noisy4x": ("angle", True, "px4sih", 4),
    }
    for name, call in expected.items():
        sc = scenarios.build_scenario(name, tmp_path / "cache")
        assert (calls[-1][0], calls[-1][1]) + calls[-1][3:] == call, name
        assert sc.source.get("noise_scale") == (call[-1] if call[-1] in (2, 4) else None)


def _short_median():
    from gpquad.study.config import Config

    cfg = Config()
    return dataclasses.replace(cfg, simulator=dataclasses.replace(cfg.simulator, duration_s=20.0))


def test_median_noise_family_is_exactly_2x_and_4x_the_benchmark_noise(tmp_path, monkeypatch):
    """median-noisy2x / 4x fly median-noisy's flights with every noise SD doubled or
    quadrupled (exactly, not approximately), and the noise itself scales: the same standard
    normals times 2 or 4 on top of the same clean flight."""
    monkeypatch.setattr(scenarios, "TEST_DURATION_S", 20.0)
    cfg = _short_median()
    built = {k: scenarios._simulated(f"m{k}", cfg, k) for k in (0, 1, 2, 4)}
    for k in (2, 4):
        assert built[k].source["measurement_noise"] == {
            s: k * sd for s, sd in scenarios.NOISE.items()
        }
    assert built[0].source["measurement_noise"] == {}
    # the scenarios' own test flights: the same clean flight plus k times the same noise
    moving = {k: sc.test.arrays.states[:, 3:9] for k, sc in built.items()}
    base = moving[1] - moving[0]
    assert np.std(base[:, :3]) == pytest.approx(scenarios.NOISE["velocity"], rel=0.1)
    for k in (2, 4):
        np.testing.assert_allclose(moving[k] - moving[0], k * base, rtol=1e-9, atol=1e-12)
    # the bad case: 2x's flights are not median-noisy's
    assert not np.allclose(moving[2] - moving[0], base, rtol=1e-9, atol=1e-12)


def test_motor_level_scenario_is_configured_with_the_four_motors_and_skipped_without_log(
    tmp_path, monkeypatch
):
    """betaflight-gecko-motors: its config's inputs are the four motor outputs (the reader's
    names), with no left-right mirror (it would swap motors, not flip signs); the scenario is
    skipped, not an error, where the log is not on this machine."""
    from gpquad.study.config import load_config

    path = scenarios.repo_root() / "experiments" / scenarios.LOGS["betaflight-gecko-motors"]
    cfg = load_config(path)
    assert cfg.data.format == "betaflight"
    assert tuple(cfg.data.inputs) == ("motor_0", "motor_1", "motor_2", "motor_3")
    assert cfg.vehicle.flipped(cfg.data.inputs) == () and not cfg.vehicle.symmetric
    assert set(cfg.evolution.targets) == {"p_dot", "q_dot", "r_dot"}
    (tmp_path / "experiments").mkdir()
    (tmp_path / "experiments" / path.name).write_text(path.read_text())
    monkeypatch.setattr(scenarios, "repo_root", lambda: tmp_path / "repo")
    (tmp_path / "repo").mkdir()
    (tmp_path / "repo" / "experiments").symlink_to(tmp_path / "experiments")
    with pytest.raises(scenarios.Skipped, match="betaflight-gecko-motors: its log .* is not"):
        scenarios.build_scenario("betaflight-gecko-motors", tmp_path)


@pytest.mark.skipif(
    not (scenarios.repo_root().parent / "shared" / "data" / "betaflight").is_dir(),
    reason="../shared/data/betaflight is not present",
)
def test_motor_level_scenario_reads_four_motor_inputs(tmp_path):
    scenario = scenarios.build_scenario("betaflight-gecko-motors", tmp_path)
    names = ("motor_0", "motor_1", "motor_2", "motor_3")
    assert scenario.fit.input_names == names and scenario.test.input_names == names
    assert set(scenario.fit.trim) == set(names)  # each motor relative to its training mean
    assert 0.05 < min(scenario.fit.trim.values()) < max(scenario.fit.trim.values()) < 0.6
    assert {info["name"].split(".")[0] for info in scenario.test.flight_info} == {"btfl_all"}
    assert [k for k, v in scenario.measured.items() if v] == ["p", "q", "r"]
