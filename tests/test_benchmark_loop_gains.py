"""Loop gains implied by identified roll and pitch equations (gpquad.benchmark.loop_gains)."""

import pytest

from gpquad.benchmark import loop_gains

INPUTS = ("u_P", "u_R", "u_Y", "u_T")
CONTROLLER = {"rate": 57.0, "angle": 310.0, "setpoint": 310.0, "motor_tau_s": 0.072}


def test_gains_of_a_hand_written_roll_equation_with_taps_lag_and_products():
    line = (
        "p_dot + 0.072 d(p_dot)/dt = -57*p - 310*phi + 200*u_R(t-1) + 90*u_R(t-3)"
        " + 20*u_R*u_T + 3*q*r + 2*v - 4*p*u_T + 4*p"
    )
    g = loop_gains.implied_gains("gpquad", line, "p_dot", INPUTS)
    # u_R*u_T at hover (u_T = 1) is 20 u_R; p*u_T - p cancels at hover
    assert g["rate"] == pytest.approx(57.0)
    assert g["angle"] == pytest.approx(310.0)
    assert g["setpoint"] == pytest.approx(310.0)
    assert g["setpoint_taps"] == {"0": pytest.approx(20.0), "1": 200.0, "3": 90.0}
    assert g["setpoint_delay_samples"] == pytest.approx((200 + 270) / 310)
    assert g["lag_s"] == 0.072


def test_pitch_equation_and_a_peers_lagged_features():
    g = loop_gains.implied_gains(
        "ols", "-46.6*q + -544*theta + 272*u_P_l0 + 272*u_P_l2 + 0.1*u_R_l0 + 1.5", "q_dot", INPUTS
    )
    assert (g["rate"], g["angle"], g["setpoint"]) == pytest.approx((46.6, 544.0, 544.0))
    assert g["setpoint_delay_samples"] == pytest.approx(1.0) and g["lag_s"] == 0.0


def test_an_equation_without_the_loops_terms_implies_zero_gains():
    g = loop_gains.implied_gains("gpquad", "p_dot = 410*u_R - 956*u_R(t-3)", "p_dot", INPUTS)
    assert g["rate"] == 0.0 and g["angle"] == 0.0 and g["setpoint"] == pytest.approx(-546.0)


def _cell(p_dot: str) -> dict:
    eqs = {"p_dot": p_dot, "q_dot": "q_dot = -46.6*q - 544*theta + 544*u_P"}
    return {
        "scenario": "rotorpy-angle",
        "method": "gpquad",
        "seed": 1,
        "equations_raw_inputs": {"hummingbird": eqs},
    }


def test_the_discrete_loop_of_issue_32_is_far_from_the_controller():
    """rotorpy's hummingbird (kp_att 544, kd_att 46.6) and the roll loop an Euler fit gave."""
    pytest.importorskip("rotorpy")
    bad = _cell("p_dot = -85*p - 876*phi + 714*u_R + 160*u_R(t-2)")
    info = {
        "scenarios": {
            "rotorpy-angle": {"kind": "rotorpy", "mode": "angle", "vehicles": ["hummingbird"]},
            "rotorpy-rate": {"kind": "rotorpy", "mode": "rate", "vehicles": ["hummingbird"]},
        }
    }
    gains = loop_gains.benchmark_gains(info, [bad])
    assert list(gains) == ["rotorpy-angle"]  # rate mode has no attitude loop to compare
    roll = gains["rotorpy-angle"]["cells"][0]["gains"]["hummingbird"]["p_dot"]
    assert roll["error"]["rate"] == pytest.approx(85 / 46.64 - 1)
    assert roll["error"]["angle"] == pytest.approx(876 / 544 - 1)
    assert roll["error"]["setpoint"] == pytest.approx(874 / 544 - 1)
    pitch = gains["rotorpy-angle"]["cells"][0]["gains"]["hummingbird"]["q_dot"]
    assert max(abs(e) for e in pitch["error"].values()) < 0.01
    text = loop_gains.markdown(gains)
    assert "| gpquad | 1 | hummingbird | p_dot | 85 (46.64, +82 %) |" in text
    assert "61 %" in text


def test_controller_gains_are_rotorpys():
    pytest.importorskip("rotorpy")
    assert loop_gains.controller_gains("crazyflie") == CONTROLLER
    hb = loop_gains.controller_gains("hummingbird")
    assert (hb["rate"], hb["angle"], hb["motor_tau_s"]) == (46.64, 544.0, 0.005)


def test_only_untrimmed_angle_mode_rotorpy_scenarios_apply():
    assert loop_gains.applies({"kind": "rotorpy", "mode": "angle", "config": {"trim": "none"}})
    assert not loop_gains.applies({"kind": "rotorpy", "mode": "angle", "config": {"trim": "mean"}})
    assert not loop_gains.applies({"kind": "simulator"})


def test_no_loop_gains_without_rotorpy(monkeypatch):
    def missing(vehicle):
        raise ImportError("No module named 'rotorpy'")

    monkeypatch.setattr(loop_gains, "controller_gains", missing)
    info = {"scenarios": {"rotorpy-angle": {"kind": "rotorpy", "mode": "angle", "vehicles": ["x"]}}}
    assert loop_gains.benchmark_gains(info, []) == {}
