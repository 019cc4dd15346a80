"""Forward-mode sensitivity kernel against plain references and finite differences."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_kernels import as_tree, prefix_trees, smooth_trees

import naive
from gpquad.engine.evolve.evaluator import Evaluator
from gpquad.engine.evolve.gradient_fit import gauss_newton_constants, residuals_and_jacobian
from gpquad.engine.kernels.sensitivity import DIVERGED_RESIDUAL, eval_with_gradient
from gpquad.engine.kernels.tree_tangent import (
    constant_slots,
    gradient_work,
    lanes_eval_with_gradient,
    lanes_gradient_program,
    right_children,
)
from gpquad.engine.numba_config import python_callable
from gpquad.engine.tree.encoding import Tree
from gpquad.engine.tree.operators import CONST, VAR_BASE
from gpquad.engine.variables import TARGET_NAMES

constant_slots = python_callable(constant_slots)
right_children = python_callable(right_children)
gradient_work = python_callable(gradient_work)
eval_with_gradient = python_callable(eval_with_gradient)
lanes_gradient_program = python_callable(lanes_gradient_program)
lanes_eval_with_gradient = python_callable(lanes_eval_with_gradient)

STARTS = np.array([10, 400, 900], dtype=np.int64)
#: A window whose mean error exceeds this (states 1000x the data's) runs away, e.g. under
#: p_dot = 6 p (v + 1): the two integrators' round-off differences grow with the state
#: (measured: 1.39e4 against 1.15e4 after 60 steps), so there both need only be large.
RUNAWAY = 1e3


def _n_const(tree):
    return int(np.count_nonzero(tree.codes == CONST))


def _with_constants(tree, x):
    values = tree.values.copy()
    values[tree.codes == CONST] = x
    return Tree(tree.codes, values, tree.delays)


def _one_lane(tree, leaves, tangents, moving):
    """(value, gradient) of eval_with_gradient at one sample."""
    grad = np.empty(_n_const(tree))
    value = eval_with_gradient(
        tree.codes,
        tree.values,
        tree.size,
        constant_slots(tree.codes, tree.size),
        leaves,
        tangents,
        gradient_work(tree.codes, tree.size, 13),
        grad,
        moving,
    )
    return value, grad


@settings(max_examples=40, deadline=None)
@given(prefix_trees, st.lists(st.floats(-2, 2), min_size=13, max_size=13))
def test_tangent_matches_finite_differences_of_the_recursive_reference(nodes, leaves):
    tree = as_tree(nodes)
    n_c = _n_const(tree)
    value, grad = _one_lane(tree, np.array(leaves), np.zeros((13, n_c)), np.arange(13))
    assert value == pytest.approx(
        naive.eval_tree(tree.codes, tree.values, leaves), rel=1e-12, abs=1e-12
    )
    x0 = tree.values[tree.codes == CONST]

    def shifted(j, h):
        x = x0.copy()
        x[j] += h
        return naive.eval_tree(tree.codes, _with_constants(tree, x).values, leaves)

    def central(j, h):
        return (shifted(j, h) - shifted(j, -h)) / (2 * h)

    for j in range(n_c):
        h = 1e-6 * max(1.0, abs(x0[j]))
        fd, fd_half = central(j, h), central(j, h / 2)
        if abs(fd - fd_half) > 1e-4 * (1 + abs(fd)):  # not smooth here (a division switch)
            continue
        # a protected division at the point itself (x / c at c = 0 is 1 there, x / c beside)
        if abs(0.5 * (shifted(j, h) + shifted(j, -h)) - value) > 1e-6 * (1 + abs(value)):
            continue
        # Richardson: the central differences' h^2 error cancels (near a pole it alone was
        # 1e-4 of the derivative: -10001.0001 for an exact -10000)
        extrapolated = (4.0 * fd_half - fd) / 3.0
        assert grad[j] == pytest.approx(extrapolated, rel=1e-4, abs=1e-5 * (1 + abs(value)))


@settings(max_examples=40, deadline=None)
@given(prefix_trees, st.integers(1, 9), st.integers(0, 10_000))
def test_lanes_gradient_is_the_one_lane_gradient_of_each_lane(nodes, n_lanes, seed):
    """lanes_eval_with_gradient walks the tree once for every lane: each lane's value,
    gradient and leaf adjoints are eval_with_gradient's to the bit (its leaves' tangents
    added in eval_with_gradient's order), divisions by near-zero included."""
    tree = as_tree(nodes)
    n_c = _n_const(tree)
    rng = np.random.default_rng(seed)
    features = rng.uniform(-2.0, 2.0, (13, n_lanes))
    features[:, 0] = 0.0  # every protected division takes its zero branch in lane 0
    tangents = rng.normal(size=(n_lanes, 13, n_c))
    moving = np.array([3, 7, 0], dtype=np.int64)
    slot_of = constant_slots(tree.codes, tree.size)
    program = lanes_gradient_program(tree.codes, tree.values, tree.size, 13, n_lanes)
    regs, _, _, _, _, _, leaf_adjoint = program
    regs[:13] = features  # the register program's leaf rows
    grad, pred = np.empty((n_c, n_lanes)), np.empty(n_lanes)
    lanes_eval_with_gradient(
        tree.codes,
        tree.size,
        slot_of,
        right_children(tree.codes, tree.size),
        program,
        grad,
        pred,
        n_lanes,
    )
    for lane in range(n_lanes):
        value, one = _one_lane(tree, features[:, lane].copy(), tangents[lane], moving)
        lanes = grad[:, lane].copy()
        for k in moving:
            if leaf_adjoint[k, lane] != 0.0:
                lanes += leaf_adjoint[k, lane] * tangents[lane, k]
        assert value == pred[lane]
        np.testing.assert_array_equal(one, lanes)


