"""Joint refit of a full model (gpquad.models.joint_fit) and tracked leaves
(gpquad.engine.evolve.leaves), on flights of the median model whose truth is known."""

import dataclasses

import numpy as np
import pytest

from gpquad.data.dataset import build_dataset
from gpquad.engine.evolve.leaves import measured_variables, tracked_states
from gpquad.engine.tree.export import from_sympy, parse_equation
from gpquad.engine.variables import STATE_NAMES, TARGET_NAMES
from gpquad.models import finish, joint_fit
from gpquad.models.equations import DiscoveredModel, Equation
from gpquad.study.config import SimulatorConfig, preset_evolution

TRUTH = dict(SimulatorConfig().equations)


@pytest.fixture(scope="module")
def raw_dataset(short_flight):
    """The 60 s flight with raw inputs (no trim), so the truth's constants apply as written."""
    return build_dataset([short_flight], validation_fraction=0.25, trim="none")


def model_of(equations: dict[str, str], dataset) -> DiscoveredModel:
    eqs = {}
    for target, text in equations.items():
        expr, delays = parse_equation(text, dataset.input_names)
        eqs[target] = Equation(
            target,
            from_sympy(expr, delays, dataset.input_names),
            dataset.input_names,
            np.nan,
            np.nan,
            dict(dataset.trim),
        )
    return DiscoveredModel(eqs, dataset.input_names, dict(dataset.trim), dataset.dt, 1, {})


def _consts(tree):
    from gpquad.engine.tree.operators import CONST

    return sorted(float(v) for v in tree.values[tree.codes == CONST])


def test_perturbed_constants_come_back_to_the_truth(raw_dataset):
    """Per-equation errors that the full model integrates (a pitch gain 8 % low, a drag
    30 % high, a thrust gain 3 % high) are undone by the joint refit, to 0.5 %."""
    wrong = dict(
        TRUTH, q_dot="-9.0*u_P - 3.3*q", a_x="10.0*theta - 0.78*u", a_z="29.0*u_T(t-5) - w - 9.81"
    )
    refitted, report = joint_fit.joint_refit(model_of(wrong, raw_dataset), raw_dataset)
    assert report["accepted"] and report["judged_on"] == "validation"
    assert report["error_after"] < 1e-4 * report["error_before"]
    truth = model_of(TRUTH, raw_dataset)
    for target in TARGET_NAMES:
        np.testing.assert_allclose(
            _consts(refitted.equations[target].tree),
            _consts(truth.equations[target].tree),
            rtol=5e-3,
            atol=1e-3,
        )


def test_the_refit_is_judged_as_a_readers_simulator_flies_it(raw_dataset):
    """A continuous-time model is judged flown by RK4 with FIDELITY_SUBSTEPS steps per
    sample: on a stiff roll loop (60 / s, one RK4 step per sample near its limit) the
    judged error is that of the fine flight, not the model's own one step per sample."""
    from gpquad.data.score import FIDELITY_SUBSTEPS

    stiff = dict(TRUTH, p_dot="10.3*u_R(t-1) - 60.0*p")
    model = dataclasses.replace(model_of(stiff, raw_dataset), integrator="rk4", substeps=1)
    fine = joint_fit.as_flown_by_readers(model)
    assert (fine.integrator, fine.substeps) == ("rk4", FIDELITY_SUBSTEPS)
    euler = model_of(stiff, raw_dataset)
    assert joint_fit.as_flown_by_readers(euler) is euler
    finer = dataclasses.replace(model, substeps=16)  # already finer: flown as it is
    assert joint_fit.as_flown_by_readers(finer) is finer
    _, report = joint_fit.joint_refit(model, raw_dataset, horizons_s=(1.0,))
    starts, steps, _ = joint_fit.judged_windows(raw_dataset, model, 1.0)
    judge = joint_fit.FullModelError(
        raw_dataset, starts, steps, joint_fit.measured_states(raw_dataset)
    )
    assert report["error_before"] == pytest.approx(judge.error(fine), rel=1e-12)
    assert abs(judge.error(model) - judge.error(fine)) > 0.01 * judge.error(fine)


