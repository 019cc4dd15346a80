"""Benchmark peers and exact-structure recovery, on a short reference flight."""

import numpy as np
import pytest

from gpquad.benchmark import peers
from gpquad.benchmark.recovery import recovered, truth_terms
from gpquad.benchmark.scenarios import make_scenario, time_split
from gpquad.data.simulator import simulate
from gpquad.study.config import MEDIAN_MODEL, SimulatorConfig

INPUTS = ("u_P", "u_R", "u_Y", "u_T")


@pytest.fixture(scope="module")
def median_scenario():
    """60 s of the median model for training, 40 s of another seed for testing."""
    # eq. 2 truth: its one-step accelerations are exactly linear in the data
    train = simulate(SimulatorConfig(duration_s=60.0, seed=0, integrator="euler"), INPUTS)
    test = simulate(SimulatorConfig(duration_s=40.0, seed=7, integrator="euler"), INPUTS)
    return make_scenario(
        "small", [train], [test], trim="mean", truth=dict(MEDIAN_MODEL), validation_fraction=0.25
    )


def test_ols_on_exact_linear_data_recovers_the_median_model(median_scenario):
    """The median model is linear in the state and lagged inputs and the data's
    accelerations are exact, so least squares finds it and the recovery rule says so."""
    peer, _ = peers.fit_peer("ols", median_scenario.fit, 0)
    assert peers.recovery(peer, median_scenario) == dict.fromkeys(MEDIAN_MODEL, True)
    x, y = peers.regression_data(median_scenario.test, median_scenario.test.validation)
    np.testing.assert_allclose(peer.predict(x, None), y, atol=1e-8)


def test_recovery_rejects_a_wrong_coefficient_delay_or_term(median_scenario):
    fit = median_scenario.fit
    trim = fit.trim["u_R"]
    good = f"10.3*(u_R_l1 + {trim!r}) - 4.15*p"  # the model's trimmed inputs
    assert recovered(good, MEDIAN_MODEL["p_dot"], "p_dot", fit)
    assert not recovered(good.replace("10.3", "10.9"), MEDIAN_MODEL["p_dot"], "p_dot", fit)
    assert not recovered(good.replace("u_R_l1", "u_R_l2"), MEDIAN_MODEL["p_dot"], "p_dot", fit)
    assert not recovered(good + " + 3*q", MEDIAN_MODEL["p_dot"], "p_dot", fit)
    assert not recovered("0", MEDIAN_MODEL["p_dot"], "p_dot", fit)
    assert truth_terms(MEDIAN_MODEL["a_z"], INPUTS) == {"u_T_l5": 28.2, "w": -1.0, "1": -9.81}


def test_zero_peer_predicts_zero(median_scenario):
    peer, _ = peers.fit_peer("zero", median_scenario.fit, 0)
    assert np.all(peer.predict(np.ones((3, 33)), np.arange(3)) == 0)
    assert not any(peers.recovery(peer, median_scenario).values())


def test_time_split_keeps_order_and_cuts_one_flight():
    flights = [simulate(SimulatorConfig(duration_s=d, seed=1), INPUTS) for d in (4.0, 8.0, 4.0)]
    train, test = time_split(flights, 0.7)  # 400 samples: cut at 280 = 100 + 180
    assert [len(f) for f in train] == [100, 180] and [len(f) for f in test] == [20, 100]
    np.testing.assert_array_equal(test[0].vel, flights[1].vel[180:])


def test_sindy_picks_a_threshold_and_flies(median_scenario):
    pytest.importorskip("pysindy")
    peer, _ = peers.fit_peer("sindy", median_scenario.fit, 0)
    assert peer.settings["threshold"] in peers.THRESHOLDS
    # exact data: only terms below the smallest threshold (0.01: the intercepts, such as
    # 10.3 x trim of u_R, about 1 % of the RMS) are lost: small error, not round-off
    assert peer.settings["validation_rse_7s"] < 0.01
    x, y = peers.regression_data(median_scenario.test, median_scenario.test.validation)
    err = np.sqrt(np.mean((peer.predict(x, None) - y) ** 2, axis=0))
    assert np.all(err < 0.02 * np.sqrt(np.mean(y**2, axis=0)))
