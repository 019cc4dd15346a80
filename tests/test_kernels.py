"""Kernels against the plain references in tests/naive.py."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import naive
from gpquad.engine.evolve.evaluator import Evaluator
from gpquad.engine.kernels import quaternion as kq
from gpquad.engine.kernels.fitness import tree_window_errors
from gpquad.engine.kernels.integrator import (
    body_accelerations,
    integrate,
    rates_from_quaternions,
    world_to_body,
)
from gpquad.engine.kernels.rollout import rollout
from gpquad.engine.kernels.step import EULER
from gpquad.engine.kernels.tree_eval import STACK_ROWS, eval_lanes
from gpquad.engine.numba_config import python_callable
from gpquad.engine.tree.encoding import Tree
from gpquad.engine.tree.operators import CONST, VAR_BASE
from gpquad.engine.variables import TARGET_NAMES

eval_lanes = python_callable(eval_lanes)

N_VARS = 13
finite = st.floats(-3, 3, allow_nan=False)


def unit_quaternions():
    return (
        st.tuples(finite, finite, finite, finite)
        .filter(lambda v: np.linalg.norm(v) > 0.1)
        .map(lambda v: np.array(v) / np.linalg.norm(v))
    )


# Random prefix trees built by hypothesis itself, independent of gpquad.engine.tree.variation.
_leaf = st.one_of(
    st.tuples(st.just(CONST), st.floats(-5, 5, allow_nan=False)).map(lambda t: [t]),
    st.integers(0, N_VARS - 1).map(lambda k: [(VAR_BASE + k, 0.0)]),
)
prefix_trees = st.recursive(
    _leaf,
    lambda kids: st.tuples(st.integers(0, 3), kids, kids).map(
        lambda t: [(t[0], 0.0)] + t[1] + t[2]
    ),
    max_leaves=16,
)
# Without division: integrating 1/phi near phi = 0 is chaotic, and then two correct
# integrators legitimately differ by more than round-off.
smooth_trees = st.recursive(
    _leaf,
    lambda kids: st.tuples(st.integers(0, 2), kids, kids).map(
        lambda t: [(t[0], 0.0)] + t[1] + t[2]
    ),
    max_leaves=16,
)


def canonical(quat):
    """q and -q are the same rotation: pick w >= 0."""
    return quat * np.where(quat[:, :1] < 0, -1.0, 1.0)


def as_tree(nodes, delays=(0, 0, 0, 0)):
    return Tree.from_lists([c for c, _ in nodes], [v for _, v in nodes], list(delays))


@given(unit_quaternions())
def test_euler_matches_scipy(q):
    got = np.array(python_callable(kq.euler_from_quat)(*q))
    ref = naive.euler(q)
    if abs(abs(ref[1]) - np.pi / 2) < 1e-3:  # gimbal lock: only theta is defined
        assert got[1] == pytest.approx(ref[1], abs=1e-6)
        return
    diff = (got - ref + np.pi) % (2 * np.pi) - np.pi
    assert np.abs(diff).max() < 1e-9
    back = kq.quat_from_euler(*got)
    assert min(np.abs(np.array(back) - q).max(), np.abs(np.array(back) + q).max()) < 1e-9


@given(st.tuples(finite, finite, finite).map(np.array), st.sampled_from([0.004, 0.01, 0.04, 0.2]))
def test_rate_increment_is_the_exponential_map(rates, dt):
    rates = rates * 8  # up to 24 rad/s, both series and libm branches
    got = np.array(python_callable(kq.rate_increment)(*rates, dt))
    ref = naive.quat_wxyz(naive.Rotation.from_rotvec(rates * dt))
    assert min(np.abs(got - ref).max(), np.abs(got + ref).max()) < 1e-14  # q and -q agree
    if np.linalg.norm(rates) * dt >= np.pi:  # the inverse is defined for < half a turn per step
        return
    back = np.array(python_callable(kq.rate_from_increment)(*got, dt))
    assert np.abs(back - rates).max() < 1e-9 * max(1.0, np.abs(rates).max())


@given(unit_quaternions(), st.tuples(finite, finite, finite).map(np.array))
def test_rotations_agree(q, v):
    mat = np.empty((3, 3))
    kq.rotation_matrix(*q, mat)
    assert np.abs(mat - naive.rotation(q).as_matrix()).max() < 1e-12
    assert np.abs(np.array(python_callable(kq.rotate_back)(*q, *v)) - mat.T @ v).max() < 1e-12


def test_integrator_matches_naive_reference():
    rng = np.random.default_rng(3)
    acc = rng.normal(size=(200, 6)) * [2, 2, 2, 6, 6, 6]
    q0 = np.array(kq.quat_from_euler(0.3, -0.2, 1.0))
    v0, w0, x0 = np.array([1.0, -0.5, 0.2]), np.array([0.5, -1.0, 2.0]), np.zeros(3)
    got = list(integrate(q0, v0, w0, x0, acc, 0.04))
    ref = list(naive.integrate(q0, v0, w0, x0, acc, 0.04))
    got[0], ref[0] = canonical(got[0]), canonical(ref[0])
    for g, r in zip(got, ref):
        assert np.abs(g - r).max() < 1e-9


def test_round_trip_reproduces_velocities_and_rates(short_flight):
    """Integrating the data's own accelerations reproduces the data to ~1e-9."""
    f = short_flight
    acc = body_accelerations(f.vel, f.rates, f.dt)
    ref = naive.body_accelerations(f.vel[:300], f.rates[:300], f.dt)
    assert np.abs(acc[:299] - ref).max() < 1e-9
    quat, vel, rates, _ = integrate(f.quat[0], f.vel[0], f.rates[0], np.zeros(3), acc, f.dt)
    assert np.abs(vel - f.vel).max() < 1e-9
    assert np.abs(rates - f.rates).max() < 1e-9
    assert np.abs(quat - f.quat).max() < 1e-9  # simulator rates are consistent with attitude