def test_the_refit_is_judged_at_the_longest_horizon_the_validation_fits(short_flight):
    """36 s of validation data: judged on its 30 s windows; 15 s: on one window of all of
    it (30 s windows shortened to the range, not the 10 s ones), and the report says so."""
    wrong = dict(TRUTH, q_dot="-9.0*u_P - 3.3*q")
    for fraction, shortest, longest in ((0.6, 30.0, 30.0), (0.25, 14.0, 15.0)):
        dataset = build_dataset([short_flight], validation_fraction=fraction, trim="none")
        _, report = joint_fit.joint_refit(model_of(wrong, dataset), dataset)
        assert report["judged_on"] == "validation" and report["accepted"]
        assert shortest <= report["horizon_s"] <= longest


def test_the_validation_chooses_among_the_horizons_fits(raw_dataset, monkeypatch):
    """The 1 s fit is nearly right (1 % off, not resolved: the horizon grows) and the later
    ones are spoiled (30 % off): the 1 s fit is kept. The bad case, keeping the last
    horizon's fit, would refuse the refit."""
    real = joint_fit.levenberg_marquardt
    calls = []

    def first_good(fun, x, jac, n, ftol, stall, triangularize):
        assert stall == joint_fit.JOINT_STALL  # every horizon's fit stops when it stalls
        calls.append(1)
        if len(calls) > 1:
            return x * 1.3
        return real(fun, x, jac, n, ftol, stall=stall, triangularize=triangularize) * 1.01

    monkeypatch.setattr(joint_fit, "levenberg_marquardt", first_good)
    wrong = dict(TRUTH, q_dot="-9.0*u_P - 3.3*q")
    refitted, report = joint_fit.joint_refit(model_of(wrong, raw_dataset), raw_dataset)
    assert len(calls) == 3 and report["fitted_to_s"] == 1.0 and report["accepted"]
    assert report["stages"]["30"] > report["error_before"] > report["stages"]["1"]
    np.testing.assert_allclose(_consts(refitted.equations["q_dot"].tree), [-9.8, -3.3], rtol=2e-2)


def test_the_horizon_grows_only_while_the_model_is_not_resolved(raw_dataset):
    """Wrong constants of the true structure: the 1 s fit flies to round-off and the refit
    stops there. A structural error (a_x without its drag) leaves every horizon to fit."""
    wrong = dict(TRUTH, q_dot="-9.0*u_P - 3.3*q")
    _, report = joint_fit.joint_refit(model_of(wrong, raw_dataset), raw_dataset)
    assert list(report["stages"]) == ["1"]
    assert report["error_after"] < len(report["states"]) * joint_fit.RSE_RESOLUTION**2
    unresolved = dict(TRUTH, a_x="10.0*theta")
    _, report = joint_fit.joint_refit(model_of(unresolved, raw_dataset), raw_dataset)
    assert list(report["stages"]) == ["1", "10", "30"]


def test_too_few_long_windows_fall_back_on_the_shorter_check(short_flight, monkeypatch):
    """36 s of validation: one 30 s window and three 10 s ones. With the long windows' test
    made blind (it never finds a drop significant), a refit that lowers both errors is
    kept on the 10 s windows' test. Bad cases: with that test blind too, refused; with a
    refit that raises the 30 s error, refused however the 10 s test answers."""
    dataset = build_dataset([short_flight], validation_fraction=0.6, trim="none")
    model = model_of(dict(TRUTH, q_dot="-9.0*u_P - 3.3*q"), dataset)
    real = joint_fit.significant_drop
    sizes = []

    def blind_to_long(before, after):
        sizes.append(len(before))
        return False if len(before) == 1 else real(before, after)

    monkeypatch.setattr(joint_fit, "significant_drop", blind_to_long)
    _, report = joint_fit.joint_refit(model, dataset)
    assert report["accepted"] and sizes == [1, 3]
    assert report["error_after"] < report["error_before"]

    monkeypatch.setattr(joint_fit, "significant_drop", lambda before, after: False)
    assert not joint_fit.joint_refit(model, dataset)[1]["accepted"]

    monkeypatch.setattr(joint_fit, "significant_drop", lambda b, a: len(b) > 1)
    monkeypatch.setattr(joint_fit, "levenberg_marquardt", lambda fun, x, *a, **k: x * 1.3)
    _, report = joint_fit.joint_refit(model, dataset)
    assert report["error_after"] > report["error_before"] and not report["accepted"]


