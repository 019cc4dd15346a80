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