def test_rates_from_quaternions_round_trip():
    rng = np.random.default_rng(5)
    rates = rng.normal(size=(400, 3)) * 3
    acc = np.zeros((400, 6))
    acc[:, 3:] = np.diff(np.vstack([rates, rates[-1]]), axis=0) / 0.01
    quat, _, w, _ = integrate(
        np.array([1.0, 0, 0, 0]), np.zeros(3), rates[0], np.zeros(3), acc, 0.01
    )
    assert np.abs(rates_from_quaternions(quat, 0.01) - w[:-1]).max() < 1e-9


def test_world_to_body_inverts_attitude():
    rng = np.random.default_rng(2)
    quat = rng.normal(size=(50, 4))
    quat /= np.linalg.norm(quat, axis=1, keepdims=True)
    body = rng.normal(size=(50, 3))
    world = np.array([naive.rotation(q).apply(b) for q, b in zip(quat, body)])
    assert np.abs(world_to_body(quat, world) - body).max() < 1e-12


@settings(max_examples=60, deadline=None)
@given(
    prefix_trees,
    st.lists(st.lists(finite, min_size=N_VARS, max_size=N_VARS), min_size=1, max_size=7),
)
def test_tree_evaluation_matches_recursive_reference(nodes, lanes):
    tree = as_tree(nodes)
    features = np.ascontiguousarray(np.array(lanes).T)
    out = np.empty(len(lanes))
    eval_lanes(
        tree.codes,
        tree.values,
        tree.size,
        features,
        np.empty((STACK_ROWS, len(lanes))),
        out,
        len(lanes),
    )
    ref = [naive.eval_tree(tree.codes, tree.values, lane) for lane in lanes]
    np.testing.assert_allclose(out, ref, rtol=1e-12, atol=1e-12)


@settings(
    max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    smooth_trees,
    st.integers(0, 5),
    st.lists(st.integers(0, 5), min_size=4, max_size=4),
    st.booleans(),
    st.sampled_from([0.0, 0.7]),
    st.sampled_from([1.0, 0.35]),
)
def test_fitness_kernel_matches_full_integration(
    short_dataset, nodes, target, delays, squared, att_weight, alpha
):
    """The kernel's exact shortcuts equal a full-state integration of every window (with the
    attitude term of angular targets when att_weight > 0, and a lag when alpha < 1)."""
    tree = as_tree(nodes, delays)
    arrays = short_dataset.arrays
    starts = np.array([10, 400, 900], dtype=np.int64)
    out = np.empty(3)
    tree_window_errors(
        tree.codes,
        tree.values,
        tree.size,
        tree.delays,
        target,
        arrays,
        starts,
        60,
        squared,
        att_weight,
        alpha,
        np.inf,
        out,
        EULER,
        1,
    )
    ref = np.array(
        [
            naive.window_error(tree, target, arrays, s, 60, squared, att_weight, alpha)
            for s in starts
        ]
    )
    both_inf = np.isinf(out) & np.isinf(ref)
    # a runaway window (mean error above 1e3, states 1000x the data's) amplifies the two
    # integrators' round-off differences with the state: there both need only be large
    tame = ~both_inf & (ref < 1e3)
    np.testing.assert_allclose(out[tame], ref[tame], rtol=1e-7, atol=1e-9)
    assert np.all(out[~both_inf & ~tame] > 1e2)


def test_true_model_has_zero_error(short_dataset):
    """The simulator's own equations score ~0 on every target (noise-free data)."""
    from gpquad.engine.tree.export import from_sympy, parse_equation
    from gpquad.study.config import MEDIAN_MODEL

    trim = short_dataset.trim
    for name, text in MEDIAN_MODEL.items():
        expr, delays = parse_equation(text, short_dataset.input_names)
        # inputs in the dataset are trim-subtracted: substitute u = u' + trim
        expr = expr.subs({s: s + trim[str(s)] for s in expr.free_symbols if str(s) in trim})
        tree = from_sympy(expr, delays, short_dataset.input_names)
        for attitude in (0.0, 1.0):  # the angles integrated from the true rates match too
            ev = Evaluator(short_dataset, name, 300, attitude=attitude)
            err = ev.window_errors([tree], np.array([20, 600], dtype=np.int64))
            assert err.max() < 1e-9, (name, attitude, err)