def test_the_shorter_windows_are_tested_only_when_they_are_shorter(raw_dataset):
    """The true model against a wrong one, on 10 s windows: a significant drop when the
    judged windows were 30 s long; no second test when they were 10 s already (the same
    windows, the same test). The bad case, the true model judged against itself: none."""
    truth = model_of(TRUTH, raw_dataset)
    wrong = model_of(dict(TRUTH, q_dot="-9.0*u_P - 3.3*q"), raw_dataset)
    states = joint_fit.measured_states(raw_dataset)
    steps = joint_fit.judged_windows(raw_dataset, truth, joint_fit.CHECK_HORIZON_S)[1]
    assert joint_fit.drops_on_shorter_windows(raw_dataset, states, 3 * steps, wrong, truth)
    assert not joint_fit.drops_on_shorter_windows(raw_dataset, states, steps, wrong, truth)
    assert not joint_fit.drops_on_shorter_windows(raw_dataset, states, 3 * steps, truth, truth)


def test_threads_give_the_same_refit(raw_dataset):
    """The Jacobian's rollouts in two threads: the same constants, bit for bit, and the same
    count of rollouts."""
    wrong = dict(TRUTH, q_dot="-9.0*u_P - 3.3*q", a_x="10.0*theta - 0.78*u")
    model = model_of(wrong, raw_dataset)
    one, report_one = joint_fit.joint_refit(model, raw_dataset, horizons_s=(1.0,))
    two, report_two = joint_fit.joint_refit(model, raw_dataset, horizons_s=(1.0,), workers=2)
    assert report_one["rollouts"] == report_two["rollouts"] > 0
    for target in TARGET_NAMES:
        assert np.array_equal(one.equations[target].tree.values, two.equations[target].tree.values)


def test_a_refit_that_does_not_help_is_not_kept(raw_dataset, monkeypatch):
    """The validation check can fail: a least-squares result that is worse on the validation
    windows leaves the model as it was."""
    model = model_of(TRUTH, raw_dataset)

    monkeypatch.setattr(joint_fit, "levenberg_marquardt", lambda fun, x, *a, **k: x * 1.05)
    kept, report = joint_fit.joint_refit(model, raw_dataset)
    assert not report["accepted"]
    assert report["error_after"] > report["error_before"]
    assert kept is model
    assert "not kept" in joint_fit.joint_fit_summary(report)


def test_unmeasured_states_keep_their_equations(raw_dataset):
    """With u and v unmeasured (a log without horizontal velocity), a_x and a_y are not
    refitted and u, v are not in the objective."""
    info = [
        dict(f, measured={**f.get("measured", {}), "u": "not logged", "v": "not logged"})
        for f in raw_dataset.flight_info
    ]
    dataset = dataclasses.replace(raw_dataset, flight_info=info)
    wrong = dict(TRUTH, a_x="10.0*theta - 0.9*u", q_dot="-9.0*u_P - 3.3*q")
    refitted, report = joint_fit.joint_refit(model_of(wrong, dataset), dataset)
    assert report["states"] == ["w", "p", "q", "r"]
    assert _consts(refitted.equations["a_x"].tree) == [-0.9, 10.0]
    assert report["accepted"]
    # within 1 %: over the 30 s window the wrong a_x, not refitted, weighs on w, and the
    # refit moves q_dot a little to make up for it
    np.testing.assert_allclose(_consts(refitted.equations["q_dot"].tree), [-9.8, -3.3], rtol=1e-2)


def test_finish_model_only_with_the_option_and_six_equations(raw_dataset, tmp_path):
    model = model_of(TRUTH, raw_dataset)
    off = preset_evolution()

    def unchanged(done, before):  # no refit: the same trees, only the printing digits set
        return (
            done.joint_fit is None
            and all(
                np.array_equal(done.equations[t].tree.values, e.tree.values)
                for t, e in before.equations.items()
            )
            and set(done.equations) == set(before.equations)
        )

    assert unchanged(finish.finish_model(model, raw_dataset, off), model)
    on = dataclasses.replace(off, finish=("joint_fit",))
    five = dataclasses.replace(
        model, equations={t: e for t, e in model.equations.items() if t != "r_dot"}
    )
    assert unchanged(finish.finish_model(five, raw_dataset, on), five)
    done = finish.finish_model(model, raw_dataset, on)
    assert done.joint_fit["constants"] == 13 and done.joint_fit["judged_on"] == "validation"
    assert done.joint_fit["rollouts"] > 13  # the Jacobians (13 rollouts each) are counted
    again = DiscoveredModel.from_dict(done.to_dict())  # the report is kept in model.json
    assert again.joint_fit == done.joint_fit


def with_inputs(dataset, column: int, values: np.ndarray):
    inputs = dataset.arrays.inputs.copy()
    inputs[:, column] = values
    arrays = dataset.arrays._replace(inputs=inputs)
    return dataclasses.replace(dataset, arrays=arrays)


