"""Benchmark scorer against independent references: data replay, a hand-computed RSE,
gpquad's own rollout, divergence, and the paired comparison on the windows a diverging peer
flew (gpquad.benchmark.paired: RSE_gpquad(S) = RSE_peer(S) x SSE ratio, checked against
scoring gpquad on those windows directly)."""

import dataclasses

import numpy as np
import pytest

from gpquad.benchmark import evaluate
from gpquad.benchmark.paired import paired, paired_markdown
from gpquad.benchmark.rollout import MAX_LAG, fly, lagged_inputs
from gpquad.data.dataset import build_dataset
from gpquad.data.simulator import simulate
from gpquad.engine.kernels.flight_arrays import FlightArrays
from gpquad.engine.tree.export import from_sympy, parse_equation
from gpquad.engine.variables import TARGET_NAMES
from gpquad.models.equations import DiscoveredModel, Equation
from gpquad.models.scoring import rse
from gpquad.study.config import MEDIAN_MODEL, SimulatorConfig

INPUTS = ("u_P", "u_R", "u_Y", "u_T")
ALL_MEASURED = dict.fromkeys("uvwpqr", True)


@pytest.fixture(scope="module")
def noisy_test_data():
    """A short noisy reference flight, all of it held out (validation)."""
    sim = SimulatorConfig(
        duration_s=40.0,
        seed=3,
        measurement_noise={"attitude": 0.005, "velocity": 0.02, "rates": 0.01},
    )
    return build_dataset([simulate(sim, INPUTS)], validation_fraction=1.0, trim="mean")


def test_flying_the_datas_own_accelerations_reproduces_the_data(noisy_test_data):
    ds = noisy_test_data
    starts, steps = evaluate.horizon_windows(ds, 7.0)
    assert len(starts) == 5 and steps == 175
    pred = fly(lambda f, idx: ds.arrays.acc[idx], ds.arrays, starts, steps)
    data = evaluate.data_windows(ds, starts, steps)
    # velocities and rates to round-off (the noisy attitude is not the rates' integral, and
    # the accelerations are the inverse of velocities and rates only)
    np.testing.assert_allclose(pred[..., 3:], data[..., 3:], rtol=0, atol=1e-12)
    metrics = evaluate.score(
        lambda s, n: fly(lambda f, idx: ds.arrays.acc[idx], ds.arrays, s, n),
        ds,
        ALL_MEASURED,
        (1.0, 7.0, 30.0),
    )
    assert metrics["1s"]["windows"] == 39 and metrics["7s"]["windows"] == 5
    assert metrics["30s"]["windows"] == 1
    for h in ("1s", "7s", "30s"):
        assert metrics[h]["mean"] < 1e-20 and metrics[h]["diverged"] == 0


def _hand_dataset():
    """13 samples at 10 Hz, identity attitude, rates zero at the window starts 5 and 8."""
    n = 13
    vel = np.zeros((n, 3))
    vel[:, 0] = [0, 0, 0, 0, 0, 1.0, 2.0, 4.0, 3.0, 5.0, 1.0, 0.0, 2.0]
    vel[:, 2] = np.linspace(-1, 1, n)
    rates = np.zeros((n, 3))
    rates[:, 1] = [0, 0, 0, 0, 0, 0.0, 0.5, -0.5, 0.0, 1.0, 2.0, -1.0, 0.0]
    states = np.hstack([np.zeros((n, 3)), vel, rates])
    quat = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    arrays = FlightArrays(
        quat=quat,
        states=states,
        acc=np.zeros((n, 6)),
        inputs=np.zeros((n, 1)),
        rot=np.zeros((n, 9)),
        dt=0.1,
    )
    from gpquad.data.dataset import Dataset

    return Dataset(
        arrays=arrays,
        input_names=("u_T",),
        segments=[(0, n)],
        train=[],
        validation=[(0, n)],
        names=["hand"],
        trim={"u_T": 0.0},
    )