def test_attitude_weight_scales_the_angle_like_the_rate(short_dataset):
    """The angle's weight is the ratio of the rate's and the angle's spreads; none for
    linear targets, for weight 0, or where a flight does not measure the angle; and it
    counts: a rate equation with a small bias scores worse with it."""
    import dataclasses

    from gpquad.engine.evolve.evaluator import attitude_weight

    states = short_dataset.arrays.states
    assert attitude_weight(short_dataset, "q_dot", 2.0) == pytest.approx(
        2.0 * states[:, 7].std() / states[:, 1].std(), rel=1e-12
    )
    assert attitude_weight(short_dataset, "a_x", 1.0) == 0.0
    assert attitude_weight(short_dataset, "p_dot", 0.0) == 0.0
    info = [{**i, "measured": {"phi": "not measured (test)"}} for i in short_dataset.flight_info]
    blind = dataclasses.replace(short_dataset, flight_info=info)
    assert attitude_weight(blind, "p_dot", 1.0) == 0.0
    assert attitude_weight(blind, "q_dot", 1.0) > 0.0
    starts = np.array([20, 600], dtype=np.int64)
    # the truth's roll equation with a small bias: p settles off by bias / damping, and the
    # roll angle integrates that offset
    from gpquad.engine.tree.export import from_sympy, parse_equation
    from gpquad.study.config import MEDIAN_MODEL

    trim = short_dataset.trim
    expr, delays = parse_equation(MEDIAN_MODEL["p_dot"] + " + 0.2", short_dataset.input_names)
    expr = expr.subs({s: s + trim[str(s)] for s in expr.free_symbols if str(s) in trim})
    biased = from_sympy(expr, delays, short_dataset.input_names)
    plain = Evaluator(short_dataset, "p_dot", 300).mean_errors([biased], starts)[0]
    with_angle = Evaluator(short_dataset, "p_dot", 300, attitude=1.0).mean_errors([biased], starts)[
        0
    ]
    assert plain > 0 and with_angle > 2.0 * plain


def test_rollout_equals_fast_path(short_dataset):
    rng = np.random.default_rng(4)
    arrays = short_dataset.arrays
    starts = np.array([30, 700], dtype=np.int64)
    from gpquad.engine.tree.variation import VariationParams, random_tree

    params = VariationParams(n_variables=13, n_inputs=4, max_depth=3)
    for target, alpha in zip(range(6), (1.0, 0.4, 1.0, 0.6, 0.3, 1.0), strict=True):
        tree = random_tree(rng, params)
        out = np.empty(2)
        tree_window_errors(
            tree.codes,
            tree.values,
            tree.size,
            tree.delays,
            target,
            arrays,
            starts,
            50,
            False,
            0.0,
            alpha,
            np.inf,
            out,
            EULER,
            1,
        )
        codes = np.full((6, tree.size), CONST, dtype=np.int64)
        values = np.zeros((6, tree.size))
        codes[target], values[target] = tree.codes, tree.values
        delays = np.zeros((6, 4), dtype=np.int64)
        delays[target] = tree.delays
        modelled = np.arange(6) == target
        sizes = np.full(6, tree.size, dtype=np.int64)
        alphas = np.where(modelled, alpha, 1.0)
        states = rollout(
            codes,
            values,
            sizes,
            delays,
            modelled,
            alphas,
            arrays,
            starts,
            50,
            np.zeros((0, 0, 0)),
            EULER,
            1,
        )
        truth = np.stack([arrays.states[s : s + 51] for s in starts])
        ref = np.abs(states[:, 1:, 3 + target] - truth[:, 1:, 3 + target]).mean(axis=1)
        ok = np.isfinite(out)
        np.testing.assert_allclose(
            out[ok], ref[ok], rtol=1e-7, atol=1e-9, err_msg=TARGET_NAMES[target]
        )


def test_bound_abandons_only_worse_trees(short_dataset):
    tree = as_tree([(1, 0.0), (VAR_BASE + 9, 0.0), (VAR_BASE + 6, 0.0)])  # u_P - p
    ev = Evaluator(short_dataset, "p_dot", 200)
    starts = np.array([50, 500], dtype=np.int64)
    full = ev.mean_errors([tree], starts)[0]
    assert ev.mean_errors([tree], starts, bounds=[full * 1.0001])[0] == pytest.approx(full)
    assert np.isinf(ev.mean_errors([tree], starts, bounds=[full * 0.5])[0])


def test_divergence_scores_inf_without_crashing(short_dataset):
    # p_dot = p * p * 100 blows up within a few steps
    tree = as_tree([(2, 0.0), (2, 0.0), (VAR_BASE + 6, 0.0), (VAR_BASE + 6, 0.0), (CONST, 1e4)])
    ev = Evaluator(short_dataset, "p_dot", 300)
    err = ev.window_errors([tree], np.array([100, 800], dtype=np.int64))
    assert np.isinf(err).all()
