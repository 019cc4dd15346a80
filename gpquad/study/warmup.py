"""Compile once: the search's kernels split between worker processes before the searches.

numba compiles a kernel in the first process that calls it and writes it to its cache; a
process that calls it later loads it instead. Searches started in two fresh workers would
both compile every kernel at once (about 20 s each on a cold cache). Instead each worker
first compiles one group (`GROUPS`): the eq. 2 kernels in one, the RK4 kernels in the other,
by fitting a small tree's constants on a synthetic flight through the same Python paths as a
search. Once both are done the searches find every kernel in the cache. With a warm cache a
group only loads its kernels (what the searches would do anyway).

tests/test_warmup.py checks that after both groups a search and the finishing steps compile
nothing more.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

#: The kernel groups, one per worker (what each compiles: `warm`).
GROUPS = ("euler", "rk4")

#: The synthetic flight: length (s), sample period (s), window length (samples).
SECONDS, DT, STEPS = 8.0, 0.04, 12


def synthetic_dataset(seed: int = 0):
    """A short smooth flight with the paper's four inputs, built by the data layer's own
    build_dataset so that its arrays have the layouts of any log's."""
    from gpquad.data.dataset import build_dataset
    from gpquad.data.flight import Flight

    rng = np.random.default_rng(seed)
    n = int(SECONDS / DT)
    t = np.arange(n) * DT

    def smooth(scale: float, cols: int) -> np.ndarray:
        f = rng.uniform(0.2, 1.0, cols)
        phase = rng.uniform(0.0, 2 * np.pi, cols)
        return scale * np.sin(np.outer(t, f) + phase)

    phi, theta, psi = smooth(0.2, 3).T
    cr, sr = np.cos(phi / 2), np.sin(phi / 2)
    cp, sp = np.cos(theta / 2), np.sin(theta / 2)
    cy, sy = np.cos(psi / 2), np.sin(psi / 2)
    quat = np.column_stack(
        [
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        ]
    )
    flight = Flight(
        name="warm-up",
        t=t,
        quat=quat,
        vel=smooth(1.0, 3),
        rates=smooth(0.5, 3),
        inputs=smooth(0.3, 4),
        input_names=("u_R", "u_P", "u_Y", "u_T"),
    )
    return build_dataset([flight], validation_fraction=0.25)


def load() -> None:
    """What every group needs, without compiling one: the search's modules imported and
    numba's compiler loaded (its first call of a kernel, about a second). Done in a
    process before it forks its workers, which then start with both."""
    import gpquad.models.joint_jacobian  # noqa: F401
    import gpquad.models.reference_models  # noqa: F401
    from gpquad.engine.evolve import gradient_fit  # noqa: F401
    from gpquad.engine.kernels import least_squares

    least_squares.sum_squares(np.zeros(1))


def warm(group: str) -> float:
    """Compile (or load from numba's cache) the kernels of `group` (GROUPS); returns the
    seconds it took. "euler": the eq. 2 fitness and sensitivity kernels, the LM's and the
    joint refit's full-model sensitivity flight, the model phase's mutation and the one-step
    tree evaluation; "rk4": the RK4 fitness (also as LM's residuals), sensitivity and
    full-model rollout kernels (about the same compilation time each; the helpers both call
    are compiled by "rk4" while "euler" compiles what calls none of them, then loaded)."""
    from gpquad.engine.evolve.evaluator import Evaluator
    from gpquad.engine.evolve.gradient_fit import (
        continued_constants,
        residuals_and_jacobian,
        residuals_only,
    )
    from gpquad.engine.kernels import least_squares
    from gpquad.engine.kernels.tree_eval import eval_on_samples
    from gpquad.engine.tree.random_stream import RandomStream
    from gpquad.engine.tree.variation import VariationParams, mutate_population
    from gpquad.models.joint_fit import constant_nodes
    from gpquad.models.joint_jacobian import flown_with_sensitivities
    from gpquad.models.reference_models import setpoint_model

    if group not in GROUPS:
        raise ValueError(f"unknown kernel group {group!r}; one of {GROUPS}")
    t0 = time.perf_counter()
    dataset = synthetic_dataset()
    integrator, substeps = ("rk4", 2) if group == "rk4" else ("euler", 1)
    setpoints = setpoint_model(dataset.input_names, dataset.dt)
    assert setpoints is not None  # the synthetic flight has the paper's input names
    model = dataclasses.replace(setpoints, integrator=integrator, substeps=substeps)
    tree = model.equations["p_dot"].tree
    starts = np.array([1, STEPS + 2], dtype=np.int64)
    if group == "euler":
        # First what reads none of the Euler angles' vectorised helpers, which both groups
        # call: the other group compiles and caches them meanwhile, this one loads them.
        params = VariationParams(n_variables=13, n_inputs=4)  # the model phase's mutation
        stream = RandomStream(np.random.default_rng(0))
        ev = Evaluator(dataset, "p_dot", STEPS, integrator=integrator, substeps=substeps)
        mutate_population(stream, ev.pack([tree, tree]), params)
        # the joint refit's sensitivity flight (here: this group compiles less)
        flown_with_sensitivities(model, dataset, constant_nodes(model), starts, STEPS)
    for target in ("a_x", "p_dot"):
        ev = Evaluator(dataset, target, STEPS, integrator=integrator, substeps=substeps)
        errors = ev.window_errors([tree, tree], starts).mean(axis=1)
        if group == "rk4":
            residuals_and_jacobian(ev, tree, starts, STEPS)
            residuals_only(ev, tree, starts, STEPS)  # LM's trial points
            continue

        def error_of(t, ev=ev):
            return float(ev.window_errors([t], starts).mean())

        continued_constants(ev, tree, float(errors[0]), starts, STEPS, error_of, 2, [])
    if group == "euler":  # the LM's trust-region branch, which a short fit may not reach
        least_squares.gradient_norm(np.eye(2), np.zeros(2))
        samples = np.arange(1, STEPS, dtype=np.int64)  # the one-step tree evaluation
        arrays = dataset.arrays
        eval_on_samples(
            tree.codes, tree.values, tree.size, tree.delays, arrays.states, arrays.inputs, samples
        )
    if group == "rk4":
        model.simulate(dataset, starts, STEPS)
    return time.perf_counter() - t0
