"""The stall rule: a search stops when it stops gaining, resumes where it stopped, and the
paper preset runs every iteration."""

import dataclasses

import pytest
from conftest import truth_dataset
from hypothesis import given
from hypothesis import strategies as st
from test_engine import TINY

from gpquad.engine.evolve.coevolution import Coevolution
from gpquad.engine.evolve.stall import EXACT_RSE, NEAR_EXACT_RSE, best_error, exact, stalled
from gpquad.engine.tree.encoding import Tree
from gpquad.engine.tree.operators import CONST
from gpquad.errors import GpquadError
from gpquad.study import checkpoint
from gpquad.study.config import config_from_dict
from gpquad.study.loop import evolve, stop_reason


def test_three_iterations_without_one_percent_stop_the_search():
    assert not stalled([1.0, 0.9, 0.8, 0.7, 0.6], 3, 0.01)
    assert stalled([1.0, 0.995, 0.999, 0.996], 3, 0.01)
    # a gain of 1 % or more starts the count again
    assert not stalled([1.0, 0.999, 0.98, 0.979, 0.978], 3, 0.01)
    assert stalled([1.0, 0.999, 0.98, 0.979, 0.978, 0.977], 3, 0.01)
    # a worse iteration is stalled; the record is too short to judge; 0 turns it off
    assert stalled([1.0, 2.0, 3.0, float("inf")], 3, 0.01)
    assert not stalled([1.0, 1.0, 1.0], 3, 0.01)
    assert not stalled([1.0] * 20, 0, 0.01)
    assert best_error([float("nan"), 2.0, 1.5]) == 1.5 and best_error([float("nan")]) == float(
        "inf"
    )


@given(st.lists(st.floats(0.01, 10.0), min_size=1, max_size=12), st.integers(1, 4))
def test_a_stall_is_patience_iterations_without_the_gain(errors, patience):
    """Against a plain reading of the rule: the last `patience` entries none below
    (1 - gain) x the lowest entry before each of them."""
    gain = 0.01
    expected = len(errors) > patience and all(
        errors[k] >= (1 - gain) * min(errors[:k])
        for k in range(len(errors) - patience, len(errors))
    )
    assert stalled(errors, patience, gain) == expected


def test_a_stalled_search_stops_and_resumes_stopped(short_dataset, tmp_path):
    ev = dataclasses.replace(TINY, iterations=6, stall_iterations=1, stall_gain=0.5)
    co = Coevolution(short_dataset, "p_dot", ev)
    state = evolve(co, co.init_state(3), ev.iterations, checkpoint_path=tmp_path / "c.ckpt")
    assert 2 <= state.iteration < 6 and len(state.best_errors) == state.iteration
    saved, _ = checkpoint.load(tmp_path / "c.ckpt")
    assert saved.best_errors == state.best_errors
    resumed = evolve(co, saved, ev.iterations)
    assert resumed.iteration == state.iteration  # nothing left to gain: no more iterations
    never = dataclasses.replace(ev, stall_iterations=0)
    full = evolve(Coevolution(short_dataset, "p_dot", never), co.init_state(3), 6)
    assert full.iteration == 6 and full.best_errors == []


def test_stall_settings_are_checked_and_the_paper_runs_every_iteration():
    with pytest.raises(GpquadError, match="evolution.stall_gain"):
        config_from_dict({"evolution": {"stall_gain": 1.5}})
    with pytest.raises(GpquadError, match="evolution.stall_iterations"):
        config_from_dict({"evolution": {"stall_iterations": -1}})
    assert config_from_dict({"preset": "paper"}).evolution.stall_iterations == 0
    assert config_from_dict({}).evolution.stall_iterations == 3


def test_an_exact_error_is_below_the_selections_resolution():
    """Exact: below a thousandth of the state's spread (selection.RSE_RESOLUTION), where
    the final selection sees no error left to gain."""
    from gpquad.engine.evolve.selection import RSE_RESOLUTION

    assert EXACT_RSE == RSE_RESOLUTION == 1e-3
    assert exact(0.5e-3, 1.0, False) and not exact(2e-3, 1.0, False)
    assert exact(0.5e-6, 1.0, True) and not exact(2e-6, 1.0, True)  # squared metric
    assert exact(1e-2, 20.0, False) and not exact(1e-2, 1.0, False)
    assert not exact(float("inf"), 1.0, False) and not exact(float("nan"), 1.0, False)


def _truth_search(iterations: int):
    """Eq. 2 data of the truth p_dot = -4.15 p + 10.3 u_R(t-1), and the default engine for
    p_dot with `iterations` iterations of 30 generations."""
    dataset = truth_dataset({}, 60.0, seed=2)
    ev = dataclasses.replace(
        config_from_dict({}).evolution,
        targets=("p_dot",),
        iterations=iterations,
        model_generations=30,
        input_taps=1,
    )
    return dataset, ev


