"""The left-right mirror of a dataset (gpquad.data.mirror) and the stability repair's
mirrored flights (gpquad.models.stability): checked against the pipeline and against the
paper's median model, which is mirror-symmetric with u_R and u_Y flipped."""

import dataclasses

import numpy as np
import pytest
from conftest import INPUTS
from test_stability import equation, model_of

from gpquad.data.dataset import build_dataset, flight_arrays
from gpquad.data.flight import Flight
from gpquad.data.mirror import mirror_arrays, mirror_dataset
from gpquad.data.simulator import simulate
from gpquad.engine.evolve.evaluator import Evaluator
from gpquad.errors import GpquadError
from gpquad.models import finish, stability
from gpquad.study.config import (
    Config,
    SimulatorConfig,
    VehicleConfig,
    config_from_dict,
    preset_evolution,
)

TRUTH = dict(SimulatorConfig().equations)
FLIP = ("u_R", "u_Y")


def mirrored_flight(flight: Flight) -> Flight:
    """The flight reflected in the body x-z plane, written out component by component."""
    quat = flight.quat * [1, -1, 1, -1]
    vel = flight.vel * [1, -1, 1]
    rates = flight.rates * [-1, 1, -1]
    inputs = flight.inputs * [-1.0 if n in FLIP else 1.0 for n in flight.input_names]
    return dataclasses.replace(flight, quat=quat, vel=vel, rates=rates, inputs=inputs)


def test_mirrored_arrays_are_the_pipelines_arrays_of_the_mirrored_flight(short_flight):
    """Euler angles, accelerations (the integrator's inverse) and step rotations of the
    mirrored flight, computed from scratch, equal the sign flips of mirror_arrays."""
    ds = build_dataset([short_flight], validation_fraction=0.25, trim="none")
    mirrored = mirror_arrays(ds.arrays, ds.input_names, FLIP)
    states, acc, rot = flight_arrays(mirrored_flight(short_flight))
    np.testing.assert_allclose(mirrored.states, states, atol=1e-9)
    np.testing.assert_allclose(mirrored.acc, acc, atol=1e-7)
    np.testing.assert_allclose(mirrored.rot, rot, atol=1e-12)
    np.testing.assert_allclose(mirrored.inputs, mirrored_flight(short_flight).inputs)
    twice = mirror_arrays(mirrored, ds.input_names, FLIP)
    for a, b in zip(twice, ds.arrays, strict=True):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize(
    "flip, symmetric", [(FLIP, True), (("u_R",), False), (("u_R", "u_P", "u_Y"), False)]
)
def test_the_median_model_flies_its_mirrored_flight_only_with_the_right_flips(
    short_flight, flip, symmetric
):
    """The truth is symmetric: with u_R and u_Y flipped it flies the mirrored flight with
    zero error; with the wrong inputs flipped (the bad case) it does not."""
    from gpquad.engine.tree.export import from_sympy, parse_equation

    ds = build_dataset([short_flight], validation_fraction=0.25, trim="none")
    mirrored = mirror_dataset(ds, flip)
    starts = np.array([20, 600], dtype=np.int64)
    worst = 0.0
    for target, text in TRUTH.items():
        expr, delays = parse_equation(text, ds.input_names)
        tree = from_sympy(expr, delays, ds.input_names)
        worst = max(worst, Evaluator(mirrored, target, 300).mean_errors([tree], starts)[0])
    assert (worst < 1e-9) == symmetric, worst


#: Heave damping 1 + 3 r: it holds while r > -1/3 rad/s; turning left faster than that, w
#: grows, which the recorded flight never shows.
ONE_SIDED_Z = "28.2*u_T(t-5) - w - 9.81 - 3.0*r*w"


@pytest.fixture(scope="module")
def turning_dataset():
    """A flight that keeps turning right (r from 0 to 1.1 rad/s, median 0.66): the yaw
    stick trimmed at -0.15 and no heading hold; the truth (the median model) is symmetric."""
    base = SimulatorConfig()
    sim = dataclasses.replace(
        base,
        duration_s=60.0,
        seed=2,
        trim={**base.trim, "u_Y": -0.15},
        pilot_gains={k: v for k, v in base.pilot_gains.items() if k != "u_Y"},
    )
    return build_dataset([simulate(sim, INPUTS)], validation_fraction=0.2, trim="none")


def turning_model(ds, front=(TRUTH["a_z"], ONE_SIDED_Z)):
    return model_of(dict(TRUTH, a_z=ONE_SIDED_Z), ds, {"a_z": list(front)})


