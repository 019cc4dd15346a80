"""The log pipeline's building blocks: one clock, gaps, hold, filter phase, segmentation."""

import dataclasses

import numpy as np
import pandas as pd
import pytest

from gpquad.data.flight import enu_flu_quat, flip_body, flip_world
from gpquad.data.pipeline import LogTable, flights_from_log, lowpass_taps, zero_phase_fir
from gpquad.data.plausibility import check_stream_time, runs
from gpquad.data.streams import Stream, in_flight_mask, resample
from gpquad.errors import GpquadError
from gpquad.study.config import DataConfig


@pytest.mark.parametrize("taps", [200, 201, 51])
def test_fir_has_no_phase_lag(taps):
    """A sine delayed by a causal FIR of L taps would lag (L-1)/2 samples; ours does not."""
    rate = 100.0
    t = np.arange(3000) / rate
    x = np.sin(2 * np.pi * 1.0 * t + 0.3)
    h = lowpass_taps(taps, 5.0, rate)
    t_out, y = zero_phase_fir(t, x, h)
    assert len(y) == len(t) - taps + 1
    gain = abs(np.sum(h * np.exp(-2j * np.pi * 1.0 * np.arange(taps) / rate)))
    expected = gain * np.sin(2 * np.pi * 1.0 * t_out + 0.3)
    assert np.abs(y - expected).max() < 1e-9  # exact: symmetric taps, centred time stamps
    # the lag estimated from the zero crossings is below a microsecond (a causal filter: ~1 s)
    causal_lag = (taps - 1) / 2 / rate
    lag = np.angle(
        np.sum(y * np.exp(-2j * np.pi * t_out)) / np.sum(expected * np.exp(-2j * np.pi * t_out))
    ) / (2 * np.pi)
    assert abs(lag) < 1e-6 < causal_lag


def test_fir_attenuates_above_cutoff():
    rate = 100.0
    t = np.arange(4000) / rate
    h = lowpass_taps(200, 5.0, rate)
    _, y_pass = zero_phase_fir(t, np.sin(2 * np.pi * 2.0 * t), h)
    _, y_stop = zero_phase_fir(t, np.sin(2 * np.pi * 15.0 * t), h)
    assert np.abs(y_pass).max() == pytest.approx(1.0, abs=0.01)
    assert np.abs(y_stop).max() < 1e-3


def _stream(name, t, values, cols, kind, required=True):
    return Stream(
        name,
        np.asarray(t, float),
        np.asarray(values, float).reshape(len(t), -1),
        tuple(cols),
        kind,
        f"{name}.csv",
        "timestamp",
        required,
    )


def test_resample_interpolates_states_holds_inputs_and_marks_gaps():
    t_state = np.arange(0.0, 10.0, 0.012)
    t_state = t_state[(t_state < 4.0) | (t_state > 4.5)]  # a 0.5 s hole
    t_in = np.arange(0.0, 10.0, 0.02)
    state = _stream("att", t_state, 2.0 * t_state + 1.0, ["x"], "state")
    inp = _stream("ctl", t_in, np.floor(t_in * 10), ["u"], "hold")
    table, valid, info = resample([state, inp], 100.0, 0.2)
    g = table["t"].to_numpy()
    assert np.allclose(np.diff(g), 0.01)
    ok = valid
    assert np.allclose(table["x"].to_numpy()[ok], 2.0 * g[ok] + 1.0, atol=1e-12)
    held = np.floor(t_in[np.searchsorted(t_in, g, side="right") - 1] * 10)
    assert np.array_equal(table["u"].to_numpy(), held)
    gap = (g > t_state[t_state < 4.0][-1]) & (g < t_state[t_state > 4.5][0])
    assert np.array_equal(~valid, gap)
    assert info[0]["gaps"] == 1 and info[1]["gaps"] == 0


def test_nan_rows_become_gaps_not_interpolation():
    t = np.arange(0.0, 10.0, 0.01)
    x = np.sin(t)
    x[300:400] = np.nan  # a NaN run of 1 s
    table, valid, info = resample([_stream("att", t, x, ["x"], "state")], 100.0, 0.2)
    assert info[0]["nan_rows"] == 100
    bad = runs(~valid)
    assert len(bad) == 1
    a, b = bad[0]
    assert table["t"][a] == pytest.approx(3.0, abs=0.011)
    assert table["t"][b] == pytest.approx(4.0, abs=0.011)


def test_quaternion_sign_flips_are_made_continuous():
    t = np.arange(0.0, 2.0, 0.01)
    ang = 0.5 * t
    q = np.column_stack([np.cos(ang / 2), np.sin(ang / 2), 0 * t, 0 * t])
    q[1::2] *= -1  # same rotations, alternating sign as some logs store them
    table, valid, _ = resample([_stream("att", t, q, ["qw", "qx", "qy", "qz"], "quat")], 50.0, 0.2)
    g = table["t"].to_numpy()
    out = table[["qw", "qx", "qy", "qz"]].to_numpy()
    assert np.allclose(np.abs(out[:, 0]), np.cos(0.25 * g), atol=1e-4)
    assert np.allclose(np.linalg.norm(out, axis=1), 1.0)