def test_zero_model_rse_matches_a_hand_computation():
    ds = _hand_dataset()
    # windows of 0.3 s = 3 steps after MAX_LAG = 5 samples of history: starts 5 and 8
    starts, steps = evaluate.horizon_windows(ds, 0.3)
    assert list(starts) == [5, 8] and steps == 3 and MAX_LAG == 5
    metrics = evaluate.score(
        lambda s, n: fly(lambda f, idx: np.zeros((len(idx), 6)), ds.arrays, s, n),
        ds,
        ALL_MEASURED,
        (0.3,),
    )
    # zero acceleration and zero rate at the start: every state stays at its start value.
    # u: window 1 predicts 1 for data 2, 4, 3; window 2 predicts 3 for data 5, 1, 0.
    # mean of the scored data (2, 4, 3, 5, 1, 0) = 2.5, sum of squares about it = 17.5.
    num_u = (1 - 2) ** 2 + (1 - 4) ** 2 + (1 - 3) ** 2 + (3 - 5) ** 2 + (3 - 1) ** 2 + 3**2
    assert metrics["0.3s"]["rse"]["u"] == pytest.approx(num_u / 17.5, rel=1e-12)
    # q: predicted 0 throughout; data 0.5, -0.5, 0, 1, 2, -1 (mean 1/3)
    q = np.array([0.5, -0.5, 0.0, 1.0, 2.0, -1.0])
    assert metrics["0.3s"]["rse"]["q"] == pytest.approx(
        (q**2).sum() / ((q - q.mean()) ** 2).sum(), rel=1e-12
    )
    # v, p, r are constant zero in the data: zero error over zero variance
    assert metrics["0.3s"]["rse"]["v"] == 0.0


def test_unmeasured_states_are_not_scored():
    ds = _hand_dataset()
    measured = {**ALL_MEASURED, "u": False}
    metrics = evaluate.score(
        lambda s, n: fly(lambda f, idx: np.zeros((len(idx), 6)), ds.arrays, s, n),
        ds,
        measured,
        (0.3,),
    )
    assert metrics["0.3s"]["rse"]["u"] is None
    others = [v for k, v in metrics["0.3s"]["rse"].items() if k != "u"]
    assert metrics["0.3s"]["mean"] == pytest.approx(np.mean(others))


def test_horizon_longer_than_the_test_data_is_skipped():
    metrics = evaluate.score(lambda s, n: None, _hand_dataset(), ALL_MEASURED, (30.0,))
    assert metrics["30s"]["windows"] == 0 and metrics["30s"]["mean"] is None


def test_diverging_model_is_counted_not_raised(noisy_test_data):
    ds = noisy_test_data

    starts, _ = evaluate.horizon_windows(ds, 7.0)

    def explode(f, idx):  # the first three windows get a huge acceleration
        return np.where(idx[:, None] < starts[3], 1e9, 0.0) * np.ones((1, 6))

    metrics = evaluate.score(lambda s, n: fly(explode, ds.arrays, s, n), ds, ALL_MEASURED, (7.0,))
    assert metrics["7s"]["diverged"] == 3 and metrics["7s"]["windows"] == 5
    assert np.isfinite(metrics["7s"]["mean"])  # the two windows with zero acceleration


def test_peer_rollout_matches_gpquads_rollout_for_the_same_equations(noisy_test_data):
    """The median model flown as a gpquad model (trees, kernels.rollout.rollout) and as a
    'lagged-feature' model through the benchmark rollout gives the same states."""
    ds = noisy_test_data
    eqs = {}
    for t in TARGET_NAMES:
        expr, delays = parse_equation(MEDIAN_MODEL[t], INPUTS)
        tree = from_sympy(expr, delays, INPUTS)
        eqs[t] = Equation(t, tree, INPUTS, 0.0, 0.0, {})
    model = DiscoveredModel(eqs, INPUTS, {}, ds.dt, 0, {})
    trim = np.array([ds.trim[n] for n in INPUTS])
    raw = dataclasses.replace(ds, arrays=ds.arrays._replace(inputs=ds.arrays.inputs + trim))

    def predict(f, idx):  # the same six equations from the lagged-feature columns
        lag = lagged_inputs(raw.arrays.inputs, idx)
        phi, theta, u, v, w, p, q, r = (f[:, i] for i in (0, 1, 3, 4, 5, 6, 7, 8))
        u_p, u_r1, u_y2, u_t5 = lag[:, 0], lag[:, 6 + 1], lag[:, 12 + 2], lag[:, 18 + 5]
        return np.column_stack(
            [
                10.0 * theta - 0.6 * u,
                -9.2 * phi - 0.6 * v,
                28.2 * u_t5 - w - 9.81,
                10.3 * u_r1 - 4.15 * p,
                -9.8 * u_p - 3.3 * q,
                -7.8 * u_y2 - 1.9 * r,
            ]
        )

    starts, steps = evaluate.horizon_windows(ds, 7.0)
    ours = fly(predict, raw.arrays, starts, steps)
    theirs = model.simulate(raw, starts, steps)
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-9)


