"""The stall rule on the validation windows: a search whose best climber stops gaining on
held-out data stops, though its training error still falls; one that keeps gaining there,
or has no validation window, runs on. Its record survives a checkpoint."""

import dataclasses
import json

import numpy as np
import pytest
from test_engine import TINY

from gpquad.data.dataset import Dataset
from gpquad.engine.evolve.coevolution import Coevolution
from gpquad.engine.evolve.state import RunState
from gpquad.engine.evolve.windows import tile
from gpquad.study import checkpoint
from gpquad.study.loop import evolve, search_stalled, stop_reason


class ScriptedSearch:
    """Just what the run loop reads of a Coevolution, with scripted errors: the training
    error falls 10 % an iteration forever; the validation error follows `validation`
    (None: the data has no validation window)."""

    def __init__(self, validation, patience=3, gain=0.01):
        self.cfg = dataclasses.replace(TINY, stall_iterations=patience, stall_gain=gain)
        self.validation = validation
        self.target_spread = 1.0
        self.evaluator = type("Ev", (), {"squared": False})()

    def iterate(self, state):
        state.iteration += 1

    def training_errors(self, state):
        return np.array([0.9**state.iteration, 2.0])

    def best_validation_error(self, state, train):
        v = self.validation(state.iteration)
        return None if v is None else float(v)

    def exact_in_model_scheme(self, state, train):
        return False


def scripted_state():
    return RunState("p_dot", 0, [], np.zeros(2), np.zeros(1), np.zeros(1), np.zeros(1), 0, {})


def rising_after_two(it):
    return [0.0, 1.0, 0.8, 0.85, 0.9, 0.95, 1.0, 1.1, 1.2, 1.3, 1.4, 1.5, 1.6][it]


def test_a_search_stops_once_its_validation_error_stops_falling():
    co = ScriptedSearch(rising_after_two)
    state = evolve(co, scripted_state(), 12)
    # lowest validation error after iteration 2; three iterations without 1 % below it
    assert state.iteration == 5
    assert state.validation_errors == [1.0, 0.8, 0.85, 0.9, 0.95]
    assert "validation error" in stop_reason(co.cfg, state)
    # the training error fell 10 % every iteration: that rule alone would have gone on
    assert all(b < a * 0.99 for a, b in zip(state.best_errors, state.best_errors[1:]))


def test_a_search_gaining_on_validation_or_without_validation_runs_on():
    falling = ScriptedSearch(lambda it: 0.9**it)
    assert evolve(falling, scripted_state(), 12).iteration == 12
    # no validation window: no record, and nothing stops it (a NaN would count as stalled)
    blind = ScriptedSearch(lambda it: None)
    state = evolve(blind, scripted_state(), 12)
    assert state.iteration == 12 and state.validation_errors == []
    # the rule turned off stops nothing either
    off = ScriptedSearch(rising_after_two, patience=0)
    assert evolve(off, scripted_state(), 12).iteration == 12


def test_the_training_rule_still_stops_first_when_it_stalls_first():
    co = ScriptedSearch(lambda it: 0.9**it)
    state = scripted_state()
    state.best_errors = [1.0, 0.999, 0.998, 0.997]
    state.validation_errors = [1.0, 0.9, 0.8, 0.7]
    assert search_stalled(co, state)
    assert "training error" in stop_reason(co.cfg, state)


def test_the_validation_error_is_the_training_best_climbers(short_dataset, tmp_path):
    ev = dataclasses.replace(TINY, iterations=2, stall_iterations=3)
    co = Coevolution(short_dataset, "p_dot", ev)
    state = evolve(co, co.init_state(4), 2, checkpoint_path=tmp_path / "c.ckpt")
    assert len(state.validation_errors) == 2
    train = co.training_errors(state)
    best = state.models[int(np.nanargmin(train))]
    starts, steps = tile(short_dataset.validation, co.window_steps, ev.max_delay)
    expected = co.evaluator.window_errors([best], starts, n_steps=steps).mean()
    assert co.best_validation_error(state, train) == pytest.approx(expected, rel=0, abs=0)
    assert state.validation_errors[-1] == pytest.approx(expected, rel=0, abs=0)
    # the record is checkpointed, and a checkpoint without it (an older one) still loads
    saved, _ = checkpoint.load(tmp_path / "c.ckpt")
    assert saved.validation_errors == state.validation_errors
    fields = json.loads(json.dumps(checkpoint.state_to_dict(state)))
    assert checkpoint.state_from_dict(fields).validation_errors == state.validation_errors
    fields["validation_errors"] = ["0.1"]  # the bad case: not numbers
    with pytest.raises(checkpoint.CorruptCheckpoint, match="validation_errors"):
        checkpoint.state_from_dict(fields)
    del fields["validation_errors"]
    assert checkpoint.state_from_dict(fields).validation_errors == []
    # no validation window: no error
    no_validation = Dataset(
        short_dataset.arrays,
        short_dataset.input_names,
        short_dataset.segments,
        short_dataset.train,
        [],
        short_dataset.names,
        short_dataset.trim,
    )
    blind = Coevolution(no_validation, "p_dot", ev)
    assert blind.best_validation_error(state, train) is None
