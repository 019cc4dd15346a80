"""Eq. 2 through the shared step (gpquad.engine.kernels.step) gives the same bits as the
kernels that coded it each on their own: the fitness, sensitivity, rollout, integrate, PID
and peer-rollout outputs of fixed random trees and flights, hashed (SHA-256) when recorded at
5a4c96c and now. The sensitivity kernel's Jacobians are hashed apart from its residuals:
they were re-recorded when the gradient went to reverse mode (the fixture's recorded_at says
how far they moved); the residuals are 5a4c96c's. IEEE doubles without fastmath are
reproducible on one platform; on another libm a hash may differ where atan2 / asin round
differently (then re-record there)."""

import dataclasses
import hashlib
import json
from pathlib import Path

import numpy as np
from eq2_flight import eq2_flight

from gpquad.benchmark.rollout import fly as peer_fly
from gpquad.control.config import PidConfig
from gpquad.control.pid import fly, make_controller
from gpquad.control.plant import design_point, truth_plant
from gpquad.data.dataset import build_dataset
from gpquad.engine.kernels.fitness import tree_window_errors
from gpquad.engine.kernels.integrator import integrate
from gpquad.engine.kernels.rollout import rollout
from gpquad.engine.kernels.sensitivity import residual_rows, window_residuals
from gpquad.engine.kernels.step import EULER
from gpquad.engine.tree.operators import CONST
from gpquad.engine.tree.variation import VariationParams, random_tree
from gpquad.study.config import MEDIAN_MODEL, SimulatorConfig

INPUTS = ("u_P", "u_R", "u_Y", "u_T")
RECORDED = Path(__file__).parent / "fixtures" / "euler_outputs.json"


def euler_outputs() -> dict[str, np.ndarray]:
    """The recorded cases, in the order (and with the draws) they were recorded."""
    cfg = dataclasses.replace(
        SimulatorConfig(integrator="euler"),
        duration_s=40.0,
        seed=7,
        stick_sd={"u_P": 0.2, "u_R": 0.2, "u_Y": 0.2, "u_T": 0.05},
    )
    arrays = build_dataset([eq2_flight(cfg, INPUTS)], validation_fraction=0.2, trim="mean").arrays
    rng = np.random.default_rng(11)
    params = VariationParams(n_variables=13, n_inputs=4, max_depth=4)
    starts = np.array([10, 250, 500, 700], dtype=np.int64)
    rec = {}
    for i in range(24):
        tree = random_tree(rng, params)
        target = i % 6
        for squared, attw, alpha in ((False, 0.0, 1.0), (True, 0.7, 0.4), (False, 1.3, 1.0)):
            out = np.empty(len(starts))
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
                attw,
                alpha,
                np.inf,
                out,
                EULER,
                1,
            )
            rec[f"fit{i}_{squared}_{attw}_{alpha}"] = out
            for angle_t in (False, True):
                n_c = int(np.count_nonzero(tree.codes == CONST))
                rows = len(starts) * 60 * residual_rows(target, attw)
                res, jac = np.empty(rows), np.empty((rows, n_c))
                window_residuals(
                    tree.codes,
                    tree.values,
                    tree.size,
                    tree.delays,
                    target,
                    arrays,
                    starts,
                    60,
                    attw,
                    angle_t,
                    alpha,
                    res,
                    jac,
                    EULER,
                    1,
                )
                rec[f"sens{i}_{attw}_{alpha}_{angle_t}"] = res
                rec[f"jac{i}_{attw}_{alpha}_{angle_t}"] = jac.ravel()
    for m in range(4):
        trees = [random_tree(rng, params) for _ in range(6)]
        size = max(t.size for t in trees)
        codes = np.full((6, size), CONST, dtype=np.int64)
        values = np.zeros((6, size))
        sizes = np.empty(6, dtype=np.int64)
        delays = np.zeros((6, 4), dtype=np.int64)
        for t, tr in enumerate(trees):
            codes[t, : tr.size], values[t, : tr.size] = tr.codes, tr.values
            sizes[t], delays[t] = tr.size, tr.delays
        modelled = rng.random(6) < 0.7
        alphas = np.where(rng.random(6) < 0.5, 0.45, 1.0)
        noise = rng.normal(0, 0.01, (len(starts), 60, 4)) if m % 2 else np.zeros((0, 0, 0))
        rec[f"roll{m}"] = rollout(
            codes, values, sizes, delays, modelled, alphas, arrays, starts, 60, noise, EULER, 1
        )
    acc = rng.normal(0, 2, (300, 6))
    q0 = np.array([0.9, 0.1, -0.2, 0.3])
    q0 /= np.linalg.norm(q0)
    flown = integrate(
        q0, np.array([1.0, -2, 0.5]), np.array([0.3, -0.2, 1.0]), np.zeros(3), acc, 0.04
    )
    for k, a in zip("qvwx", flown, strict=True):
        rec[f"integ_{k}"] = a
    plant = truth_plant(MEDIAN_MODEL, INPUTS, 0.04)
    pid = PidConfig()
    design = design_point(plant, np.array([0.5, 0.5, 0.5, 0.2]))
    controller = make_controller(pid.nominal_gains, design, -np.ones(4), np.ones(4), pid)
    for lag in (1.0, 0.5):
        plant.alphas[:] = lag
        f = fly(
            plant,
            controller,
            np.array([[5.0, 0.0, -1.0], [5.0, 4.0, -2.0]]),
            rng.normal(0, 0.02, (400, 4)),
        )
        rec[f"pid_pos_{lag}"], rec[f"pid_states_{lag}"] = f.pos, f.states
    weights = rng.normal(0, 0.3, (9 + 4 * 6, 6))
    rec["peer"] = peer_fly(
        lambda features, idx: np.tanh(features @ weights) * 3.0, arrays, starts, 80
    )
    return rec


def digest(a: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(a).tobytes()).hexdigest()[:20]


def test_euler_kernels_give_the_recorded_bits():
    recorded = json.loads(RECORDED.read_text())["sha256_20"]
    now = {k: digest(v) for k, v in euler_outputs().items()}
    assert set(now) == set(recorded)
    differ = sorted(k for k in now if now[k] != recorded[k])
    assert not differ, differ


def test_a_one_ulp_change_is_seen():
    """The check can fail: a result changed in its last bit hashes differently."""
    a = np.array([0.1, 0.2, 0.3])
    b = a.copy()
    b[1] = np.nextafter(b[1], 1.0)
    assert digest(a) != digest(b)
