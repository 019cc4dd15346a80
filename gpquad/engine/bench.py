"""Throughput benchmark of the fitness kernel and of one paper-scale iteration.

`gpquad bench` prints, and `gpquad bench --json` returns as one JSON object:
- window_steps_per_s: 15-node trees over 84 windows of 750 steps (the 14 x 6
  evaluations of one generation), per core; one random 15-node tree per target, so
  that every kernel path is exercised as evolution exercises it;
- paths: the same for three fixed 15-node trees, one per kernel path (an angular
  target reading rates and inputs only; one reading an Euler angle and a velocity,
  which integrates attitude and velocity; a linear target);
- paths_rk4: the same three trees flown by RK4 (gpquad.engine.kernels.step), one step per
  sample and (rk4x4) four, in window-steps (samples) per second;
- generation_window_steps_per_s: the real pattern, 14 different random trees x 6 windows;
- constant_fit_ms: one Levenberg-Marquardt fit of the rates-and-inputs tree's two
  constants through the integrator (gpquad.engine.evolve.gradient_fit, 20 evaluations at
  most, 6 windows of 750 steps, from constants 30 % off), and constant_fit_window_steps_per_s:
  its residual-and-Jacobian rollouts (window-steps with sensitivities) per second;
- paper_iteration_s: wall time of one paper-scale iteration (600 + 80 generations and
  a simplification) on the reference simulator's flight, target p_dot;
- paper_run_s: 30 such iterations (measured with --full, else projected from one);
- machine: the CPU, the CPU numba compiled for, the cores and the BLAS kernels
  (gpquad._machine).
"""

import time

import numpy as np

from gpquad._machine import machine
from gpquad.data.io import load_dataset
from gpquad.engine.evolve.coevolution import Coevolution
from gpquad.engine.evolve.evaluator import Evaluator
from gpquad.engine.evolve.gradient_fit import gauss_newton_constants
from gpquad.engine.tree.encoding import Tree
from gpquad.engine.tree.operators import CONST, OPERATORS, VAR_BASE
from gpquad.engine.tree.variation import random_tree
from gpquad.engine.variables import TARGET_NAMES, terminal_names
from gpquad.study.config import Config, preset_evolution


def prefix_tree(tokens, input_names, delays=None) -> Tree:
    """A Tree from prefix tokens: operator symbols, variable names and numbers."""
    symbols = {op.symbol: op.code for op in OPERATORS}
    index = {n: VAR_BASE + i for i, n in enumerate(terminal_names(input_names))}
    codes, values = [], []
    for tok in tokens:
        if isinstance(tok, (int, float)):
            codes.append(CONST)
            values.append(float(tok))
        else:
            codes.append(symbols[tok] if tok in symbols else index[tok])
            values.append(0.0)
    delay = [int((delays or {}).get(n, 0)) for n in input_names]
    return Tree.from_lists(codes, values, delay)


def path_trees(input_names) -> dict[str, tuple[str, Tree]]:
    """One fixed 15-node tree per kernel path: (target, tree)."""
    u_p, u_r, u_y, u_t = input_names[:4]
    return {
        # (10.3 u_R - 4.15 p) + (q r - u_P u_Y)
        "rates_and_inputs": (
            "p_dot",
            prefix_tree(
                ["+", "-", "*", 10.3, u_r, "*", 4.15, "p", "-", "*", "q", "r", "*", u_p, u_y],
                input_names,
                {u_r: 1},
            ),
        ),
        # (10.3 u_R - 4.15 p) + (theta q - v u_Y)
        "attitude_and_velocity": (
            "p_dot",
            prefix_tree(
                ["+", "-", "*", 10.3, u_r, "*", 4.15, "p", "-", "*", "theta", "q", "*", "v", u_y],
                input_names,
                {u_r: 1},
            ),
        ),
        # (10 theta - 0.6 u) + (q r - v u_T)
        "linear_target": (
            "a_x",
            prefix_tree(
                ["+", "-", "*", 10.0, "theta", "*", 0.6, "u", "-", "*", "q", "r", "*", "v", u_t],
                input_names,
            ),
        ),
    }


def random_trees_of_size(rng, params, size: int, count: int) -> list[Tree]:
    trees = []
    while len(trees) < count:
        tree = random_tree(rng, params)
        if tree.size == size:
            trees.append(tree)
    return trees


def _rate(func, steps_per_call: int, min_time: float = 1.0) -> float:
    func()  # compile / warm
    calls, start = 0, time.perf_counter()
    while True:
        func()
        calls += 1
        elapsed = time.perf_counter() - start
        if elapsed >= min_time:
            return calls * steps_per_call / elapsed


