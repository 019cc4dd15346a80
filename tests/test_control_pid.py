"""Evolved PID waypoint control: hand computations on a linear plant, course measures, the
ES's determinism, the command end to end, and bad inputs."""

import dataclasses
import json
import math

import numpy as np
import pytest

from gpquad.cli.commands import main
from gpquad.control.config import ControlConfig, CourseConfig, PidConfig, load_control_config
from gpquad.control.courses import deviation, progress, score_path
from gpquad.control.evolve import evolve_gains
from gpquad.control.pid import fly, make_controller
from gpquad.control.pid_kernel import pid_command
from gpquad.control.plant import design_point, truth_plant
from gpquad.errors import GpquadError
from gpquad.study.config import MEDIAN_MODEL, Config, SimulatorConfig, folder_config_dict
from gpquad.study.store import write_json

NAMES = ("u_P", "u_R", "u_Y", "u_T")
DT = 0.04
#: A linear plant with round numbers: rate-level roll/pitch/yaw, thrust with a hover offset.
LINEAR = {
    "a_x": "-10.0*theta",
    "a_y": "8.0*phi",
    "a_z": "-20.0*u_T + 10.0",
    "p_dot": "2.0*u_R",
    "q_dot": "-4.0*u_P",
    "r_dot": "0.5*u_Y",
}
SPAN = np.ones(4)
GAINS = np.array([2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 0.5, 0.25, 1.0, 2.0, 3.0, 0.5, 1.5])


def _controller(plant, cfg=None, gains=GAINS):
    d = design_point(plant, SPAN)
    return make_controller(gains, d, -5 * np.ones(4), 5 * np.ones(4), cfg or PidConfig())


def test_design_point_of_a_linear_plant():
    d = design_point(truth_plant(LINEAR, NAMES, DT), SPAN)
    assert [NAMES[c] for c in d.chan] == ["u_R", "u_P", "u_Y", "u_T"]
    np.testing.assert_allclose(d.gain, [2.0, -4.0, 0.5, -20.0], rtol=1e-6)
    np.testing.assert_allclose(d.hover, [0.0, 0.0, 0.0, 0.5], atol=1e-9)  # -20 u + 10 = 0
    assert d.g_x == pytest.approx(-10.0) and d.g_y == pytest.approx(8.0)


def test_pid_command_by_hand():
    """err (3, 4, 2) m with psi = 0, vel (0.5, -1, 0.2), angles (0.1, -0.05, 0.2), rates
    (0.3, 0.4, 0.5), integral 1, g_x = -10, g_y = 8, max angle 0.35, rate level."""
    ctrl = np.array([-10.0, 8.0, 0.35, 1.0, 0.5, 5.0, 0, 0, 0])
    cmd = np.empty(4)
    pid_command(
        GAINS,
        ctrl,
        np.array([3.0, 4.0, 2.0]),
        np.array([0.5, -1.0, 0.2]),
        np.array([0.1, -0.05, 0.0]),
        np.array([0.3, 0.4, 0.5]),
        np.array([1.0]),
        cmd,
    )
    # theta* = (0.5*3 - 0.25*0.5)/-10 = -0.1375; phi* = (1*4 - 2*(-1))/8 = 0.75 -> 0.35
    assert cmd[0] == pytest.approx(2.0 * (0.35 - 0.1) - 3.0 * 0.3)
    assert cmd[1] == pytest.approx(4.0 * (-0.1375 + 0.05) - 5.0 * 0.4)
    assert cmd[2] == pytest.approx(6.0 * 0.0 - 7.0 * 0.5)
    assert cmd[3] == pytest.approx(3.0 * 2.0 + 0.5 * 1.0 - 1.5 * 0.2)
    # angle level: the inner loop does not subtract the measured angle
    ctrl[3] = 0.0
    pid_command(
        GAINS,
        ctrl,
        np.array([3.0, 4.0, 2.0]),
        np.array([0.5, -1.0, 0.2]),
        np.array([0.1, -0.05, 0.0]),
        np.array([0.3, 0.4, 0.5]),
        np.array([1.0]),
        cmd,
    )
    assert cmd[0] == pytest.approx(2.0 * 0.35 - 3.0 * 0.3)


