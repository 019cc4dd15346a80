"""Stiff loops are fitted with the RK4 steps per sample that fly them as their ODEs."""

import dataclasses

import numpy as np
import pytest
import sympy as sp
from hypothesis import given, settings
from hypothesis import strategies as st

from gpquad.data.dataset import build_dataset
from gpquad.data.simulator import simulate
from gpquad.engine.evolve.gradient_fit import continued_constants
from gpquad.engine.tree.export import from_sympy, parse_equation
from gpquad.models.equation import Equation
from gpquad.models.refine_problem import RefineProblem
from gpquad.models.stiffness import gains, loop_speed, model_substeps, substeps_for
from gpquad.study.config import Config, SimulatorConfig

INPUTS = ("u_P", "u_R", "u_Y", "u_T")
#: |lambda| dt = 2.4 at 25 Hz: one RK4 step per sample keeps 0.49 of p over a sample where
#: the ODE keeps 0.09.
STIFF = "-60.0*p + 60.0*u_R"


@settings(max_examples=50, deadline=None)
@given(
    st.floats(-300, 0),
    st.floats(-3000, 0),
    st.sampled_from([0.0, 0.005, 0.02, 0.07]),
)
def test_loop_speed_is_the_largest_root(c, k, tau):
    if tau > 0:  # tau s^3 + s^2 - c s - k = 0
        roots = np.roots([tau, 1.0, -c, -k])
    else:  # s^2 - c s - k = 0
        roots = np.roots([1.0, -c, -k])
    assert loop_speed(c, k, tau) == pytest.approx(np.max(np.abs(roots)), rel=1e-6, abs=1e-9)


def test_substeps_are_the_least_power_of_two_within_the_limit():
    assert substeps_for(4.15, 0.04) == 1  # the quickstart's p_dot
    assert substeps_for(40.0, 0.04) == 2  # betaflight-gecko's p_dot
    assert substeps_for(60.0, 0.04) == 4
    assert substeps_for(1e4, 0.04) == 8  # capped at the readers' scheme
    assert substeps_for(4.15, 0.04, least=2) == 2
    assert substeps_for(float("nan"), 0.04) == 1


def test_gains_are_the_medians_of_the_derivatives():
    p, phi, u = sp.symbols("p phi u_R", real=True)
    expr = -40 * p - 300 * phi + 2 * p * u + 10 * u
    columns = {"p": np.array([1.0, 2.0, 3.0]), "phi": np.zeros(3), "u_R": np.array([0.0, 1, 2])}

    def values(e):
        f = sp.lambdify([p, phi, u], e, "numpy")
        return np.broadcast_to(f(columns["p"], columns["phi"], columns["u_R"]), (3,))

    assert gains("p_dot", expr, values) == (pytest.approx(-38.0), pytest.approx(-300.0))
    assert gains("a_x", sp.Float(1.0) * p, values) == (0.0, 0.0)  # a_x reads no u


@pytest.fixture(scope="module")
def stiff_problem():
    sim = dataclasses.replace(SimulatorConfig(), duration_s=80.0, seed=4)
    sim = dataclasses.replace(sim, equations={**sim.equations, "p_dot": STIFF})
    ds = build_dataset([simulate(sim, INPUTS)], validation_fraction=0.2, trim="none")
    expr, delays = parse_equation("-50.0*p + 50.0*u_R", INPUTS)
    tree = from_sympy(expr, delays, INPUTS)
    equation = Equation("p_dot", tree, INPUTS, 0.0, 0.0, {})
    return RefineProblem(equation, ds, Config().evolution), equation, ds


def _constants(expr):
    return sorted(float(c) for c in sp.expand(expr).atoms(sp.Float))


def test_a_stiff_loop_is_fitted_as_its_ode(stiff_problem):
    problem, equation, _ = stiff_problem
    start = problem.canonical(equation)
    assert problem.ev.substeps == 1 and problem.fitting(start).substeps == 2  # |-50| dt = 2
    fitted, _ = problem.fit(start)
    assert problem.fitting(fitted).substeps == 4  # the fitted loop needed more: refitted
    assert _constants(fitted) == pytest.approx([-60.0, 60.0], rel=0.01)
    # One RK4 step per sample fits the constants that make the discrete map fly: the test
    # fails if the fit does not fly the finer scheme.
    tree = problem.tree(start)

    def error_of(t):
        return float(problem.ev.window_errors([t], problem.starts, n_steps=problem.steps).mean())

    coarse, _ = continued_constants(
        problem.ev, tree, error_of(tree), problem.starts, problem.steps, error_of, 40, problem.short
    )
    assert abs(_constants(problem.expr(coarse))[0] + 60.0) > 3.0


def _equation(target, text):
    expr, delays = parse_equation(text, INPUTS)
    return Equation(target, from_sympy(expr, delays, INPUTS), INPUTS, 0.0, 0.0, {})


def test_the_model_is_flown_as_finely_as_its_stiffest_loop(stiff_problem):
    from gpquad.study.fit import new_model

    _, _, ds = stiff_problem
    slow = _equation("p_dot", "-4.0*p + 4.0*u_R")
    assert model_substeps(new_model({"p_dot": slow}, ds, Config()), ds) == 1
    stiff = _equation("q_dot", "-60.0*q + 60.0*u_P")
    model = new_model({"p_dot": slow, "q_dot": stiff}, ds, Config())
    assert model_substeps(model, ds) == 4
    lagged = dataclasses.replace(_equation("q_dot", "-4.0*q + 4.0*u_P"), lag=0.01)
    assert model_substeps(new_model({"q_dot": lagged}, ds, Config()), ds) == 4  # 100/s
    assert model_substeps(dataclasses.replace(model, integrator="euler"), ds) == 1


def test_a_finished_model_flies_with_its_stiffest_loops_steps(stiff_problem):
    from gpquad.models.finish import finish_model
    from gpquad.study.fit import new_model

    _, _, ds = stiff_problem
    evolution = dataclasses.replace(Config().evolution, finish=("symmetrize",))
    stiff = _equation("q_dot", "-60.0*q + 60.0*u_P")
    finished = finish_model(new_model({"q_dot": stiff}, ds, Config()), ds, evolution)
    assert finished.integrator == "rk4" and finished.substeps == 4
    slow = _equation("q_dot", "-6.0*q + 6.0*u_P")
    assert finish_model(new_model({"q_dot": slow}, ds, Config()), ds, evolution).substeps == 1