@settings(
    max_examples=20, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    smooth_trees,
    st.integers(0, 5),
    st.lists(st.integers(0, 5), min_size=4, max_size=4),
    st.sampled_from([0.0, 0.06]),
)
def test_residuals_match_the_plain_integration(short_dataset, nodes, target, delays, lag):
    """mean |residual| per window equals the plain-numpy window error (scipy rotations),
    with and without a lag."""
    tree = as_tree(nodes, delays)
    ev = Evaluator(short_dataset, TARGET_NAMES[target], 60, lag=lag)
    assert (ev.alpha < 1.0) == (lag > 0)
    res, _, _ = residuals_and_jacobian(ev, tree, STARTS, 60)
    got = np.abs(res.reshape(3, 60)).mean(axis=1)
    ref = np.array(
        [
            naive.window_error(tree, target, short_dataset.arrays, s, 60, alpha=ev.alpha)
            for s in STARTS
        ]
    )
    fine = np.isfinite(ref) & (got < DIVERGED_RESIDUAL / 2) & (ref < RUNAWAY)
    np.testing.assert_allclose(got[fine], ref[fine], rtol=1e-7, atol=1e-9)
    assert np.all(got[np.isfinite(ref) & (ref >= RUNAWAY)] > RUNAWAY / 10)
    # Every window the reference sees diverge is flagged by the residuals (a window can also
    # be flagged, or simply have a large finite error, where the reference is still finite:
    # the kernel stops at its state limit first).
    assert np.all(got[np.isinf(ref)] >= DIVERGED_RESIDUAL / 2 / 60)


# Angular targets: exact when the tree reads rates, inputs and constants only.
RATE_LEAVES = [VAR_BASE + k for k in range(6, 13)]