def test_pid_command_heading_frame():
    """Heading east (psi = pi/2), a waypoint 2 m east is 2 m ahead: only pitch reacts."""
    ctrl = np.array([-10.0, 8.0, 0.35, 1.0, 0.5, 5.0, 0, 0, 0])
    cmd = np.empty(4)
    g = np.zeros(13)
    g[6], g[0], g[2] = 1.0, 1.0, 1.0
    pid_command(
        g,
        ctrl,
        np.array([0.0, 2.0, 0.0]),
        np.zeros(3),
        np.array([0.0, 0.0, math.pi / 2]),
        np.zeros(3),
        np.zeros(1),
        cmd,
    )
    assert cmd[1] == pytest.approx(2.0 / -10.0)
    assert cmd[0] == pytest.approx(0.0, abs=1e-12)


def test_first_step_by_hand():
    """The first input is hover + command / sensitivity, and the plant integrates it."""
    plant = truth_plant(LINEAR, NAMES, DT)
    c = _controller(plant)
    wp = np.array([[3.0, 4.0, 2.0]])
    f = fly(plant, c, wp, np.zeros((2, 4)))
    # at rest: theta* = 0.5*3/-10 = -0.15, phi* = 1*4/8 = 0.5 -> 0.35, a_z* = 3*2 = 6
    u = f.inputs[0]
    assert u[1] == pytest.approx(2.0 * 0.35 / 2.0)  # roll: kp (phi* - 0) / 2
    assert u[0] == pytest.approx(4.0 * -0.15 / -4.0)  # pitch
    assert u[3] == pytest.approx(0.5 + 6.0 / -20.0)  # thrust
    # one step later: p = 2 u_R dt, and w = a_z dt = (-20 u_T + 10) dt
    assert f.states[1, 6] == pytest.approx(2.0 * u[1] * DT)
    assert f.states[1, 5] == pytest.approx((-20.0 * u[3] + 10.0) * DT)


def test_noise_and_limits_reach_the_plant():
    plant = truth_plant(LINEAR, NAMES, DT)
    c = dataclasses.replace(_controller(plant), lo=-0.1 * np.ones(4), hi=0.1 * np.ones(4))
    noise = np.zeros((2, 4))
    noise[0, 1] = 0.05
    f = fly(plant, c, np.array([[3.0, 4.0, 2.0]]), noise)
    assert f.inputs[0, 1] == pytest.approx(0.1)  # clipped from 0.35
    assert f.states[1, 6] == pytest.approx(2.0 * (0.1 + 0.05) * DT)  # plant sees the noise


def test_command_limit():
    """command_limit 0.05 caps the roll input at hover + 0.05 (it would be 0.35 without)."""
    plant = truth_plant(LINEAR, NAMES, DT)
    c = _controller(plant, PidConfig(command_limit=0.05))
    f = fly(plant, c, np.array([[3.0, 4.0, 2.0]]), np.zeros((2, 4)))
    assert f.inputs[0, 1] == pytest.approx(0.05)
    assert f.inputs[0, 3] == pytest.approx(0.5 + 6.0 / -20.0)  # thrust is not limited


def test_course_measures_by_hand():
    wp = np.array([[4.0, 0.0, 0.0], [4.0, 3.0, 0.0]])
    pos = np.array([[2.0, 1.0, 0.0], [5.0, 2.0, 0.0], [4.0, 3.0, 0.0]])
    target = np.array([0, 1, 2])
    np.testing.assert_allclose(deviation(pos, wp), [1.0, 1.0, 0.0])
    np.testing.assert_allclose(progress(pos, target, wp), [2.0, 6.0, 7.0])
    s = score_path(pos, target, wp, flown=2, n_steps=2)
    assert s.rmse_m == pytest.approx(math.sqrt(2 / 3))
    assert s.completion == pytest.approx(1.0)
    assert s.fitness(1.0) == pytest.approx(1.0 / (1.0 + math.sqrt(2 / 3)))
    cut = score_path(pos, target, wp, flown=1, n_steps=2)  # diverged after step 1
    assert cut.diverged and cut.fitness(1.0) == pytest.approx(6 / 7 / 2 - 1.0)


def test_closed_loop_reaches_a_waypoint_on_the_median_model():
    plant = truth_plant(MEDIAN_MODEL, NAMES, 0.04)
    cfg = PidConfig()
    d = design_point(plant, np.array([0.5, 0.5, 0.5, 0.2]))
    c = make_controller(cfg.nominal_gains, d, -np.ones(4), np.ones(4), cfg)
    f = fly(plant, c, np.array([[5.0, 0.0, -1.0]]), np.zeros((500, 4)))
    assert f.score.completion == 1.0 and not f.score.diverged
    assert np.linalg.norm(f.pos[-1] - [5.0, 0.0, -1.0]) < 0.3


