"""Exports of continuous-time (RK4) models: python and C fly them as DiscoveredModel.fly_states
(rk4_rollout) does, to 1e-12; `rhs` is the continuous-time right-hand
side with which another integrator flies the model; the comparison catches an RK4 model
flown by eq. 2, with other substeps, or with a perturbed constant."""

from __future__ import annotations

import numpy as np
import pytest
from export_models import (
    assert_flies_like,
    c_rhs,
    compile_c,
    fly_c,
    hand_inputs,
    hand_model,
    history_rows,
    in_scheme,
    kernel_commanded,
    load_python,
    median_model,
    python_and_c,
    rk4_model,
)
from scipy.integrate import solve_ivp
from scipy.spatial.transform import Rotation

from gpquad.cli.commands import main
from gpquad.models.exports import export

X0 = np.array([0.05, -0.1, 3.0, 1.0, -0.5, 0.2, 0.1, -0.2, 0.3])

CASES = {
    "rk4_x4": rk4_model(),
    "rk4_x1": rk4_model(1),
    "hand_rk4_x2": in_scheme(hand_model(), "rk4", 2),
    "median_rk4_x3": in_scheme(median_model(), "rk4", 3),
}


@pytest.mark.parametrize("name", list(CASES))
def test_rk4_exports_fly_as_fly_states(name, tmp_path):
    model = CASES[name]
    inputs = hand_inputs()
    reference = model.fly_states(inputs, X0)
    module, lib = python_and_c(model, tmp_path)
    assert (module.INTEGRATOR, module.SUBSTEPS) == ("rk4", model.substeps)
    assert not hasattr(module, "accel")  # eq. 2's filtered step belongs to euler models
    assert_flies_like(module.fly(inputs, X0), reference)
    code, states = fly_c(lib, inputs, X0)
    assert code == 0
    assert_flies_like(states, reference)


def test_the_header_states_the_scheme_and_the_ode():
    python = export(rk4_model(), "python")
    header = export(rk4_model(), "c", name="m")["m.h"]
    for text in (python, header):
        assert "scheme: rk4, continuous time: fly() integrates the ODE below by 4" in text
        assert "h = dt / 4 = 0.01 s" in text
        assert "[u, v, w]_dot = [a_x, a_y, a_z] - omega x [u, v, w]" in text
        assert "a_dot = (rhs - a) / tau" in text
    assert '#define GPQUAD_INTEGRATOR "rk4"' in header and "GPQUAD_SUBSTEPS 4" in header
    assert "gpquad_accel" not in header and "gpquad_rhs(" in header
    euler = export(hand_model(), "python")
    assert "scheme: euler (the paper's eq. 2)" in euler and "def accel(" in euler


@pytest.mark.parametrize("wrong", [("euler", 1), ("rk4", 2)])
def test_the_comparison_catches_another_scheme(wrong, tmp_path):
    """The RK4 x4 model exported as eq. 2 or as RK4 x2 does not fly as the model."""
    model = rk4_model()
    inputs = hand_inputs()
    reference = model.fly_states(inputs, X0)
    module, lib = python_and_c(in_scheme(model, *wrong), tmp_path, name="wrong")
    with pytest.raises(AssertionError, match="largest difference"):
        assert_flies_like(module.fly(inputs, X0), reference)
    with pytest.raises(AssertionError, match="largest difference"):
        assert_flies_like(fly_c(lib, inputs, X0)[1], reference)


def test_the_comparison_catches_a_perturbed_constant(tmp_path):
    """p_dot's 30.0 changed by 1e-9 relative in the generated python and C."""
    model = rk4_model()
    inputs = hand_inputs()
    reference = model.fly_states(inputs, X0)
    wrong = repr(30.0 * (1 + 1e-9))
    python = export(model, "python")
    head, body = python.split("def _commanded", 1)
    assert body.count("(30.0 * ") == 1
    module = load_python(
        head + "def _commanded" + body.replace("(30.0 * ", f"({wrong} * "), tmp_path / "bad_rk4.py"
    )
    with pytest.raises(AssertionError, match="largest difference"):
        assert_flies_like(module.fly(inputs, X0), reference)
    files = export(model, "c", name="bad_rk4")
    assert files["bad_rk4.c"].count("(30.0 * ") == 1
    files["bad_rk4.c"] = files["bad_rk4.c"].replace("(30.0 * ", f"({wrong} * ")
    with pytest.raises(AssertionError, match="largest difference"):
        assert_flies_like(fly_c(compile_c(files, tmp_path), inputs, X0)[1], reference)