def test_the_mirrored_flights_expose_a_one_sided_equation_and_the_repair_swaps_it(turning_dataset):
    ds = turning_dataset
    assert ds.arrays.states[:, 8].min() > -0.1  # the flight never turns left
    model = turning_model(ds)
    # without the mirror the recorded flights fly: nothing to repair (the bad case)
    kept, plain = stability.repair_stability(model, ds)
    assert plain["diverged_before"] == 0 and plain["swaps"] == [] and kept is model
    repaired, report = stability.repair_stability(model, ds, mirror=FLIP)
    assert report["diverged_before"] == report["diverged_after"] == 0
    assert report["mirrored_diverged_before"] > 0 and report["mirrored_diverged_after"] == 0
    assert [(s["target"], s["why"]) for s in report["swaps"]] == [("a_z", "mirror diverged")]
    assert repaired.equations["a_z"].text() == equation("a_z", TRUTH["a_z"], ds).text()
    line = stability.stability_summary(report)
    assert "mirrored (u_R, u_Y flipped)" in line and "a_z" in line


def test_the_mirror_never_trades_a_recorded_flight(turning_dataset):
    """An alternative that flies the mirror but diverges on the recorded flights is not taken."""
    ds = turning_dataset
    model = turning_model(ds, front=["28.2*u_T(t-5) - w - 9.81 + 3.0*r*w"])
    repaired, report = stability.repair_stability(model, ds, mirror=FLIP)
    assert report["mirrored_diverged_before"] > 0 and report["swaps"] == []
    assert repaired.equations["a_z"].text() == model.equations["a_z"].text()


def test_finish_model_flies_the_mirror_only_when_asked_and_the_inputs_exist(turning_dataset):
    ds = turning_dataset
    model = turning_model(ds)
    repair = preset_evolution(finish=["repair"])
    plain = finish.finish_model(model, ds, repair)
    assert "mirrored" not in plain.stability
    mirrored = finish.finish_model(model, ds, repair, VehicleConfig(mirror_inputs=FLIP))
    assert mirrored.stability["mirrored_diverged_after"] == 0
    asymmetric = finish.finish_model(
        model, ds, repair, VehicleConfig(symmetric=False, mirror_inputs=FLIP)
    )
    assert "mirrored" not in asymmetric.stability
    assert VehicleConfig(mirror_inputs=("u_X",)).flipped(ds.input_names) == ()
    assert VehicleConfig(mirror_inputs=FLIP).flipped(ds.input_names) == FLIP


def test_score_counts_the_mirrored_windows_that_diverge(turning_dataset):
    """gpquad score's mirrored count (gpquad.data.score): the one-sided a_z flies the
    recorded windows and diverges on mirrored ones; the truth's a_z on neither."""
    from gpquad.data.score import mirrored_diverged
    from gpquad.models.scoring import SCORED_INDEX, diverged, divergence_bound

    ds = turning_dataset
    steps = 250
    starts = np.arange(10, len(ds.arrays.states) - steps - 1, steps)
    bound = divergence_bound(ds.arrays.states[:, list(SCORED_INDEX)])
    one_sided = turning_model(ds)
    truth = model_of(TRUTH, ds)
    assert not diverged(one_sided.simulate(ds, starts, steps), bound).any()
    assert mirrored_diverged(one_sided, ds, starts, steps, bound, FLIP) > 0
    assert mirrored_diverged(truth, ds, starts, steps, bound, FLIP) == 0


def test_config_checks_the_mirrored_inputs():
    ok = config_from_dict({"vehicle": {"mirror_inputs": list(FLIP)}})
    assert ok.vehicle.mirror_inputs == FLIP
    with pytest.raises(GpquadError, match=r"vehicle.mirror_inputs\[1\]"):
        config_from_dict({"vehicle": {"mirror_inputs": ["u_R", "u_Q"]}})
    # names none of the inputs (motor-level inputs): the mirror is off, not an error
    motors = config_from_dict({"data": {"inputs": ["m0", "m1", "m2", "m3"]}})
    assert motors.vehicle.flipped(("m0", "m1", "m2", "m3")) == ()
    # an old config's key moves to [vehicle] with a note
    notes = []
    old = config_from_dict({"evolution": {"mirror_inputs": list(FLIP)}}, notes=notes)
    assert old.vehicle.mirror_inputs == FLIP and "vehicle.mirror_inputs" in notes[0]
    assert Config().vehicle.mirror_inputs == FLIP and Config().vehicle.symmetric
