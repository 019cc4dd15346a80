"""Thrust, drag and dead reckoning against rotorpy's own coefficients (short flights)."""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("rotorpy")

from gpquad.physics.commands import run_command  # noqa: E402
from gpquad.physics.config import load_physics_config  # noqa: E402
from gpquad.physics.identify import identify_drag, identify_thrust  # noqa: E402

CONFIG = """
name = "test"
seed = 5
[truth]
vehicle = "hummingbird"
dt = 0.02
side = 1.5
speed = 2.0
cache = "{cache}"
[noise]
accel_noise_sd = 0.2
accel_bias_sd = 0.05
calibration_s = 0.4
rotor_noise_sd = 2.0
velocity_noise_sd = 0.01
[regression]
parasitic_drag = true
[drag]
flights = ["forward", "lateral"]
[deadreckon]
manoeuvres = ["L"]
yaw = [true]
"""


@pytest.fixture(scope="module")
def config_path(tmp_path_factory):
    root = tmp_path_factory.mktemp("rotorpy")
    path = root / "physics.toml"
    path.write_text(CONFIG.format(cache=(root / "flights").as_posix()))
    return path


@pytest.fixture(scope="module")
def thrust(config_path):
    return identify_thrust(load_physics_config(config_path))


def test_thrust_coefficient_within_two_percent(thrust):
    hover = thrust["fits"]["standard_hover"]
    assert abs(hover["relative_error"]["k_t"]) < 0.02
    refined = thrust["fits"]["refined_forward"]
    assert abs(refined["relative_error"]["k_t"]) < 0.02
    assert abs(refined["relative_error"]["k_z"]) < 0.25


def test_refined_thrust_beats_standard_on_forward_flight(thrust):
    std, ref = thrust["fits"]["standard_forward"], thrust["fits"]["refined_forward"]
    assert thrust["refined_beats_standard"]
    assert ref["rmse_val"] < 0.5 * std["rmse_val"] and ref["r2_val"] > std["r2_val"]
    # fitted on forward flight, the standard model's k_t absorbs the missing terms
    assert abs(std["relative_error"]["k_t"]) > abs(ref["relative_error"]["k_t"])


def test_drag_coefficient_within_ten_percent(config_path):
    drag = identify_drag(load_physics_config(config_path))
    for key in ("x", "x_parasitic"):
        assert abs(drag["fits"][key]["relative_error"]["k_dx"]) < 0.10, drag["fits"][key]


def test_deadreckon_command_orders_coriolis_first(config_path, tmp_path):
    out = run_command("deadreckon", config_path, tmp_path / "dr")
    res = json.loads((out / "deadreckon.json").read_text())
    (flight,) = res["flights"]
    norms = {m: np.linalg.norm(v["rmse"]) for m, v in flight["models"].items()}
    assert norms["coriolis"] < norms["refined"] < norms["base"]
    assert norms["coriolis"] < 0.3
    run = json.loads((out / "run.json").read_text())
    assert run["seed"] == 5 and run["config"]["truth"]["side"] == 1.5
    assert (out / "tracks_L-yaw.png").is_file() and (out / "deadreckon.md").is_file()
    again = run_command("deadreckon", config_path, tmp_path / "dr2")
    assert (again / "deadreckon.json").read_bytes() == (out / "deadreckon.json").read_bytes()
    other = run_command("deadreckon", config_path, tmp_path / "dr3", seed=6)
    assert (other / "deadreckon.json").read_bytes() != (out / "deadreckon.json").read_bytes()