@pytest.mark.parametrize("model", [rk4_model(), hand_model()], ids=["rk4", "euler"])
def test_rhs_is_f_or_the_lag_state_and_the_lag_derivative(model, tmp_path):
    """python and C rhs: a = f (the kernel's tree value), a lagged equation's lag state; its
    lag_dot = (f - lag) / tau."""
    inputs = hand_inputs(60)
    states = model.fly_states(inputs, X0)
    kernel = kernel_commanded(model, states, inputs)
    module, lib = python_and_c(model, tmp_path)
    tau = np.array(module.TAU)
    lagged = tau > 0
    assert lagged.sum() >= 1
    np.testing.assert_allclose(np.array(module.LAG_RATE)[lagged], 1.0 / tau[lagged], rtol=1e-12)
    lag = np.linspace(-2.0, 3.0, 6)
    for k in range(0, 60, 7):
        hist = history_rows(inputs, k, module.HISTORY)
        f = kernel[k]
        want = (
            np.where(lagged, lag, f),
            np.where(lagged, np.array(module.LAG_RATE) * (f - lag), 0.0),
        )
        for got in (module.rhs(states[k], hist, lag), c_rhs(lib, states[k], hist, lag)):
            np.testing.assert_array_equal(got[0], want[0])
            np.testing.assert_array_equal(got[1], want[1])
        zero = (np.where(lagged, 0.0, f), np.where(lagged, np.array(module.LAG_RATE) * f, 0.0))
        for got in (module.rhs(states[k], hist), c_rhs(lib, states[k], hist, None)):
            np.testing.assert_array_equal(np.vstack(got), np.vstack(zero))
    with pytest.raises(ValueError, match="lag needs 6"):
        module.rhs(states[0], history_rows(inputs, 0, module.HISTORY), np.zeros(5))


def own_flight(module, inputs, x0) -> tuple[np.ndarray, np.ndarray]:
    """The exported model flown as a user would: the header's ODE with module.rhs and the
    world position x_dot = R(q) V, by scipy's DOP853 over each sample (inputs held), attitude
    as a scipy Rotation. Returns states (N, 9) and position (N, 3) from x = 0."""
    quat = Rotation.from_euler("ZYX", [x0[2], x0[1], x0[0]]).as_quat()  # x y z w
    y = np.concatenate([quat[[3, 0, 1, 2]], x0[3:], np.zeros(6), np.zeros(3)])
    out = np.empty((len(inputs), 9))
    pos = np.empty((len(inputs), 3))

    def state_of(y):
        psi, theta, phi = Rotation.from_quat(y[[1, 2, 3, 0]]).as_euler("ZYX")
        return np.concatenate([[phi, theta, psi], y[4:10]])

    for k in range(len(inputs)):
        out[k], pos[k] = state_of(y), y[16:19]
        hist = history_rows(inputs, k, module.HISTORY)

        def ode(_t, y, hist=hist):
            q0, q1, q2, q3 = y[:4]
            vel, omega = y[4:7], y[7:10]
            accel, lag_dot = module.rhs(state_of(y), hist, y[10:16])
            p, q, r = omega
            quat_dot = 0.5 * np.array(
                [
                    -q1 * p - q2 * q - q3 * r,
                    q0 * p + q2 * r - q3 * q,
                    q0 * q + q3 * p - q1 * r,
                    q0 * r + q1 * q - q2 * p,
                ]
            )
            world_vel = Rotation.from_quat(y[[1, 2, 3, 0]]).apply(vel)
            return np.concatenate(
                [quat_dot, accel[:3] - np.cross(omega, vel), accel[3:], lag_dot, world_vel]
            )

        y = solve_ivp(ode, (0.0, module.DT), y, method="DOP853", rtol=1e-11, atol=1e-12).y[:, -1]
    return out, pos


