"""Scenario registry: the rotorpy scenarios through a stand-in generator module, and their
skip when the generator or rotorpy is missing."""

import sys
import types

import pytest

from gpquad.benchmark import scenarios
from gpquad.data.flight import write_flight_file
from gpquad.data.simulator import simulate
from gpquad.study.config import SimulatorConfig

INPUTS = ("u_P", "u_R", "u_Y", "u_T")


def _fake_module(tmp_path, calls):
    """Stands in for gpquad.benchmark.rotorpy_flights (written on another branch)."""
    def ensure_flights(mode, noisy, cache_dir):
        calls.append((mode, noisy, str(cache_dir)))
        paths = {}
        for part, seeds in (("train", (1, 2)), ("validation", (3,)), ("test", (4,))):
            paths[part] = [write_flight_file(simulate(SimulatorConfig(duration_s=20.0, seed=s),
                                                      INPUTS), tmp_path / f"{part}{s}.parquet")
                           for s in seeds]
        return {**paths, "input_names": INPUTS, "config": {"format": "generic", "trim": "mean",
                                                          "inputs": list(INPUTS)},
                "vehicles": ["a", "b"], "seeds": [1, 2, 3, 4]}

    module = types.ModuleType("gpquad.benchmark.rotorpy_flights")
    module.ensure_flights = ensure_flights
    return module


def test_rotorpy_scenario_reads_the_generators_flights(tmp_path, monkeypatch):
    calls = []
    monkeypatch.setitem(sys.modules, "gpquad.benchmark.rotorpy_flights",
                        _fake_module(tmp_path, calls))
    sc = scenarios.build_scenario("rotorpy-angle-noisy", tmp_path / "cache")
    assert calls == [("angle", True, str(tmp_path / "cache"))]
    assert sc.name == "rotorpy-angle-noisy" and sc.truth is None
    assert len(sc.fit.train) == 2 and len(sc.fit.validation) == 1
    assert sc.fit.n_samples == 1500 and sc.test.n_samples == 500
    assert sc.test.validation == [(0, 500)] and sc.test.trim == sc.fit.trim
    assert sc.source["vehicles"] == ["a", "b"]


def test_rotorpy_scenario_is_skipped_when_generator_or_rotorpy_missing(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "gpquad.benchmark.rotorpy_flights", None)
    with pytest.raises(scenarios.Skipped, match="rotorpy_flights unavailable"):
        scenarios.build_scenario("rotorpy-rate", tmp_path)
    module = types.ModuleType("gpquad.benchmark.rotorpy_flights")

    def no_rotorpy(mode, noisy, cache_dir):
        raise ModuleNotFoundError("No module named 'rotorpy'")

    module.ensure_flights = no_rotorpy
    monkeypatch.setitem(sys.modules, "gpquad.benchmark.rotorpy_flights", module)
    with pytest.raises(scenarios.Skipped, match="rotorpy is not installed"):
        scenarios.build_scenario("rotorpy-rate", tmp_path)


def test_unknown_scenario_is_a_user_error(tmp_path):
    from gpquad.errors import GpquadError

    with pytest.raises(GpquadError, match="unknown scenario"):
        scenarios.build_scenario("median-loud", tmp_path)
