"""GA baseline: analytic gradients, the GA operators, noise-free recovery, config strictness."""

import dataclasses

import numpy as np
import pytest
import sympy as sp

from gpquad.baselines import ga_identify as gi
from gpquad.baselines import quad12
from gpquad.baselines.ga import GAParams, initial_population, mutate, run_ga
from gpquad.baselines.ga_config import GAConfig, Quad12SimConfig, load_ga_config
from gpquad.baselines.symbolic import ParametricModel, finite_difference
from gpquad.errors import GpquadError


def fd_gradient(cost, theta, h=1e-6):
    g = np.zeros_like(theta)
    for j in range(theta.size):
        e = np.zeros_like(theta)
        e[j] = h * max(1.0, abs(theta[j]))
        g[j] = (cost(theta + e) - cost(theta - e)) / (2 * e[j])
    return g


@pytest.fixture(scope="module")
def record():
    cfg = GAConfig(simulator=Quad12SimConfig(duration_s=20.0))
    return cfg, gi.simulate(cfg)[0]


@pytest.mark.parametrize("loop", list(quad12.LOOPS))
def test_loop_gradient_matches_finite_differences(record, loop):
    cfg, rec = record
    prob = gi.loop_data(rec, loop, len(rec.t), "forward")
    rng = np.random.default_rng(3)
    theta = rng.uniform(-1, 1, (3, len(prob.names)))
    _, grad = prob.gradient(theta)
    for i in range(3):
        fd = fd_gradient(lambda t: prob.cost(t[None])[0], theta[i])
        np.testing.assert_allclose(grad[i], fd, rtol=1e-6, atol=1e-6 * np.abs(fd).max())


def test_user_model_gradient_nonlinear():
    """A user f(X, U, theta) with sin and a parameter product: symbolic gradient == FD."""

    def f(X, U, th):
        return [X[1], th[0] * sp.sin(X[0]) + th[1] * th[2] * U[0] - th[2] * X[1] ** 2]

    model = ParametricModel.from_function(f, ["x", "v"], ["u"], ["k", "g", "c"])
    assert model.rows == ("v",)
    rng = np.random.default_rng(0)
    X, U, D = rng.normal(size=(50, 2)), rng.normal(size=(50, 1)), rng.normal(size=(50, 1))
    theta = np.array([[0.7, -1.3, 0.4]])
    _, grad = model.gradient(X, U, D, theta)
    fd = fd_gradient(lambda t: model.cost(X, U, D, t[None])[0], theta[0])
    np.testing.assert_allclose(grad[0], fd, rtol=1e-6)
    # the symbolic Jacobian is what sympy says
    assert (
        sp.simplify(
            model.jacobian[("v", "g")] - sp.Symbol("c", real=True) * sp.Symbol("u", real=True)
        )
        == 0
    )


def test_forward_difference_of_zoh_record_is_consistent(record):
    """Least squares on forward differences recovers the truth to < 0.5 % (RK4 data)."""
    cfg, rec = record
    for loop in quad12.LOOPS:
        prob = gi.loop_data(rec, loop, len(rec.t), "forward")
        zero = np.zeros((1, len(prob.names)))
        cols = []
        for p in prob.names:
            e = np.zeros((1, len(prob.names)))
            e[0, prob.names.index(p)] = 1.0
            cols.append(
                (
                    prob.model.predict(prob.X, prob.U, e) - prob.model.predict(prob.X, prob.U, zero)
                ).reshape(-1)
            )
        sol = np.linalg.lstsq(np.array(cols).T, prob.D.T.reshape(-1), rcond=None)[0]
        truth = np.array([cfg.simulator.true_params[p] for p in prob.names])
        assert np.abs((sol - truth) / truth).max() < 5e-3


def test_mutation_stays_in_box_and_moves_genes():
    rng = np.random.default_rng(1)
    z = rng.random((200, 5))
    out = mutate(rng, z, 0.5, 10, 100, 2.0)
    assert out.min() >= 0.0 and out.max() <= 1.0
    changed = np.mean(out != z)
    assert 0.4 < changed < 0.6