@pytest.mark.parametrize(
    "t, word", [([0.0, 0.1, 0.1, 0.2], "duplicate"), ([0.0, 0.2, 0.1, 0.3], "backwards")]
)
def test_bad_timestamps_are_one_line_errors(t, word):
    with pytest.raises(GpquadError) as err:
        check_stream_time(np.array(t), "log.csv", "timestamp")
    msg = str(err.value)
    assert word in msg and "log.csv" in msg and "timestamp" in msg and "\n" not in msg


def test_all_nan_stream_is_an_error():
    t = np.arange(0.0, 1.0, 0.01)
    with pytest.raises(GpquadError, match="every row"):
        resample([_stream("att", t, np.full(len(t), np.nan), ["x"], "state")], 100.0, 0.2)


def test_runs():
    assert runs(np.array([0, 1, 1, 0, 1], bool)) == [(1, 3), (4, 5)]
    assert runs(np.zeros(3, bool)) == []


def test_in_flight_mask_modes_and_dip_bridging():
    t = np.arange(0.0, 20.0, 0.01)
    thrust = np.where((t > 2) & (t < 18), 0.4, 0.0)
    thrust[(t > 9) & (t < 9.5)] = 0.1  # a short dip in flight: bridged
    armed = t > 1
    base = DataConfig()
    m = in_flight_mask(t, armed, thrust, base, "x")
    assert runs(m) == [(201, 1800)]
    m = in_flight_mask(t, armed, thrust, dataclasses.replace(base, segment="armed"), "x")
    assert m.sum() == (t > 1).sum()
    m = in_flight_mask(
        t, armed, thrust, dataclasses.replace(base, segment="range", time_range=(5.0, 6.0)), "x"
    )
    assert t[m][0] == pytest.approx(5.0) and t[m][-1] == pytest.approx(6.0)
    with pytest.raises(GpquadError, match="no arming state"):
        in_flight_mask(t, None, thrust, dataclasses.replace(base, segment="armed"), "x")


def test_frame_round_trips():
    rng = np.random.default_rng(3)
    q = rng.normal(size=(50, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q[q[:, 0] < 0] *= -1
    assert np.allclose(enu_flu_quat(enu_flu_quat(q)), q, atol=1e-12)
    v = rng.normal(size=(50, 3))
    assert np.array_equal(flip_body(flip_body(v)), v)
    assert np.array_equal(flip_world(flip_world(v)), v)
    # ENU east is NED y, ENU up is NED -z
    assert np.array_equal(flip_world(np.array([[1.0, 2.0, 3.0]])), [[2.0, 1.0, -3.0]])


def _log_table(n_s=40.0, rate=100.0, omega=0.8):
    """A LogTable of a craft yawing at a constant rate with a world velocity, all measured."""
    t = np.arange(0.0, n_s, 1.0 / rate)
    psi = omega * t
    table = pd.DataFrame(
        {
            "t": t,
            "qw": np.cos(psi / 2),
            "qx": 0.0,
            "qy": 0.0,
            "qz": np.sin(psi / 2),
            "p": 0.0,
            "q": 0.0,
            "r": omega,
            "vx": 1.0,
            "vy": 0.0,
            "vz": -0.5,
            "u_T": 0.5,
        }
    )
    ones = np.ones(len(t), bool)
    measured = {k: "measured (test)" for k in ("phi", "theta", "psi", "u", "v", "w", "p", "q", "r")}
    return LogTable(
        "synthetic", "synthetic.csv", table, ones, ones.copy(), rate, ("u_T",), measured
    )


def test_pipeline_derives_exact_rates_and_body_velocity():
    data = DataConfig(inputs=("u_T",), min_segment_s=1.0)
    (flight,) = flights_from_log(_log_table(), data)
    assert flight.dt == pytest.approx(0.04)
    # filtering keeps a constant yaw rate; rates from the quaternion reproduce it exactly
    assert np.allclose(flight.rates[:, 2], 0.8, atol=1e-9)
    assert np.allclose(flight.rates[:, :2], 0.0, atol=1e-9)
    # world velocity (1, 0, -0.5) seen from a body yawed by psi
    psi = 0.8 * flight.t
    assert np.allclose(flight.vel[:, 0], np.cos(psi), atol=1e-6)
    assert np.allclose(flight.vel[:, 1], -np.sin(psi), atol=1e-6)
    assert np.allclose(flight.vel[:, 2], -0.5, atol=1e-9)
    # edges without full filter support are dropped: 199 samples at 100 Hz
    assert flight.t[0] == pytest.approx(99.5 / 100.0)
    assert any("zero-phase FIR" in s for s in flight.meta["pipeline"])


def test_gap_splits_a_flight_and_short_pieces_are_dropped():
    log = _log_table(n_s=60.0)
    log.valid[3000:3050] = False  # a 0.5 s gap at 30 s
    log.in_flight[:200] = False
    data = DataConfig(inputs=("u_T",), min_segment_s=10.0)
    flights = flights_from_log(log, data)
    assert len(flights) == 2
    assert flights[0].t[-1] < 30.0 < 30.5 < flights[1].t[0]
    log.in_flight[:] = False
    with pytest.raises(GpquadError, match="no usable flight"):
        flights_from_log(log, data)