def test_window_sse_is_rse_numerator_window_by_window():
    ds = _hand_dataset()
    metrics = evaluate.score(
        lambda s, n: fly(lambda f, idx: np.zeros((len(idx), 6)), ds.arrays, s, n),
        ds,
        ALL_MEASURED,
        (0.3,),
    )
    sse = metrics["0.3s"]["window_sse"]
    # u: window 1 predicts 1 for data 2, 4, 3; window 2 predicts 3 for data 5, 1, 0
    assert sse[0][0] == 1 + 9 + 4 and sse[1][0] == 4 + 4 + 9
    assert (sse[0][0] + sse[1][0]) / 17.5 == pytest.approx(metrics["0.3s"]["rse"]["u"])


def _cells(ds, peer_acc, our_acc, horizon=7.0):
    score = {
        m: evaluate.score(lambda s, n, a=a: fly(a, ds.arrays, s, n), ds, ALL_MEASURED, (horizon,))
        for m, a in (("sindy", peer_acc), ("gpquad", our_acc))
    }
    return [
        {"scenario": "x", "method": "sindy", "seed": 0, "metrics": score["sindy"]},
        {"scenario": "x", "method": "gpquad", "seed": 1, "metrics": score["gpquad"]},
    ]


def test_gpquad_is_scored_on_exactly_the_windows_the_peer_flew(noisy_test_data):
    ds = noisy_test_data
    starts, steps = evaluate.horizon_windows(ds, 7.0)

    def explode(f, idx):  # the peer diverges on the first three windows, zero elsewhere
        return np.where(idx[:, None] < starts[3], 1e9, 0.0) * np.ones((1, 6))

    def ours(f, idx):  # a model that flies everywhere, with some error
        return np.full((len(idx), 6), 0.05)

    rows = paired(_cells(ds, explode, ours))
    assert len(rows) == 1
    row = rows[0]
    assert (row["peer"], row["horizon"], row["flown"], row["windows"]) == ("sindy", "7s", [2], 5)
    flown = starts[3:]
    data = evaluate.data_windows(ds, flown, steps)
    direct = rse(fly(ours, ds.arrays, flown, steps), data)
    assert row["gpquad_rse"]["mean"] == pytest.approx(direct.mean(), rel=1e-5)
    assert row["peer_rse"] == pytest.approx(
        rse(fly(explode, ds.arrays, flown, steps), data).mean(), rel=1e-12
    )
    # over every window (what the summary table shows) gpquad's number is another one
    everywhere = rse(fly(ours, ds.arrays, starts, steps), evaluate.data_windows(ds, starts, steps))
    assert abs(everywhere.mean() - direct.mean()) > 1e-3 * direct.mean()
    assert "| x | sindy | 7s | 2 of 5 |" in paired_markdown(rows)


def test_no_row_without_a_diverged_peer_or_per_window_errors(noisy_test_data):
    ds = noisy_test_data
    zero = lambda f, idx: np.zeros((len(idx), 6))  # noqa: E731
    assert paired(_cells(ds, zero, zero)) == []  # the peer flew every window
    starts, _ = evaluate.horizon_windows(ds, 7.0)
    explode = lambda f, idx: np.where(idx[:, None] < starts[3], 1e9, 0.0) * np.ones((1, 6))  # noqa: E731
    cells = _cells(ds, explode, zero)
    del cells[1]["metrics"]["7s"]["window_sse"]  # a cell from before per-window errors
    assert paired(cells) == [] and paired_markdown([]) == ""


def test_gpquad_diverging_where_the_peer_flew_loses(noisy_test_data):
    ds = noisy_test_data
    starts, _ = evaluate.horizon_windows(ds, 7.0)
    first = lambda f, idx: np.where(idx[:, None] < starts[1], 1e9, 0.0) * np.ones((1, 6))  # noqa: E731
    last = lambda f, idx: np.where(idx[:, None] >= starts[4], 1e9, 0.0) * np.ones((1, 6))  # noqa: E731
    rows = paired(_cells(ds, first, last))
    assert rows[0]["gpquad_rse"]["mean"] == np.inf