def test_tracked_heading_is_detected_and_untracked_is_not(raw_dataset):
    """psi stays allowed when u_Y is its set-point (psi lagging u_Y plus a little noise),
    not when u_Y is a rate command (the median model's) or independent of psi."""
    psi = raw_dataset.arrays.states[:, STATE_NAMES.index("psi")]
    y = raw_dataset.input_names.index("u_Y")
    assert tracked_states(raw_dataset, ["psi"]) == {}  # rate-level input
    rng = np.random.default_rng(3)
    setpoint = np.roll(psi, -3) + 0.3 * psi.std() * rng.standard_normal(len(psi))
    angle = with_inputs(raw_dataset, y, setpoint)
    assert tracked_states(angle, ["psi", "phi"]) == {"psi": "u_Y"}
    scaled = with_inputs(raw_dataset, y, 20.0 * setpoint)  # correlated, other units
    assert tracked_states(scaled, ["psi"]) == {}
    allowed = measured_variables(angle, ("psi",), keep_tracked=True)
    assert allowed is None  # nothing left out
    left_out = measured_variables(angle, ("psi",), keep_tracked=False)
    assert STATE_NAMES.index("psi") not in left_out


def test_sweep_full_models_are_refitted_when_configured(raw_dataset):
    """`gpquad sweep` assembles its full models through the same step."""
    from types import SimpleNamespace

    from gpquad.study.assemble import model_of as assembled
    from gpquad.study.config import Config

    eqs = model_of(dict(TRUTH, q_dot="-9.0*u_P - 3.3*q"), raw_dataset).equations
    runs = {t: [SimpleNamespace(equation=e)] for t, e in eqs.items()}
    choice = {t: 0 for t in runs}
    cfg = Config(evolution=preset_evolution())
    plain = assembled(choice, runs, raw_dataset, cfg)
    assert plain.joint_fit is None and plain.equations == eqs
    on = dataclasses.replace(
        cfg, evolution=dataclasses.replace(cfg.evolution, finish=("joint_fit",))
    )
    refitted = assembled(choice, runs, raw_dataset, on)
    assert refitted.joint_fit["accepted"]
    # within 1 %: over the 30 s window the wrong a_x, not refitted, weighs on w, and the
    # refit moves q_dot a little to make up for it
    np.testing.assert_allclose(_consts(refitted.equations["q_dot"].tree), [-9.8, -3.3], rtol=1e-2)


def test_significant_drop_needs_more_than_the_windows_spread():
    rng = np.random.default_rng(0)
    before = 1.0 + rng.random(12)
    assert joint_fit.significant_drop(before, 0.5 * before)  # every window halves
    mixed = before + 0.3 * rng.standard_normal(12)  # some better, some worse
    mixed -= (mixed.sum() - before.sum() + 0.05) / 12  # total 0.05 lower
    assert mixed.sum() < before.sum()
    assert not joint_fit.significant_drop(before, mixed)
    assert joint_fit.significant_drop([1.0], [0.9]) and not joint_fit.significant_drop([1.0], [1.1])


def test_a_large_skewed_drop_in_every_window_is_kept_and_a_small_one_is_not():
    """The held-out vehicle's case (rotorpy-heldout-angle seed 3, validation windows of 10 s):
    every window lower, one holding most of the drop; the t statistic is below 2, the sum
    falls to a quarter. Kept; the same windows with the sum falling only to 60 %, or one
    window worse, are not."""
    before = np.array(
        [0.0050, 0.0068, 0.0131, 0.0160, 0.0020, 0.0778, 0.0040, 0.0068, 0.0032, 0.0020, 0.0072]
    )
    after = np.array(
        [0.0042, 0.0030, 0.0028, 0.0042, 0.0015, 0.0032, 0.0025, 0.0059, 0.0024, 0.0012, 0.0053]
    )
    drop = before - after
    assert drop.mean() < joint_fit.SIGNIFICANCE * drop.std(ddof=1) / np.sqrt(drop.size)
    assert joint_fit.significant_drop(before, after)
    to_60_percent = before - drop * (0.4 * before.sum() / drop.sum())  # same t statistic
    assert np.all(to_60_percent < before)
    assert not joint_fit.significant_drop(before, to_60_percent)
    one_worse = after.copy()
    one_worse[0] = before[0] + 1e-4
    assert not joint_fit.significant_drop(before, one_worse)