def constant_fit_speed(
    evaluator, input_names, starts, n_steps: int, min_time: float = 1.0
) -> tuple[float, float]:
    """(ms per LM fit, window-steps with sensitivities per s) of the rates-and-inputs
    tree's constants fitted from 30 % off on `starts`."""
    _, tree = path_trees(input_names)["rates_and_inputs"]
    start = Tree(
        tree.codes, np.where(tree.codes == CONST, tree.values * 1.3, tree.values), tree.delays
    )

    def error_of(t):
        return float(evaluator.mean_errors([t], starts)[0])

    def fit():
        gauss_newton_constants(evaluator, start, error_of(start), starts, n_steps, error_of, 20)

    fit()  # compile / warm
    before, fits, t0 = evaluator.evaluations, 0, time.perf_counter()
    while time.perf_counter() - t0 < min_time:
        fit()
        fits += 1
    elapsed = time.perf_counter() - t0
    return 1e3 * elapsed / fits, (evaluator.evaluations - before) * n_steps / elapsed


def run_benchmark(full: bool = False, seed: int = 0) -> dict:
    cfg = Config()
    dataset = load_dataset(cfg)
    ev = preset_evolution("paper")  # the paper's 750-step windows and one delay per input
    rng = np.random.default_rng(seed)
    co = Coevolution(dataset, "p_dot", ev)
    window = co.window_steps
    starts84 = co.space.starts(co.space.random(rng, 84))
    steps84 = 84 * window
    evaluators = {t: Evaluator(dataset, t, window) for t in TARGET_NAMES}
    paths = {
        name: _rate(lambda t=target, tr=tree: evaluators[t].window_errors([tr], starts84), steps84)
        for name, (target, tree) in path_trees(dataset.input_names).items()
    }
    rk4 = {
        (t, m): Evaluator(dataset, t, window, integrator="rk4", substeps=m)
        for t in TARGET_NAMES
        for m in (1, 4)
    }
    paths_rk4 = {
        f"{name} rk4x{m}": _rate(
            lambda t=target, tr=tree, m=m: rk4[t, m].window_errors([tr], starts84), steps84
        )
        for name, (target, tree) in path_trees(dataset.input_names).items()
        for m in (1, 4)
    }
    mix = random_trees_of_size(rng, co.params, 15, len(TARGET_NAMES))

    def all_targets():
        for target, tree in zip(TARGET_NAMES, mix):
            evaluators[target].window_errors([tree], starts84)

    one_tree = _rate(all_targets, steps84 * len(TARGET_NAMES))
    trees = [random_tree(rng, co.params) for _ in range(14)]
    generation = _rate(lambda: evaluators["p_dot"].window_errors(trees, starts84[:6]), steps84)
    fit_ms, fit_steps_per_s = constant_fit_speed(
        evaluators["p_dot"], dataset.input_names, starts84[:6], window
    )
    state = co.init_state(seed)
    t0 = time.perf_counter()
    co.iterate(state)
    iteration = time.perf_counter() - t0
    if full:
        t0 = time.perf_counter()
        state = co.init_state(seed)
        while state.iteration < ev.iterations:
            co.iterate(state)
        paper_run = time.perf_counter() - t0
    else:
        paper_run = iteration * ev.iterations
    return {
        "window_steps_per_s": one_tree,
        "paths": paths,
        "paths_rk4": paths_rk4,
        "generation_window_steps_per_s": generation,
        "constant_fit_ms": fit_ms,
        "constant_fit_window_steps_per_s": fit_steps_per_s,
        "paper_iteration_s": iteration,
        "paper_run_s": paper_run,
        "paper_run_measured": bool(full),
        "iterations": ev.iterations,
        "machine": machine(),
    }


def format_report(result: dict) -> str:
    kind = "measured" if result["paper_run_measured"] else "projected from one iteration"
    m = result["machine"]
    blas = ", ".join(f"{b['library']} ({b['kernels']})" for b in m["blas"]["libraries"])
    lines = [
        f"machine: {m['cpu']}, {m['cores']} cores, kernels compiled for {m['compiled_for']}; "
        f"BLAS {blas}",
        "fitness kernel, 15-node trees x 84 windows x 750 steps (one random tree per target):",
        f"    {result['window_steps_per_s'] / 1e6:8.1f} M window-steps/s per core",
    ]
    for name, rate in result["paths"].items():
        lines.append(f"    path {name:24s} {rate / 1e6:8.1f} M window-steps/s")
    for name, rate in result.get("paths_rk4", {}).items():
        base = result["paths"][name.split()[0]]
        lines.append(
            f"    path {name:30s} {rate / 1e6:8.2f} M window-steps/s "
            f"({base / rate:.1f}x euler's cost per window-step)"
        )
    lines += [
        f"one generation, 14 random trees x 6 windows: "
        f"{result['generation_window_steps_per_s'] / 1e6:8.1f} M window-steps/s per core",
        f"constant fit (LM through the integrator, 2 constants, 6 windows): "
        f"{result['constant_fit_ms']:8.1f} ms per fit, "
        f"{result['constant_fit_window_steps_per_s'] / 1e6:.1f} M window-steps/s",
        f"one paper-scale iteration (600 + 80 generations): {result['paper_iteration_s']:8.2f} s",
        f"paper-scale run, {result['iterations']} iterations ({kind}): "
        f"{result['paper_run_s']:8.1f} s",
    ]
    return "\n".join(lines)