def test_a_search_that_is_exact_stops_and_the_paper_goes_on():
    """On eq. 2 data of the truth p_dot = -4.15 p + 10.3 u_R(t-1) the search reaches the
    truth's error (rounding) and stops at once; with the rule off (the bad case) it runs
    every iteration."""
    dataset, ev = _truth_search(6)
    co = Coevolution(dataset, "p_dot", ev)
    state = evolve(co, co.init_state(1), ev.iterations)
    assert state.iteration < 4
    assert exact(state.best_errors[-1], co.target_spread, False)
    never = dataclasses.replace(ev, stall_iterations=0)
    full = evolve(Coevolution(dataset, "p_dot", never), co.init_state(1), ev.iterations)
    assert full.iteration == 6


def test_the_final_selections_fits_stop_when_they_stop_gaining(monkeypatch):
    """Every LM fit of the final selection (by BIC, the default) runs with lm.STALL and the
    search's own fits without it; the chosen equation still flies the truth
    p_dot = -4.15 p + 10.3 u_R(t-1) to within the selection's resolution."""
    from gpquad.engine.evolve import coevolution
    from gpquad.engine.evolve.lm import STALL

    dataset, ev = _truth_search(1)
    assert ev.integrator != "euler" and ev.selection == "bic"  # both schemes are pruned in
    co = Coevolution(dataset, "p_dot", ev)
    rules = []
    fit = coevolution.continued_constants

    def recorded(*args, stall=None, **kwargs):
        rules.append(stall)
        return fit(*args, stall=stall, **kwargs)

    monkeypatch.setattr(coevolution, "continued_constants", recorded)
    state = evolve(co, co.init_state(1), ev.iterations)
    assert rules and set(rules) == {None}  # the search's fits: no stall rule
    rules.clear()
    tree, train, _ = co.best(state)
    assert rules and set(rules) == {STALL}
    assert exact(train, co.target_spread, co.evaluator.squared)


def test_a_search_exact_only_in_the_configured_integrator_stops_and_prunes_there(
    median_dataset, monkeypatch
):
    """The median model's flight is flown in continuous time: its a_x = 10 theta - 0.6 u
    errs in the generations' eq. 2 surrogate (above EXACT_RSE, below NEAR_EXACT_RSE), and is
    exact once its constants are fitted through RK4, so the search stops there and its
    final choice prunes in RK4 only. Without the RK4 check (the bad case) the search runs
    every iteration."""
    from gpquad.engine.evolve import choice

    ev = dataclasses.replace(
        config_from_dict({}).evolution, targets=("a_x",), iterations=4, input_taps=1
    )
    assert ev.integrator == "rk4"
    co = Coevolution(median_dataset, "a_x", ev)
    state = evolve(co, co.init_state(1), ev.iterations)
    spread = co.target_spread
    assert state.iteration < 4
    # it says why: exact, not stalled (the bad case below stalls)
    assert stop_reason(ev, state) == "its best equation is exact"
    stuck = dataclasses.replace(state, best_errors=[1.0, 1.0, 1.0, 1.0])
    assert "lowered its training error by less than 1 %" in stop_reason(ev, stuck)
    assert not exact(state.best_errors[-1], spread, co.evaluator.squared)
    assert exact(state.best_errors[-1], spread, co.evaluator.squared, NEAR_EXACT_RSE)
    assert co.exact_in_model_scheme(state)
    # a best climber that no fit of its constants makes exact is not exact there, past the
    # gate (opened for it) or not
    constant = Tree.from_lists([CONST], [0.5], state.models[0].delays)
    wrong = dataclasses.replace(state, models=[constant] * len(state.models))
    assert not co.exact_in_model_scheme(wrong)
    with monkeypatch.context() as opened:
        opened.setattr(choice, "NEAR_EXACT_RSE", float("inf"))
        assert not co.exact_in_model_scheme(wrong)
    # the final choice prunes it in RK4 only, and finds the truth's two terms
    schemes = []
    prune = choice.prune_by_bic

    def recorded(evaluator, *args):
        schemes.append(evaluator.scheme)
        return prune(evaluator, *args)

    with monkeypatch.context() as patched:
        patched.setattr(choice, "prune_by_bic", recorded)
        tree, train, _ = co.best(state)
        assert schemes == [co.model_evaluator.scheme] and tree.size == 7
        assert exact(train, spread, co.model_evaluator.squared)
        # the bad case: not known exact, it is pruned in eq. 2 first
        schemes.clear()
        patched.setattr(Coevolution, "exact_in_model_scheme", lambda *a: False)
        co.best(state)
        assert schemes == [co.evaluator.scheme, co.model_evaluator.scheme]
    monkeypatch.setattr(choice, "NEAR_EXACT_RSE", 0.0)
    full = evolve(Coevolution(median_dataset, "a_x", ev), co.init_state(1), ev.iterations)
    assert full.iteration == 4