def test_an_own_integrator_of_rhs_flies_the_model(tmp_path):
    """The ODE of the header integrated by scipy with rhs flies as fly() with 32 RK4
    substeps to 1e-7 of each state's scale; the same equations by eq. 2 are far off."""
    model = rk4_model(32)
    inputs = hand_inputs(100)
    module = load_python(export(model, "python"), tmp_path / "own_export.py")
    own = own_flight(module, inputs, X0)[0]
    assert_flies_like(own, module.fly(inputs, X0), rtol=1e-7)
    with pytest.raises(AssertionError, match="largest difference"):
        assert_flies_like(own, in_scheme(model, "euler").fly_states(inputs, X0), rtol=1e-7)


def test_rk4_fly_position_is_the_odes(tmp_path):
    """An RK4 model's fly() position is x_dot = R(q) V flown as part of its RK4 state: within
    1e-7 of the path's scale of DOP853 on the same ODE (inputs held) at 4 substeps, and
    converging at RK4's order. Eq. 2's sum x' = x + R(q) V dt over the same flown states
    (what fly gave before) is about 1e-2 off however many the substeps."""
    inputs = hand_inputs(100)
    module = load_python(export(rk4_model(1), "python"), tmp_path / "position_export.py")
    reference = own_flight(module, inputs, X0)[1]
    scale = np.abs(reference).max()
    assert scale > 10.0  # metres: the flight goes somewhere
    errors = {}
    for substeps in (2, 4):
        model = rk4_model(substeps)
        flight = model.fly(inputs, X0)
        errors[substeps] = np.abs(flight.pos - reference).max() / scale
        world_vel = Rotation.from_quat(flight.quat[:, [1, 2, 3, 0]]).apply(flight.vel)
        summed = np.vstack([np.zeros(3), np.cumsum(world_vel[:-1] * model.dt, axis=0)])
        assert np.abs(summed - reference).max() / scale > 1e-3, substeps
    assert errors[4] < 1e-7 and errors[2] > 10.0 * errors[4], errors


def test_casadi_rhs_matches_the_python_rhs(tmp_path):
    casadi = pytest.importorskip(
        "casadi", reason="casadi is not installed (the [casadi] extra); its export is optional"
    )
    from gpquad.models.exports import casadi_functions

    model = rk4_model()
    inputs = hand_inputs(60)
    states = model.fly_states(inputs, X0)
    module = load_python(export(model, "python"), tmp_path / "casadi_rk4_export.py")
    functions = casadi_functions(model)
    assert set(functions) == {"commanded", "rhs"}  # no eq. 2 accel for an rk4 model
    exported = casadi.Function.deserialize(export(model, "casadi"))
    assert exported.name() == "rhs"
    lag = np.linspace(-1.0, 1.0, 6)
    for k in (0, 10, 25, 59):
        hist = history_rows(inputs, k, module.HISTORY)
        want = module.rhs(states[k], hist, lag)
        for fn in (functions["rhs"], exported):
            got = fn(states[k], hist, lag)
            np.testing.assert_allclose(np.array(got[0]).ravel(), want[0], rtol=1e-12, atol=1e-12)
            np.testing.assert_allclose(np.array(got[1]).ravel(), want[1], rtol=1e-12, atol=1e-12)
    run = tmp_path / "run"
    run.mkdir()
    (run / "model.json").write_text(export(model, "json"))
    saved_path = tmp_path / "m.casadi"
    assert main(["export", str(run), "--format", "casadi", "--out", str(saved_path)]) == 0
    saved = casadi.Function.load(str(saved_path))
    assert saved.name() == "rhs"
    hist = history_rows(inputs, 40, module.HISTORY)
    np.testing.assert_allclose(
        np.array(saved(states[40], hist, lag)[1]).ravel(),
        module.rhs(states[40], hist, lag)[1],
        rtol=1e-12,
    )
