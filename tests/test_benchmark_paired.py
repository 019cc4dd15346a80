"""Per-window squared errors and the paired comparison on the windows a peer flew
(gpquad.benchmark.paired): the identity RSE_gpquad(S) = RSE_peer(S) x SSE ratio, checked
against scoring gpquad on those windows directly."""

import numpy as np
import pytest
from test_benchmark_rollout import ALL_MEASURED, _hand_dataset, noisy_test_data  # noqa: F401

from gpquad.benchmark import evaluate
from gpquad.benchmark.paired import paired, paired_markdown
from gpquad.benchmark.rollout import fly
from gpquad.models.scoring import rse


def test_window_sse_is_rse_numerator_window_by_window():
    ds = _hand_dataset()
    metrics = evaluate.score(lambda s, n: fly(lambda f, idx: np.zeros((len(idx), 6)),
                                              ds.arrays, s, n), ds, ALL_MEASURED, (0.3,))
    sse = metrics["0.3s"]["window_sse"]
    # u: window 1 predicts 1 for data 2, 4, 3; window 2 predicts 3 for data 5, 1, 0
    assert sse[0][0] == 1 + 9 + 4 and sse[1][0] == 4 + 4 + 9
    assert (sse[0][0] + sse[1][0]) / 17.5 == pytest.approx(metrics["0.3s"]["rse"]["u"])


def _cells(ds, peer_acc, our_acc, horizon=7.0):
    score = {m: evaluate.score(lambda s, n, a=a: fly(a, ds.arrays, s, n), ds, ALL_MEASURED,
                               (horizon,)) for m, a in (("sindy", peer_acc), ("gpquad", our_acc))}
    return [{"scenario": "x", "method": "sindy", "seed": 0, "metrics": score["sindy"]},
            {"scenario": "x", "method": "gpquad", "seed": 1, "metrics": score["gpquad"]}]


def test_gpquad_is_scored_on_exactly_the_windows_the_peer_flew(noisy_test_data):  # noqa: F811
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
        rse(fly(explode, ds.arrays, flown, steps), data).mean(), rel=1e-12)
    # over every window (what the summary table shows) gpquad's number is another one
    everywhere = rse(fly(ours, ds.arrays, starts, steps), evaluate.data_windows(ds, starts, steps))
    assert abs(everywhere.mean() - direct.mean()) > 1e-3 * direct.mean()
    assert "| x | sindy | 7s | 2 of 5 |" in paired_markdown(rows)


def test_no_row_without_a_diverged_peer_or_per_window_errors(noisy_test_data):  # noqa: F811
    ds = noisy_test_data
    zero = lambda f, idx: np.zeros((len(idx), 6))  # noqa: E731
    assert paired(_cells(ds, zero, zero)) == []   # the peer flew every window
    starts, _ = evaluate.horizon_windows(ds, 7.0)
    explode = lambda f, idx: np.where(idx[:, None] < starts[3], 1e9, 0.0) * np.ones((1, 6))  # noqa: E731
    cells = _cells(ds, explode, zero)
    del cells[1]["metrics"]["7s"]["window_sse"]  # a cell from before per-window errors
    assert paired(cells) == [] and paired_markdown([]) == ""


def test_gpquad_diverging_where_the_peer_flew_loses(noisy_test_data):  # noqa: F811
    ds = noisy_test_data
    starts, _ = evaluate.horizon_windows(ds, 7.0)
    first = lambda f, idx: np.where(idx[:, None] < starts[1], 1e9, 0.0) * np.ones((1, 6))  # noqa: E731
    last = lambda f, idx: np.where(idx[:, None] >= starts[4], 1e9, 0.0) * np.ones((1, 6))  # noqa: E731
    rows = paired(_cells(ds, first, last))
    assert rows[0]["gpquad_rse"]["mean"] == np.inf
