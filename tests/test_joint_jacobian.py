"""The joint refit's Jacobian from one sensitivity flight (gpquad.models.joint_jacobian,
gpquad.engine.kernels.rollout_sensitivity) against central differences of the residuals
that the rollout kernel gives."""

import dataclasses

import numpy as np
import pytest

from gpquad.data.dataset import build_dataset
from gpquad.engine.tree.export import from_sympy, parse_equation
from gpquad.models import joint_fit
from gpquad.models.equations import DiscoveredModel, Equation
from gpquad.models.joint_jacobian import flown_with_sensitivities

#: A model with every path of the kernel: a lag (q_dot), delays, products and a quotient
#: of states, the Euler angles in every equation, a stiff roll loop (-40 p: two RK4 steps
#: per sample at 25 Hz).
EQUATIONS = {
    "a_x": "10.0*theta - 0.6*u + 0.2*q*w",
    "a_y": "-9.2*phi - 0.6*v + 0.1*psi",
    "a_z": "28.2*u_T(t-5) - w - 9.81 + 0.3*phi*theta",
    "p_dot": "10.3*u_R(t-1) - 40.0*p - 2.0*phi + 0.4*q*r",
    "q_dot": "-9.8*u_P - 3.3*q - 1.5*theta/(1.0 + 0.5*u_T)",
    "r_dot": "-7.8*u_Y(t-2) - 1.9*r + 0.2*p*q",
}
LAGS = {"q_dot": 0.08}


@pytest.fixture(scope="module")
def dataset(short_flight):
    return build_dataset([short_flight], validation_fraction=0.25, trim="none")


def model_of(dataset, equations=EQUATIONS, substeps=2) -> DiscoveredModel:
    eqs = {}
    for target, text in equations.items():
        expr, delays = parse_equation(text, dataset.input_names)
        tree = from_sympy(expr, delays, dataset.input_names)
        eqs[target] = Equation(
            target, tree, dataset.input_names, np.nan, np.nan, lag=LAGS.get(target, 0.0)
        )
    model = DiscoveredModel(eqs, dataset.input_names, {}, dataset.dt, 1, {})
    return dataclasses.replace(model, integrator="rk4", substeps=substeps)


def problem(dataset, model, seconds=2.0, fitted=None):
    """(objective, slots, x0, residuals(x)) as the joint refit sets them up."""
    states = joint_fit.measured_states(dataset)
    slots = [
        (t, idx)
        for t, idx in joint_fit.constant_nodes(model)
        if len(idx) and (fitted is None or t in fitted)
    ]
    x0 = np.concatenate([model.equations[t].tree.values[idx] for t, idx in slots])
    starts, steps = joint_fit.horizon_starts(
        dataset, dataset.train, seconds, joint_fit.model_history(model), 8
    )
    objective = joint_fit.FullModelError(dataset, starts, steps, states)

    def residuals(x):
        return objective.residuals(joint_fit.with_constants(model, slots, x))

    return objective, slots, x0, residuals


def central_differences(residuals, x0):
    h = 1e-6 * np.maximum(1.0, np.abs(x0))
    columns = []
    for j in range(x0.size):
        up, down = x0.copy(), x0.copy()
        up[j] += h[j]
        down[j] -= h[j]
        columns.append((residuals(up) - residuals(down)) / (2.0 * h[j]))
    return np.column_stack(columns)


def column_errors(jac, reference):
    """Each column's largest difference relative to the reference column's largest entry."""
    scale = np.maximum(np.abs(reference).max(axis=0), 1e-12)
    return np.abs(jac - reference).max(axis=0) / scale


def sensitivity_jacobian(dataset, model, objective, slots, workers=1):
    states, sens = flown_with_sensitivities(
        model, dataset, slots, objective.starts, objective.steps, workers
    )
    return states, objective.jacobian_of(states, sens)


def test_the_flight_is_the_rollout_and_its_jacobian_the_residuals_derivative(dataset):
    model = model_of(dataset)
    objective, slots, x0, residuals = problem(dataset, model)
    states, jac = sensitivity_jacobian(dataset, model, objective, slots)
    # the states are the rollout kernel's, bit for bit
    flown = model.simulate(dataset, objective.starts, objective.steps)
    assert np.array_equal(states, flown)
    assert jac.shape == (residuals(x0).size, x0.size) == (objective.residuals(model).size, 23)
    errors = column_errors(jac, central_differences(residuals, x0))
    assert errors.max() < 1e-5, errors