def test_unsteerable_model_is_refused():
    no_thrust = dict(LINEAR, a_z="10.0 - w")
    with pytest.raises(GpquadError, match="one-to-one"):
        design_point(truth_plant(no_thrust, NAMES, DT), SPAN)
    no_tilt = dict(LINEAR, a_x="-u")
    with pytest.raises(GpquadError, match="d a_x / d theta"):
        design_point(truth_plant(no_tilt, NAMES, DT), SPAN)


TINY = PidConfig(
    popsize=4,
    generations=3,
    courses_per_generation=1,
    course=CourseConfig(legs=2, leg_min_m=2.0, leg_max_m=3.0),
)


def test_es_is_deterministic_for_a_seed():
    plant = truth_plant(MEDIAN_MODEL, NAMES, 0.04)
    d = design_point(plant, np.array([0.5, 0.5, 0.5, 0.2]))
    start = make_controller(TINY.nominal_gains, d, -np.ones(4), np.ones(4), TINY)
    sd = np.full(4, 0.02)
    a = evolve_gains(plant, start, TINY, sd, seed=7)
    b = evolve_gains(plant, start, TINY, sd, seed=7)
    c = evolve_gains(plant, start, TINY, sd, seed=8)
    np.testing.assert_array_equal(a.controller.gains, b.controller.gains)
    assert a.history == b.history
    assert not np.array_equal(a.controller.gains, c.controller.gains)


def _run_folder(tmp_path):
    """A run folder whose model is the simulator's truth (a short simulated flight)."""
    from gpquad.data.simulator import TruthModel
    from gpquad.engine.tree.export import from_sympy
    from gpquad.models.equations import DiscoveredModel, Equation
    from gpquad.study.runner import write_model

    cfg = Config(simulator=SimulatorConfig(duration_s=40.0))
    truth = TruthModel(cfg.simulator.equations, NAMES)
    eqs = {
        t: Equation(t, from_sympy(truth.exprs[t], truth.delays[t], NAMES), NAMES, 0.0, 0.0, {})
        for t in truth.exprs
    }
    run = tmp_path / "run"
    run.mkdir()
    write_model(run, DiscoveredModel(eqs, NAMES, {n: 0.0 for n in NAMES}, 0.04, 1, cfg.to_dict()))
    write_json(run / "config.json", folder_config_dict(cfg))
    return run


def test_command_end_to_end(tmp_path, capsys):
    run = _run_folder(tmp_path)
    conf = tmp_path / "control.toml"
    conf.write_text(
        "[pid]\npopsize = 4\ngenerations = 2\nrepetitions = 2\n[pid.course]\nlegs = 2\n"
    )
    out = tmp_path / "out"
    assert (
        main(
            [
                "control",
                "pid",
                str(run),
                "--config",
                str(conf),
                "--out",
                str(out),
                "--json",
                "--courses",
                "2",
            ]
        )
        == 0
    )
    last = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert set(last) >= {"model_rmse_m", "truth_rmse_m", "completion"}
    # the model is the truth: both plants fly alike (only the noise differs)
    assert last["truth_rmse_m"] < 1.5 * last["model_rmse_m"]
    assert last["completion"] > 0.9
    summary = json.loads((out / "summary.json").read_text())
    assert len(summary["tests"]) == 2 and len(summary["tests"][0]["truth"]["rmse_m"]) == 2
    assert (out / "paths_course1.png").is_file() and (out / "paths.csv").is_file()