@settings(
    max_examples=20, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(smooth_trees, st.integers(0, 5), st.sampled_from([0.0, 0.06]))
def test_jacobian_matches_finite_differences(short_dataset, nodes, target, lag):
    if target >= 3:  # keep only leaves that are exact for angular targets
        nodes = [
            (RATE_LEAVES[c % len(RATE_LEAVES)], v) if c >= VAR_BASE else (c, v) for c, v in nodes
        ]
    tree = as_tree(nodes, (1, 0, 2, 3))
    n_c = _n_const(tree)
    ev = Evaluator(short_dataset, TARGET_NAMES[target], 40, lag=lag)
    res, jac, diverged = residuals_and_jacobian(ev, tree, STARTS, 40)
    if diverged or n_c == 0 or np.abs(res).max() > 1e3:
        return
    x0 = tree.values[tree.codes == CONST]
    for j in range(n_c):
        h = 1e-6 * max(1.0, abs(x0[j]))
        up, down = x0.copy(), x0.copy()
        up[j] += h
        down[j] -= h
        r_up = residuals_and_jacobian(ev, _with_constants(tree, up), STARTS, 40)[0]
        r_down = residuals_and_jacobian(ev, _with_constants(tree, down), STARTS, 40)[0]
        fd = (r_up - r_down) / (2 * h)
        np.testing.assert_allclose(jac[:, j], fd, rtol=1e-4, atol=1e-6 * (1 + np.abs(fd).max()))


def _tree(text, dataset):
    from gpquad.engine.tree.export import from_sympy, parse_equation

    expr, delays = parse_equation(text, dataset.input_names)
    return from_sympy(expr, delays, dataset.input_names)


@pytest.mark.parametrize(
    "target, start_text, truth",
    [
        ("a_z", "3.0*u_T(t-5) - w + 0.5", 28.2),
        ("p_dot", "2.0*u_R(t-1) - 1.0*p + 0.1", 10.3),
    ],
)
def test_gauss_newton_reaches_far_coefficients(short_dataset, target, start_text, truth):
    """From constants of order one, LM on the integrated error finds 28.2 and 10.3."""
    ev = Evaluator(short_dataset, target, 250)
    starts = np.array([20, 500, 1000], dtype=np.int64)
    tree = _tree(start_text, short_dataset)
    error = ev.mean_errors([tree], starts)[0]

    def error_of(t):
        return ev.mean_errors([t], starts)[0]

    fitted, fitted_error = gauss_newton_constants(ev, tree, error, starts, 250, error_of, 30)
    assert fitted_error < 1e-6 * error
    consts = fitted.values[fitted.codes == CONST]
    assert np.min(np.abs(np.abs(consts) - truth)) < 1e-4 * truth


def test_gauss_newton_keeps_a_tree_it_cannot_improve(short_dataset):
    ev = Evaluator(short_dataset, "p_dot", 100)
    starts = np.array([20, 500], dtype=np.int64)
    no_constants = as_tree([(1, 0.0), (VAR_BASE + 10, 0.0), (VAR_BASE + 6, 0.0)])  # u_R - p
    err = ev.mean_errors([no_constants], starts)[0]
    kept, kept_err = gauss_newton_constants(ev, no_constants, err, starts, 100, lambda t: 0.0, 20)
    assert kept is no_constants and kept_err == err
    # A claimed error that no fit can beat (0) keeps the original tree.
    tree = _tree("2.0*u_R(t-1) - 1.0*p", short_dataset)
    kept, kept_err = gauss_newton_constants(
        ev, tree, 0.0, starts, 100, lambda t: ev.mean_errors([t], starts)[0], 20
    )
    assert kept is tree and kept_err == 0.0
    # A diverging start (positive feedback of 1e4) is left alone rather than crashing.
    bad = _tree("10000.0*p", short_dataset)
    kept, kept_err = gauss_newton_constants(
        ev, bad, np.inf, starts, 100, lambda t: ev.mean_errors([t], starts)[0], 20
    )
    assert kept is bad and kept_err == np.inf


@settings(
    max_examples=15, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(smooth_trees, st.integers(3, 5), st.lists(st.integers(0, 5), min_size=4, max_size=4))
def test_attitude_rows_match_the_plain_integration(short_dataset, nodes, target, delays):
    """With an attitude weight every step has a rate row and a weighted angle row whose
    absolute values sum to the plain-numpy window error with the same weight."""
    tree = as_tree(nodes, delays)
    ev = Evaluator(short_dataset, TARGET_NAMES[target], 60, attitude=1.0)
    assert ev.att_weight > 0
    res, jac, _ = residuals_and_jacobian(ev, tree, STARTS, 60)
    assert res.shape == (3 * 60 * 2,) and jac.shape[0] == res.shape[0]
    got = np.abs(res.reshape(3, 60 * 2)).sum(axis=1) / 60
    ref = np.array(
        [
            naive.window_error(tree, target, short_dataset.arrays, s, 60, att_weight=ev.att_weight)
            for s in STARTS
        ]
    )
    fine = np.isfinite(ref) & (got < DIVERGED_RESIDUAL / 2) & (ref < RUNAWAY)
    np.testing.assert_allclose(got[fine], ref[fine], rtol=1e-7, atol=1e-9)


@pytest.mark.parametrize(
    "target, text",
    [
        ("p_dot", "54.4*(u_R - phi) - 4.66*p + 0.3*q*r"),
        ("q_dot", "40.0*(u_P - theta) - 5.0*q + 2.0*phi*r"),
        ("r_dot", "20.0*(u_Y - psi) - 3.0*r + 0.5*phi"),
    ],
)
def test_attitude_jacobian_follows_finite_differences(short_dataset, target, text):
    """Trees that read Euler angles, with the angle rows: the attitude sensitivity
    (Euler kinematics linearised each step) is within 5 % of central differences (of the
    largest entry) over 2 s windows at 25 Hz with rates up to 1.6 rad/s, where the Euler
    form and the exponential map differ by about dt |omega| / 2 = 3 % per step. Zero
    tangents on the angles (the default, angle_tangents off) are off by 90-600 % here."""
    tree = _tree(text, short_dataset)

    def worst_error(ev):
        res, jac, diverged = residuals_and_jacobian(ev, tree, STARTS, 50)
        assert diverged == 0
        x0 = tree.values[tree.codes == CONST]
        worst = 0.0
        for j in range(len(x0)):
            h = 1e-6 * max(1.0, abs(x0[j]))
            up, down = x0.copy(), x0.copy()
            up[j] += h
            down[j] -= h
            fd = (
                residuals_and_jacobian(ev, _with_constants(tree, up), STARTS, 50)[0]
                - residuals_and_jacobian(ev, _with_constants(tree, down), STARTS, 50)[0]
            ) / (2 * h)
            worst = max(worst, np.abs(jac[:, j] - fd).max() / np.abs(fd).max())
        return worst

    assert (
        worst_error(Evaluator(short_dataset, target, 50, attitude=1.0, angle_tangents=True)) < 0.05
    )
    assert worst_error(Evaluator(short_dataset, target, 50, attitude=1.0)) > 0.5


@pytest.mark.parametrize("substeps", [1, 2])
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_rk4_residuals_alone_are_the_sensitivity_flights_to_the_bit(short_dataset, seed, substeps):
    """LM flies its trial points without the Jacobian (gradient_fit.residuals_only, the RK4
    fitness kernel over lanes): their residuals equal the sensitivity flight's to the bit
    (random trees of every target, lags, the attitude rows, windows that diverge beside
    others and trees that diverge in every window), or LM would take other steps."""
    from gpquad.engine.bench import prefix_tree
    from gpquad.engine.evolve.gradient_fit import residuals_only
    from gpquad.engine.tree.variation import VariationParams, random_tree

    rng = np.random.default_rng(seed)
    params = VariationParams(n_variables=9 + 4, n_inputs=4, max_depth=4)
    starts = np.array([12, 150, 300, 301, 450, 650, 900], dtype=np.int64)
    names = short_dataset.input_names
    fixed = [
        ("p_dot", prefix_tree(["*", 80.0, "*", "p", "p"], names)),  # blows up where p > 0
        ("q_dot", prefix_tree(["+", "*", 1e3, "q", 1e4], names)),  # everywhere
    ]
    seen = {"mixed": 0, "all": 0}
    for k in range(32):
        target = TARGET_NAMES[int(rng.integers(6))]
        tree = random_tree(rng, params)
        if k < len(fixed):
            target, tree = fixed[k]
        ev = Evaluator(
            short_dataset,
            target,
            40,
            attitude=0.5 if k % 3 else 0.0,
            lag=0.0 if k % 2 else 0.08,
            integrator="rk4",
            substeps=substeps,
        )
        if not np.any(tree.codes == CONST):
            continue
        alone = residuals_only(ev, tree, starts, 40)
        with_jacobian, _, diverged = residuals_and_jacobian(ev, tree, starts, 40)
        np.testing.assert_array_equal(alone, with_jacobian)
        seen["mixed"] += 0 < diverged < len(starts)
        seen["all"] += diverged == len(starts)
    assert seen["mixed"] > 0 and seen["all"] > 0


def test_residuals_alone_are_for_rk4_only(short_dataset):
    from gpquad.engine.bench import prefix_tree
    from gpquad.engine.evolve.gradient_fit import residuals_only

    tree = prefix_tree(["*", -2.0, "p"], short_dataset.input_names)
    assert residuals_only(Evaluator(short_dataset, "p_dot", 40), tree, [12], 40) is None


@pytest.mark.parametrize("seed", [1, 2])
def test_rk4_windows_flown_together_are_each_window_flown_alone(short_dataset, seed):
    """The RK4 sensitivity kernel flies its windows as lanes, sensitivity_rk4.LANES at a time:
    the residuals and the Jacobian of windows flown together equal each window flown alone,
    to the bit (random trees of every target, lags, the attitude rows, angle tangents, more
    windows than one block of lanes, windows that diverge beside others)."""
    from gpquad.engine.bench import prefix_tree
    from gpquad.engine.kernels.sensitivity_rk4 import LANES
    from gpquad.engine.tree.variation import VariationParams, random_tree

    rng = np.random.default_rng(seed)
    params = VariationParams(n_variables=9 + 4, n_inputs=4, max_depth=4)
    starts = np.sort(rng.choice(np.arange(10, 1000), LANES + 7, replace=False)).astype(np.int64)
    fixed = [("p_dot", prefix_tree(["*", 80.0, "*", "p", "p"], short_dataset.input_names))]
    mixed = 0
    for k in range(12):
        target = TARGET_NAMES[int(rng.integers(6))]
        tree = random_tree(rng, params)
        if k < len(fixed):
            target, tree = fixed[k]
        if not np.any(tree.codes == CONST):
            continue
        ev = Evaluator(
            short_dataset,
            target,
            12,
            attitude=0.5 if k % 3 else 0.0,
            angle_tangents=k % 4 == 1,
            lag=0.0 if k % 2 else 0.08,
            integrator="rk4",
            substeps=1 + k % 2,
        )
        res, jac, diverged = residuals_and_jacobian(ev, tree, starts, 12)
        alone = [
            residuals_and_jacobian(ev, tree, starts[w : w + 1], 12) for w in range(len(starts))
        ]
        np.testing.assert_array_equal(res, np.concatenate([r for r, _, _ in alone]))
        np.testing.assert_array_equal(jac, np.concatenate([j for _, j, _ in alone]))
        assert diverged == sum(d for _, _, d in alone)
        mixed += 0 < diverged < len(starts)
    assert mixed > 0
