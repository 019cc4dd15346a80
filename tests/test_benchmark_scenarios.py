"""Scenario registry: the rotorpy scenarios through a stand-in generator module, and their
skip when the generator or rotorpy is missing."""

import dataclasses
import sys
import types

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

    def ensure_flights(mode, noisy, cache_dir, fleet="tuned"):
        calls.append((mode, noisy, str(cache_dir)) + (() if fleet == "tuned" else (fleet,)))
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
