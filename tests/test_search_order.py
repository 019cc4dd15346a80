"""The searches go to the worker processes longest first (gpquad.study.fit.SEARCH_ORDER);
each is reported as it arrives, and recorded (history, checkpoint) in target order."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from export_models import HAND_TRIM, equation

from gpquad.engine.variables import TARGET_NAMES
from gpquad.study import fit
from gpquad.study.config import Config
from gpquad.study.search import Progress
from gpquad.study.store import HistoryWriter


class Said:
    def __init__(self):
        self.lines: list[str] = []

    def write(self, text):
        self.lines.extend(line for line in text.splitlines() if line.strip())

    def flush(self):
        pass


def fake_workers(monkeypatch, arrival, threads: list | None = None):
    """Workers that record the order the searches were handed out, and return them in the
    order `arrival` (a function of that order); `threads` receives, as each search
    arrives, the threads its pool's share file gives a search still running."""
    handed: list[str] = []

    def submit_all(processes, func, arguments):
        handed.extend(args[1] for args in arguments)
        return arguments

    def completed(arguments):
        for _, target, _, _, share, jobs in arrival(list(arguments)):
            if threads is not None:
                threads.append(fit.workers.threads_of(share, jobs)())
            eq = equation(target, ("*", 2.0, "p"), [0, 0, 0, 0], HAND_TRIM)
            rows = [{"target": target, "iteration": 0, "generation": 0}]
            yield target, eq, rows, 1.0, {"generations": 0.5}

    monkeypatch.setattr(fit.workers, "submit_all", submit_all)
    monkeypatch.setattr(fit.workers, "completed", completed)
    return handed


def test_longest_first_is_the_measured_order_and_keeps_every_target():
    assert fit.longest_first(TARGET_NAMES) == list(fit.SEARCH_ORDER)
    assert sorted(fit.SEARCH_ORDER) == sorted(TARGET_NAMES)
    assert fit.longest_first(["a_y", "q_dot", "a_x"]) == ["q_dot", "a_x", "a_y"]


@pytest.mark.parametrize("arrival", [lambda a: a, lambda a: a[::-1], lambda a: a[2:] + a[:2]])
def test_searches_go_longest_first_and_are_recorded_in_target_order(tmp_path, monkeypatch, arrival):
    handed = fake_workers(monkeypatch, arrival)
    history = HistoryWriter(tmp_path / "history.csv")
    (tmp_path / "checkpoints").mkdir()
    said = Said()
    report = Progress(True, 6, stream=said)
    equations: dict = {}
    timings: dict = {}
    phases = fit._search_in_workers(
        None, Config(), report, tmp_path, history, list(TARGET_NAMES), 2, equations, timings
    )
    history.close()
    assert handed == list(fit.SEARCH_ORDER)
    assert phases == {t: {"generations": 0.5} for t in TARGET_NAMES}  # each search's own
    # the history rows in target order, whatever the order they arrived in
    rows = (tmp_path / "history.csv").read_text().splitlines()[1:]
    assert [r.split(",")[0] for r in rows] == list(TARGET_NAMES)
    ends = [
        json.loads((tmp_path / "checkpoints" / f"{t}.json").read_text())["history_bytes"]
        for t in TARGET_NAMES
    ]
    assert ends == sorted(ends) and len(set(ends)) == 6
    # each equation reported as it arrived, named, with its seconds
    arrived = [args[1] for args in arrival([(None, t) for t in fit.SEARCH_ORDER])]
    lines = [line for line in said.lines if "-> " in line]
    assert [line.split("-> ")[1].split(" =")[0] for line in lines] == arrived
    assert all(line.endswith("; 1.0 s)") for line in lines)
    assert report.done == 6 * Config().evolution.iterations
    assert sorted(equations) == sorted(TARGET_NAMES) and set(timings) == set(TARGET_NAMES)


def test_an_interrupted_search_keeps_what_arrived_in_target_order(monkeypatch):
    """Interrupted after the last two searches handed out arrived (a_y, then a_x), the
    equations found so far are those two, in target order."""

    def arrival(arguments):
        yield from arguments[::-1][:2]
        raise KeyboardInterrupt

    fake_workers(monkeypatch, arrival)
    with pytest.raises(KeyboardInterrupt) as info:
        fit.search_equations(None, Config(), Progress(False, 6), jobs=2)
    found = info.value.equations  # type: ignore[attr-defined]
    assert list(found) == [t for t in TARGET_NAMES if t in ("a_x", "a_y")]


@pytest.mark.parametrize("jobs, expected", [(2, [1, 1, 1, 1, 1, 2]), (4, [1, 1, 1, 1, 2, 4])])
def test_the_searches_left_share_the_idle_cores(tmp_path, monkeypatch, jobs, expected):
    """As searches finish, the ones still running may take the cores they left idle:
    jobs // (searches left) threads; the share file is gone once the pool is done."""
    threads: list[int] = []
    fake_workers(monkeypatch, lambda a: a, threads)
    shares = []
    real = fit.workers.CoreShare

    class Recorded(real):  # type: ignore[misc, valid-type]
        def __init__(self, *args):
            super().__init__(*args)
            shares.append(self.path)

    monkeypatch.setattr(fit.workers, "CoreShare", Recorded)
    report = Progress(False, 6)
    fit._search_in_workers(None, Config(), report, None, None, list(TARGET_NAMES), jobs, {}, {})
    assert threads == expected
    assert len(shares) == 1 and not Path(shares[0]).exists()


@pytest.mark.parametrize(
    "pending, jobs, after",
    [(TARGET_NAMES, 2, 5), (TARGET_NAMES, 4, 3), (TARGET_NAMES, 8, 1), (["a_x"], 2, 0)],
)
def test_idle_is_called_once_when_a_process_has_no_search_left(monkeypatch, pending, jobs, after):
    """`idle` (the command line loads its plotting there) runs once, when fewer searches
    are left than the pool's processes (min(jobs, 6)): not before, while every core is
    busy; at once for a resumed run with fewer searches than processes."""
    arrived: list[str] = []

    def arrival(arguments):
        for args in arguments:
            arrived.append(args[1])
            yield args

    fake_workers(monkeypatch, arrival)
    calls: list[int] = []
    fit._search_in_workers(
        None,
        Config(),
        Progress(False, 6),
        None,
        None,
        list(pending),
        jobs,
        {},
        {},
        lambda: calls.append(len(arrived)),
    )
    assert calls == [after]


def test_the_early_finish_starts_once_a_core_is_idle_and_hears_of_every_equation(monkeypatch):
    """Six searches on two processes: a core is idle once five have arrived; the early
    finish is started then (with the command line's idle hook), not before, and told of
    every equation as it arrives."""
    fake_workers(monkeypatch, lambda a: a)
    calls: list = []

    class Early:
        def found(self, equation):
            calls.append(("found", equation.target))

        def start(self):
            calls.append(("start", None))

    report = Progress(False, 6)
    fit._search_in_workers(
        None,
        Config(),
        report,
        None,
        None,
        list(TARGET_NAMES),
        2,
        {},
        {},
        idle=lambda: calls.append(("idle", None)),
        early=Early(),
    )
    arrived = [("found", t) for t in fit.SEARCH_ORDER]
    assert calls == arrived[:5] + [("idle", None), ("start", None)] + arrived[5:]