def test_ga_recovers_quadratic_minimum_and_is_deterministic():
    target = np.array([0.3, -0.2, 0.8])
    scale = np.array([1.0, 10.0, 100.0])  # ill-conditioned

    def cost(th):
        return 0.5 * (((th - target) * scale) ** 2).sum(axis=1)

    def grad(th):
        return cost(th), (th - target) * scale**2

    low, high = np.full(3, -1.0), np.full(3, 1.0)
    init = initial_population(np.random.default_rng(0), 20, 3)
    runs = [
        run_ga(
            cost,
            grad,
            low,
            high,
            init,
            GAParams(population=20, generations=40),
            np.random.default_rng(5),
        )
        for _ in range(2)
    ]
    np.testing.assert_array_equal(runs[0].best, runs[1].best)
    # steepest descent is slow along the weak (scale 1) axis, so that one is looser
    assert np.abs(runs[0].theta - target).max() < 1e-2
    assert np.abs(runs[0].theta - target)[1:].max() < 1e-4
    assert np.all(np.diff(runs[0].best_cost) <= 0)  # elitism: the best never gets worse


def test_ga_gradient_recovers_true_parameters_noise_free(record):
    cfg, rec = record
    cfg = dataclasses.replace(cfg, ga=dataclasses.replace(cfg.ga, generations=60))
    results, problems, _ = gi.identify_loops(cfg, rec, True, seed=0)
    params = gi.assemble(cfg, results, problems)
    err = {p: abs(v / cfg.simulator.true_params[p] - 1) for p, v in params.items()}
    assert set(err) == set(quad12.PARAMS)
    assert max(err.values()) < 0.05, err


def test_ga_config_is_strict(tmp_path):
    path = tmp_path / "ga.toml"
    path.write_text("[ga]\npopulaton = 10\n")
    with pytest.raises(GpquadError, match=r"ga.toml.*ga\.populaton.*unknown key"):
        load_ga_config(path)
    path.write_text("[simulator]\nrate_hz = 'fast'\n")
    with pytest.raises(GpquadError, match=r"simulator\.rate_hz.*expected float"):
        load_ga_config(path)
    path.write_text("[ga.bounds]\na_1 = [0.0, -1.0]\n")
    with pytest.raises(GpquadError, match=r"ga\.bounds\.a_1"):
        load_ga_config(path)


def test_experiment_config_loads():
    from pathlib import Path

    cfg = load_ga_config(Path(__file__).parent.parent / "experiments/baseline_ga_gradient.toml")
    assert cfg.study.seeds == 20 and cfg.ga.loops == tuple(quad12.LOOPS)


def test_engine_state_conversion_round_trip(record):
    _, rec = record
    states = quad12.to_engine_states(rec.X[::50])
    back = quad12.from_engine_states(states)
    np.testing.assert_allclose(back[:, 6:], rec.X[::50, 6:], atol=1e-12)
    np.testing.assert_allclose(back[:, [1, 3, 5]], rec.X[::50, [1, 3, 5]], atol=1e-12)


def test_finite_difference_schemes():
    X = np.arange(10.0)[:, None] ** 2
    np.testing.assert_allclose(finite_difference(X, 1.0, "forward")[:, 0], 2 * np.arange(9) + 1)
    np.testing.assert_allclose(finite_difference(X, 1.0, "central")[1:, 0], 2 * np.arange(1, 9))


def test_gradient_operator_speeds_up_convergence(record):
    """Same initial populations and streams: the gradient GA reaches 5 % of the initial
    position-loop error in fewer generations than the traditional GA (3 seeds)."""
    cfg, rec = record
    cfg = dataclasses.replace(
        cfg, ga=dataclasses.replace(cfg.ga, generations=80, loops=("position",))
    )
    gens = {}
    for grad in (True, False):
        gens[grad] = []
        for seed in range(3):
            results, problems, _ = gi.identify_loops(cfg, rec, grad, seed)
            curve = gi.relative_error_curve(cfg, results, problems)
            g = gi.generations_to(curve, 0.05)
            gens[grad].append(cfg.ga.generations + 1 if g is None else g)
    assert np.median(gens[True]) < np.median(gens[False]), gens
