"""Thrust/drag regressions, dead reckoning, sync and config on data with a known truth built
here (no rotorpy needed)."""

from __future__ import annotations

import numpy as np
import pytest

from gpquad.errors import GpquadError
from gpquad.physics.aero import THRUST_MODELS, drag_regressors, thrust_regressors
from gpquad.physics.deadreckon import MODELS, integrate, position_rmse
from gpquad.physics.regression import METHODS, fit
from gpquad.physics.sync import causal_moving_average, peak_sync, residual_rmse, xcorr_sync

TRUE = {"k_t": 5.57e-6, "k_z": 2.32e-4, "k_h": 0.0136}


def _forward_flight(rng, n=3000):
    """Rotor speeds and body velocities of a forward flight, and m f_z from eq. (19)."""
    t = np.arange(n) * 0.01
    rotor = 470 + 60 * np.sin(0.7 * t)[:, None] + rng.normal(0, 20, (n, 4))
    vel = np.column_stack([3 + 2 * np.sin(0.3 * t), 0.5 * np.cos(0.2 * t), np.sin(0.9 * t)])
    X = thrust_regressors("refined", rotor, vel)
    y = X @ np.array([TRUE[k] for k in THRUST_MODELS["refined"]])
    return rotor, vel, y + rng.normal(0, 0.05, n)


@pytest.mark.parametrize("method", METHODS)
def test_refined_thrust_recovers_known_coefficients(method):
    rng = np.random.default_rng(3)
    rotor, vel, y = _forward_flight(rng)
    X = thrust_regressors("refined", rotor, vel)
    res = fit(X[:2000], y[:2000], THRUST_MODELS["refined"], method, X_val=X[2000:], y_val=y[2000:])
    for name, c, se in zip(res["names"], res["coef"], res["se"]):
        assert abs(c - TRUE[name]) < 4 * se + 1e-3 * abs(TRUE[name]), (name, c, se)
        assert se > 0
    assert res["r2"] > 0.99 and res["r2_val"] > 0.99


def test_refined_beats_standard_and_standard_is_biased_in_forward_flight():
    rng = np.random.default_rng(4)
    rotor, vel, y = _forward_flight(rng)
    scores = {}
    for model in THRUST_MODELS:
        X = thrust_regressors(model, rotor, vel)
        scores[model] = fit(
            X[:2000], y[:2000], THRUST_MODELS[model], X_val=X[2000:], y_val=y[2000:]
        )
    assert scores["refined"]["rmse_val"] < 0.5 * scores["standard"]["rmse_val"]
    assert abs(scores["standard"]["coef"][0] / TRUE["k_t"] - 1) > 0.02


def test_drag_regression_with_and_without_parasitic_term():
    rng = np.random.default_rng(5)
    n = 2000
    rotor = 470 + rng.normal(0, 30, (n, 4))
    vel = np.column_stack([rng.uniform(-4, 4, n), rng.uniform(-4, 4, n), rng.normal(0, 0.3, n)])
    fx = -9.5e-4 * vel[:, 0] * rotor.mean(1) - 0.01 * np.linalg.norm(vel, axis=1) * vel[:, 0]
    X, names = drag_regressors(0, rotor, vel, parasitic=True)
    res = fit(X, fx + rng.normal(0, 0.05, n), names)
    assert names == ["k_dx", "c_dx"]
    for c, se, true in zip(res["coef"], res["se"], (-9.5e-4, -0.01)):
        assert abs(c - true) < 4 * se and se < 0.1 * abs(true)
    X1, _ = drag_regressors(0, rotor, vel, parasitic=False)
    biased = fit(X1, fx, ["k_dx"])["coef"][0]
    assert biased < -9.5e-4 * 1.02  # the frame drag leaks into k_dx when not modelled


def test_regression_rejects_bad_input():
    X = np.ones((3, 2))
    with pytest.raises(GpquadError, match="method"):
        fit(X, np.ones(3), ["a", "b"], "lasso")
    with pytest.raises(GpquadError, match="samples"):
        fit(X[:2], np.ones(2), ["a", "b"])


def _yawing_cruise(n=600, dt=0.01, yaw_rate=1.5, speed=2.0):
    """Level vehicle yawing at a constant rate while flying a straight line at constant
    world velocity: the specific force is (0, 0, g) and the body velocity turns."""
    from scipy.spatial.transform import Rotation

    t = np.arange(n) * dt
    rot = Rotation.from_euler("z", (yaw_rate * t)[:, None]).as_matrix()
    vel = np.tile([speed, 0.0, 0.0], (n, 1))
    pos = np.column_stack([speed * t, np.zeros(n), np.ones(n)])
    w_hover = np.sqrt(0.5 * 9.81 / (4 * TRUE["k_t"]))
    return {
        "t": t,
        "pos": pos,
        "vel": vel,
        "rot": rot,
        "rotor": np.full((n, 4), w_hover),
        "force": np.tile([0.0, 0.0, 9.81], (n, 1)),
    }


COEF = {
    "drag": {"k_dx": 0.0, "k_dy": 0.0},
    "standard": {"k_t": TRUE["k_t"]},
    "refined": {"k_t": TRUE["k_t"], "k_z": 0.0, "k_h": 0.0},
}