def test_the_check_fails_for_the_jacobian_of_another_scheme(dataset):
    """The bad case: the sensitivities of the same model flown with one RK4 step per
    sample, where the residuals fly two, are off by more than the check allows."""
    model = model_of(dataset)
    objective, slots, x0, residuals = problem(dataset, model)
    _, coarse = sensitivity_jacobian(dataset, model_of(dataset, substeps=1), objective, slots)
    assert column_errors(coarse, central_differences(residuals, x0)).max() > 1e-3


def test_only_the_fitted_equations_have_columns_and_a_missing_one_is_the_data(dataset):
    """Constants of equations the refit does not fit (an unmeasured state) have no column;
    a target without an equation flies the data's acceleration (no tangent)."""
    equations = {t: e for t, e in EQUATIONS.items() if t != "a_y"}
    model = model_of(dataset, equations)
    objective, slots, x0, residuals = problem(dataset, model, fitted={"p_dot", "q_dot", "a_z"})
    assert [t for t, _ in slots] == ["a_z", "p_dot", "q_dot"]
    states, jac = sensitivity_jacobian(dataset, model, objective, slots)
    assert np.array_equal(states, model.simulate(dataset, objective.starts, objective.steps))
    assert column_errors(jac, central_differences(residuals, x0)).max() < 1e-5


def test_threads_give_the_same_jacobian(dataset):
    model = model_of(dataset)
    objective, slots, _, _ = problem(dataset, model)
    one = sensitivity_jacobian(dataset, model, objective, slots, workers=1)
    two = sensitivity_jacobian(dataset, model, objective, slots, workers=3)
    assert np.array_equal(one[0], two[0]) and np.array_equal(one[1], two[1])


def test_a_diverging_window_has_finite_rows(dataset):
    """A window that blows up gives clipped residuals and zero Jacobian rows, not NaN."""
    unstable = dict(EQUATIONS, p_dot="10.3*u_R(t-1) + 60.0*p")
    model = model_of(dataset, unstable)
    objective, slots, _, _ = problem(dataset, model, seconds=8.0)
    states, jac = sensitivity_jacobian(dataset, model, objective, slots)
    assert not np.all(np.isfinite(states))
    residuals = objective.residuals_of(states)
    assert np.all(np.isfinite(jac))
    clipped = np.abs(residuals) >= joint_fit.RESIDUAL_CLIP
    assert clipped.any() and np.all(jac[clipped] == 0.0)


def test_the_refit_of_a_continuous_time_model_flies_sensitivities(dataset):
    """An RK4 model's refit takes its Jacobians from sensitivity flights (no rollout per
    constant); an eq. 2 model's from forward differences."""
    wrong = dict(EQUATIONS, q_dot="-9.0*u_P - 3.3*q - 1.5*theta/(1.0 + 0.5*u_T)")
    rk4 = model_of(dataset, wrong, substeps=2)
    _, report = joint_fit.joint_refit(rk4, dataset, horizons_s=(1.0,))
    assert report["sensitivity_flights"] > 0
    assert report["rollouts"] < 10 * report["sensitivity_flights"] + 30
    euler = dataclasses.replace(rk4, integrator="euler", substeps=1)
    _, report = joint_fit.joint_refit(euler, dataset, horizons_s=(1.0,))
    assert report["sensitivity_flights"] == 0
    assert report["rollouts"] > report["constants"]


def test_the_objectives_windows_in_threads_give_the_same_residuals(dataset):
    """FullModelError flies its windows in chunks side by side: the same residuals to the
    bit for 1, 2 and 3 threads."""
    model = model_of(dataset)
    states = joint_fit.measured_states(dataset)
    starts, steps = joint_fit.horizon_starts(dataset, dataset.train, 2.0, 5, None)
    one, *more = (
        joint_fit.FullModelError(dataset, starts, steps, states, workers).residuals(model)
        for workers in (1, 2, 3)
    )
    assert len(starts) >= 3 and all(np.array_equal(one, r) for r in more)
