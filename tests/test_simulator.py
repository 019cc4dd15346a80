"""The reference simulator: truth model, pilot, measurement noise."""

import dataclasses

import numpy as np
import pytest

from gpquad.data.simulator import simulate
from gpquad.errors import GpquadError
from gpquad.study.config import SimulatorConfig

INPUTS = ("u_P", "u_R", "u_Y", "u_T")
SHORT = dataclasses.replace(SimulatorConfig(), duration_s=40.0)


def test_flight_follows_its_equations():
    flight = simulate(SHORT, INPUTS)
    acc = flight.meta["true_acc"]
    # p_dot = 10.3 u_R(t-1) - 4.15 p at every step (t >= 1)
    expected = 10.3 * flight.inputs[:-1, 1] - 4.15 * flight.rates[1:, 0]
    assert np.abs(acc[1:, 3] - expected).max() < 1e-12
    # hover trim: u_T stays around 9.81 / 28.2 and the attitude stays small
    assert abs(flight.inputs[:, 3].mean() - 9.81 / 28.2) < 0.02
    assert np.abs(flight.rates).max() < 3.0


def test_measurement_noise_leaves_the_flight_unchanged():
    clean = simulate(SHORT, INPUTS)
    sd = {"attitude": 0.01, "velocity": 0.05, "rates": 0.02}
    noisy = simulate(dataclasses.replace(SHORT, measurement_noise=sd), INPUTS)
    assert np.array_equal(clean.inputs, noisy.inputs)
    assert np.std(noisy.vel - clean.vel) == pytest.approx(0.05, rel=0.05)
    assert np.std(noisy.rates - clean.rates) == pytest.approx(0.02, rel=0.05)
    # rotation angle between clean and noisy attitude: chi with 3 d.o.f. of SD 0.01
    dot = np.abs(np.sum(noisy.quat * clean.quat, axis=1)).clip(max=1.0)
    angle = 2 * np.arccos(dot)
    assert np.sqrt(np.mean(angle**2)) == pytest.approx(0.01 * np.sqrt(3), rel=0.05)
    assert np.allclose(np.linalg.norm(noisy.quat, axis=1), 1.0)


def test_bad_simulator_settings_are_named():
    with pytest.raises(GpquadError, match="pilot_gains"):
        simulate(dataclasses.replace(SHORT, pilot_gains={"u_X": {"phi": 1.0}}), INPUTS)
    with pytest.raises(GpquadError, match="diverged"):
        simulate(
            dataclasses.replace(SHORT, equations={"p_dot": "5*p + u_R"}, pilot_gains={}), INPUTS
        )


def _roll_recurrence(flight, a: float, b: float, dt: float) -> np.ndarray:
    """p at each sample of p_dot = -a p + b u_R(t-1) with u_R held over each sample:
    the exact solution p' = e^(-a dt) p + b (1 - e^(-a dt)) / a u."""
    u = flight.inputs[:, 1]
    p = np.empty(len(u))
    p[0] = flight.rates[0, 0]
    decay = np.exp(-a * dt)
    for k in range(len(u) - 1):
        p[k + 1] = decay * p[k] + b * (1.0 - decay) / a * u[max(k - 1, 0)]
    return p


def test_truth_is_flown_as_the_ode_it_is_printed_as():
    """The default simulator flies p_dot = 10.3 u_R(t-1) - 4.15 p by RK4: its roll rate is the
    ODE's exact solution with the inputs held; eq. 2 (the paper's discrete truth) is not."""
    dt = 1.0 / SHORT.rate_hz
    flight = simulate(SHORT, INPUTS)
    assert (SHORT.integrator, SHORT.substeps) == ("rk4", 8)
    exact = _roll_recurrence(flight, 4.15, 10.3, dt)
    scale = np.abs(exact).max()
    assert np.abs(flight.rates[:, 0] - exact).max() < 1e-8 * scale
    discrete = simulate(dataclasses.replace(SHORT, integrator="euler"), INPUTS)
    exact = _roll_recurrence(discrete, 4.15, 10.3, dt)
    assert np.abs(discrete.rates[:, 0] - exact).max() > 1e-3 * scale


def test_euler_truth_is_eq2_step_by_step():
    """integrator = "euler" flies the truth one eq. 2 step per sample, as the paper's model
    is defined: the flight of the plain loop over TruthModel and integrate_step."""
    from eq2_flight import eq2_flight

    cfg = dataclasses.replace(SHORT, duration_s=20.0, integrator="euler")
    flight, ref = simulate(cfg, INPUTS), eq2_flight(cfg, INPUTS)
    for name in ("quat", "vel", "rates", "pos", "inputs"):
        np.testing.assert_allclose(getattr(flight, name), getattr(ref, name), atol=1e-12)
    rk4 = simulate(dataclasses.replace(cfg, integrator="rk4"), INPUTS)
    assert np.abs(rk4.rates - ref.rates).max() > 1e-3  # the comparison sees a scheme change


@pytest.mark.parametrize(
    "change, field",
    [({"integrator": "rk5"}, "simulator.integrator"), ({"substeps": 0}, "simulator.substeps")],
)
def test_bad_truth_scheme_is_named(change, field):
    with pytest.raises(GpquadError, match=field.replace(".", r"\.")):
        simulate(dataclasses.replace(SHORT, **change), INPUTS)