def test_coriolis_model_is_exact_and_the_others_drift_when_yawing():
    meas = _yawing_cruise()
    errors = {m: position_rmse(integrate(m, meas, COEF, 0.5), meas["pos"]) for m in MODELS}
    assert max(errors["coriolis"]) < 1e-9
    for m in ("accelerometer", "base", "refined"):
        assert max(errors[m]) > 0.5  # without -Omega x V the body velocity does not turn


def test_without_rotation_all_models_agree_with_the_truth():
    meas = _yawing_cruise(yaw_rate=0.0)
    for m in MODELS:
        assert max(position_rmse(integrate(m, meas, COEF, 0.5), meas["pos"])) < 1e-9


def test_causal_moving_average_matches_a_loop_and_uses_only_the_past():
    x = np.random.default_rng(6).normal(size=(50, 2))
    y = causal_moving_average(x, 5)
    ref = np.array([x[max(0, k - 4) : k + 1].mean(axis=0) for k in range(50)])
    np.testing.assert_allclose(y, ref)
    x2 = x.copy()
    x2[30:] += 100.0  # a change in the future leaves the past alone
    np.testing.assert_allclose(causal_moving_average(x2, 5)[:30], y[:30])
    with pytest.raises(GpquadError):
        causal_moving_average(x, 0)


def test_peak_and_cross_correlation_sync_recover_a_known_offset():
    rng = np.random.default_rng(7)
    t_a = np.arange(0, 30, 0.002)  # Betaflight clock, 500 Hz
    roll = np.deg2rad(40) * np.exp(-(((t_a - 12.0) / 0.3) ** 2)) + 0.1 * np.sin(1.3 * t_a)
    offset = 3.217
    t_b = np.arange(-5, 40, 1 / 120)  # motion capture, 120 Hz, starts early
    roll_b = np.interp(t_b - offset, t_a, roll, left=0, right=0) + rng.normal(0, 0.002, len(t_b))
    peak = peak_sync(t_a, roll, t_b, roll_b)
    assert peak["offset_s"] == pytest.approx(offset, abs=2 / 120)  # one 120 Hz sample
    assert peak["t_in_b"] == pytest.approx(offset, abs=2 / 120)  # arm time of log A
    assert peak["t_end_b"] - peak["t_in_b"] == pytest.approx(t_a[-1], abs=1e-9)
    xc = xcorr_sync(t_a, roll, t_b, roll_b)
    assert xc["offset_s"] == pytest.approx(offset, abs=0.005)
    assert residual_rmse(t_a, roll, t_b, roll_b, peak["offset_s"]) < 0.01
    assert residual_rmse(t_a, roll, t_b, roll_b, peak["offset_s"] + 0.5) > 0.02


def test_config_errors_name_the_field(tmp_path):
    from gpquad.physics.config import load_physics_config

    good = tmp_path / "ok.toml"
    good.write_text('seed = 3\n[regression]\nmethod = "gls"\n[noise]\naccel_noise_sd = 0.2\n')
    cfg = load_physics_config(good)
    assert cfg.seed == 3 and cfg.regression.method == "gls" and cfg.noise.accel_noise_sd == 0.2
    cases = {
        '[regression]\nmethod = "ridge"\n': "regression.method",
        "[truth]\nspeeed = 2\n": "truth.speeed",
        "[noise]\naccel_noise_sd = -1\n": "noise.accel_noise_sd",
        '[deadreckon]\nmanoeuvres = ["Z"]\n': "deadreckon.manoeuvres",
        "colour = 1\n": "colour",
    }
    for text, fieldname in cases.items():
        bad = tmp_path / "bad.toml"
        bad.write_text(text)
        with pytest.raises(GpquadError) as exc:
            load_physics_config(bad)
        assert exc.value.field == fieldname


def test_cli_config_error_is_one_line(tmp_path, capsys):
    from gpquad.cli.commands import main

    bad = tmp_path / "bad.toml"
    bad.write_text('[truth]\nvehicle = "blimp"\n')
    assert main(["physics", "thrust", str(bad), "--out", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "truth.vehicle" in err[0]


def test_drag_fit_warns_when_an_axis_is_not_excited(monkeypatch):
    from gpquad.physics import identify
    from gpquad.physics.config import DragConfig, PhysicsConfig

    rng = np.random.default_rng(8)
    n = 400
    vel = np.column_stack([np.linspace(0, 4, n), rng.normal(0, 0.01, n), np.zeros(n)])
    rotor = np.full((n, 4), 470.0) + rng.normal(0, 5, (n, 4))
    # y is barely excited and its noise happens to point the wrong way: the bad case
    force = np.column_stack(
        [-9.5e-4 * vel[:, 0] * rotor.mean(1), 1e-3 * vel[:, 1] * rotor.mean(1), np.full(n, 9.81)]
    )
    flight = {"rotor": rotor, "vel_body": vel, "force": force, "name": "forward"}
    monkeypatch.setattr(identify, "load_flight", lambda cfg, name, yaw=False: flight)
    monkeypatch.setattr(
        identify,
        "vehicle_params",
        lambda name: {"num_rotors": 4, "mass": 0.5, "k_eta": 5.57e-6, "k_d": 1.19e-4},
    )
    res = identify.identify_drag(PhysicsConfig(drag=DragConfig(flights=("forward",))))
    assert res["fits"]["x"]["relative_error"]["k_dx"] == pytest.approx(0.0, abs=0.02)
    warnings = res.get("warnings", [])
    assert any(w.startswith("y: k_dy") for w in warnings)
    assert not any(w.startswith("x") for w in warnings)
