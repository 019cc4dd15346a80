"""The finishing steps of a fit: each step timed and its summary line reported
(gpquad.models.finish makes the model; this is what `gpquad run`, `gpquad.fit` and the
benchmark's cells show of it)."""

from __future__ import annotations

import dataclasses
import time

from gpquad.data.dataset import Dataset
from gpquad.models.equations import DiscoveredModel
from gpquad.models.finish import finish_model
from gpquad.models.joint_fit import joint_fit_summary
from gpquad.models.refine import refined_summary
from gpquad.models.stability import stability_summary
from gpquad.models.symmetrize import symmetrized_summary
from gpquad.models.symmetry import mirror_odd_terms, parity_summary
from gpquad.study.config import Config
from gpquad.study.search import Progress

FINISH_WORDS = {
    "symmetrize": "symmetric equations",
    "refine": "refining the rate equations",
    "repair": "full-model stability repair",
    "joint_fit": "joint refit",
}


class StepClock:
    """Wall time of each finishing step (the time between one step's start and the next)."""

    def __init__(self, say):
        self.say = say
        self.seconds: dict[str, float] = {}
        self._current: tuple[str, float] | None = None

    def start(self, name: str) -> None:
        self.stop()
        self.say(f"gpquad: {FINISH_WORDS[name]} ...")
        self._current = (name, time.perf_counter())

    def stop(self) -> None:
        if self._current is not None:
            name, t0 = self._current
            self.seconds[name] = time.perf_counter() - t0
            self._current = None


def finish(
    model: DiscoveredModel,
    dataset: Dataset,
    cfg: Config,
    report: Progress | None = None,
    seconds: dict[str, float] | None = None,
    workers: int = 1,
    early=None,
) -> DiscoveredModel:
    """The finished model (cfg.evolution.finish), each step's summary line reported, and
    its terms of the wrong left-right parity when the vehicle is symmetric. `seconds`, if
    given, receives each step's wall time; `workers`: threads of the steps (the run's jobs;
    the same model for any number); `early`: the EarlyFinish of the searches, if any (its
    results are taken where their inputs are the finish's own; its owner closes it)."""
    say = (lambda text: None) if report is None else report.say
    clock = StepClock(say)
    if early is not None:
        early.drain()  # the searches have ended: the finish does what has not begun
    model = finish_model(model, dataset, cfg.evolution, cfg.vehicle, clock.start, workers, early)
    clock.stop()
    if seconds is not None:
        seconds.update(clock.seconds)
    for name, summary in (
        ("symmetrized", symmetrized_summary),
        ("refined", refined_summary),
        ("stability", stability_summary),
        ("joint_fit", joint_fit_summary),
    ):
        if getattr(model, name) is not None:
            say(summary(getattr(model, name)))
    flipped = cfg.vehicle.flipped(dataset.input_names)
    if flipped:
        found = mirror_odd_terms(model, dataset, flipped)
        model = dataclasses.replace(model, mirror_parity=found)
        say(parity_summary(found, flipped))
    return model