def test_bad_inputs(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text('[pid]\ninput_level = "torque"\n')
    with pytest.raises(GpquadError, match="pid.input_level"):
        load_control_config(bad)
    bad.write_text('[pid]\nmodel_form = "raw"\n')
    with pytest.raises(GpquadError, match="pid.model_form"):
        load_control_config(bad)
    bad.write_text("[pid]\ncommand_limit = -1.0\n")
    with pytest.raises(GpquadError, match="pid.command_limit"):
        load_control_config(bad)
    bad.write_text("[pid]\nnominal_gains = [1.0, 2.0]\n")
    with pytest.raises(GpquadError, match="pid.nominal_gains"):
        load_control_config(bad)
    bad.write_text("[pid]\npopsize = 4\nsurprise = 1\n")
    with pytest.raises(GpquadError):
        load_control_config(bad)
    assert load_control_config(None) == ControlConfig()
    assert main(["control", "pid", str(tmp_path / "missing")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "model.json" in err[0]
    run = _run_folder(tmp_path)
    assert main(["control", "pid", str(run), "--courses", "0"]) == 2
    assert "--courses" in capsys.readouterr().err


def test_documented_config_is_the_defaults():
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "experiments" / "control.toml"
    assert load_control_config(path) == ControlConfig()


def test_waypoint_passed_counts_as_reached():
    """Side and forward forces of 0.5 and 0.3 m/s^2 would hold the craft 0.5 / kp_y = 1 m
    beside and 0.3 / kp_x = 0.6 m beyond the waypoint, outside the 0.5 m radius: passing the
    waypoint (projection beyond it) switches legs, at the first step north of 3 m."""
    plant = truth_plant(
        dict(MEDIAN_MODEL, a_y="-9.2*phi - 0.6*v + 0.5", a_x="10.0*theta - 0.6*u + 0.3"),
        NAMES,
        0.04,
    )
    cfg = PidConfig()
    d = design_point(plant, np.array([0.5, 0.5, 0.5, 0.2]))
    c = make_controller(cfg.nominal_gains, d, -np.ones(4), np.ones(4), cfg)
    f = fly(plant, c, np.array([[3.0, 0.0, 0.0], [3.0, 5.0, 0.0]]), np.zeros((300, 4)))
    k = int(np.argmax(f.pos[:, 0] >= 3.0))
    assert k > 0 and f.target[k] == 1 and f.target[k - 1] == 0
    assert abs(f.pos[k, 1]) > 0.5  # it did not come within the radius


def test_model_forms_differ_where_protected_division_fires():
    """q_dot = -100 / (34 / u_P): the tree gives -100 at u_P = trim (protected division),
    the simplified equation -100 u_P / 34 gives 0."""
    from gpquad.control.plant import model_plant
    from gpquad.engine.tree.encoding import Tree
    from gpquad.engine.tree.operators import CONST, DIV, VAR_BASE
    from gpquad.models.equations import DiscoveredModel, Equation

    u_p = VAR_BASE + 9 + NAMES.index("u_P")
    tree = Tree.from_lists([DIV, CONST, DIV, CONST, u_p], [0, -100.0, 0, 34.0, 0], [0] * 4)
    trim = {"u_P": 0.2, "u_R": 0.0, "u_Y": 0.0, "u_T": 0.0}
    model = DiscoveredModel(
        {"q_dot": Equation("q_dot", tree, NAMES, 0.0, 0.0, trim)}, NAMES, trim, 0.04, 1, {}
    )
    at_trim = np.array([0.2, 0.0, 0.0, 0.0])
    assert model_plant(model, "tree").accelerations(np.zeros(9), at_trim)[4] == -100.0
    assert model_plant(model).accelerations(np.zeros(9), at_trim)[4] == pytest.approx(0.0)
    off = np.array([0.54, 0.0, 0.0, 0.0])  # u_P - trim = 0.34: both -1
    assert model_plant(model, "tree").accelerations(np.zeros(9), off)[4] == pytest.approx(-1.0)
    assert model_plant(model).accelerations(np.zeros(9), off)[4] == pytest.approx(-1.0)


def test_a_lagged_equation_reaches_the_plant_by_hand():
    """An identified equation's lag (gpquad.engine.lag) is flown: from rest, the applied
    roll acceleration is alpha times the equation's value at the first step, and the lag
    leaves the other equations alone."""
    plant = truth_plant(LINEAR, NAMES, DT)
    plant.alphas[3] = 0.25  # p_dot
    f = fly(plant, _controller(plant), np.array([[3.0, 4.0, 2.0]]), np.zeros((2, 4)))
    u = f.inputs[0]
    assert f.states[1, 6] == pytest.approx(0.25 * 2.0 * u[1] * DT)
    assert f.states[1, 5] == pytest.approx((-20.0 * u[3] + 10.0) * DT)


def test_model_plant_takes_each_equations_lag():
    from gpquad.control.plant import model_plant
    from gpquad.engine.lag import lag_alpha
    from gpquad.engine.tree.export import from_sympy, parse_equation
    from gpquad.models.equations import DiscoveredModel, Equation

    expr, delays = parse_equation("-3.3*q - 9.8*u_P", NAMES)
    eq = Equation("q_dot", from_sympy(expr, delays, NAMES), NAMES, 0.0, 0.0, {}, lag=0.05)
    plant = model_plant(DiscoveredModel({"q_dot": eq}, NAMES, {}, 0.04, 1, {}))
    assert plant.alphas[4] == pytest.approx(lag_alpha(0.05, 0.04)) and plant.alphas[4] < 1.0
    assert np.all(np.delete(plant.alphas, 4) == 1.0)
