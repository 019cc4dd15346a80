"""Throughput benchmark of the fitness kernel and of one paper-scale iteration.

`gpquad bench` prints, and `gpquad bench --json` returns as one JSON object:
- window_steps_per_s: one 15-node tree over 84 windows of 750 steps (the 14 x 6
  evaluations of one generation), per core;
- generation_window_steps_per_s: the real pattern, 14 different random trees x 6 windows;
- paper_iteration_s: wall time of one paper-scale iteration (600 + 80 generations and
  a simplification) on the reference simulator's flight, target p_dot;
- paper_run_s: 30 such iterations (measured with --full, else projected from one).
"""

from __future__ import annotations

import time

import numpy as np

from gpquad.config import Config, EvolutionConfig
from gpquad.data.io import load_dataset
from gpquad.evolve.coevolution import Coevolution
from gpquad.evolve.evaluator import Evaluator
from gpquad.tree.encoding import Tree
from gpquad.tree.operators import ADD, CONST, DIV, MUL, SUB, VAR_BASE
from gpquad.tree.variation import random_tree
from gpquad.variables import terminal_names


def benchmark_tree(input_names) -> Tree:
    """15 nodes: (10.3 u_R - 4.15 p) + (theta q - v / 20); reads an Euler angle and a velocity."""
    idx = {n: VAR_BASE + i for i, n in enumerate(terminal_names(input_names))}
    codes = [ADD, SUB, MUL, CONST, idx[input_names[1]], MUL, CONST, idx["p"],
             SUB, MUL, idx["theta"], idx["q"], DIV, idx["v"], CONST]
    values = [0.0] * 15
    values[3], values[6], values[14] = 10.3, 4.15, 20.0
    return Tree.from_lists(codes, values, [0, 1, 0, 0][: len(input_names)])


def _rate(func, steps_per_call: int, min_time: float = 1.0) -> float:
    func()  # compile / warm
    calls, start = 0, time.perf_counter()
    while True:
        func()
        calls += 1
        elapsed = time.perf_counter() - start
        if elapsed >= min_time:
            return calls * steps_per_call / elapsed


def run_benchmark(full: bool = False, seed: int = 0) -> dict:
    cfg = Config()
    dataset = load_dataset(cfg)
    ev = EvolutionConfig()
    rng = np.random.default_rng(seed)
    evaluator = Evaluator(dataset, "p_dot", ev.window_steps)
    co = Coevolution(dataset, "p_dot", ev)
    starts84 = co.space.starts(co.space.random(rng, 84))
    tree = benchmark_tree(dataset.input_names)
    one_tree = _rate(lambda: evaluator.window_errors([tree], starts84), 84 * ev.window_steps)
    trees = [random_tree(rng, co.params) for _ in range(14)]
    starts6 = starts84[:6]
    generation = _rate(lambda: evaluator.window_errors(trees, starts6), 84 * ev.window_steps)
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
        "generation_window_steps_per_s": generation,
        "paper_iteration_s": iteration,
        "paper_run_s": paper_run,
        "paper_run_measured": bool(full),
        "iterations": ev.iterations,
    }


def format_report(result: dict) -> str:
    kind = "measured" if result["paper_run_measured"] else "projected from one iteration"
    return "\n".join([
        f"fitness kernel, 15-node tree x 84 windows x 750 steps: "
        f"{result['window_steps_per_s'] / 1e6:8.1f} M window-steps/s per core",
        f"one generation pattern, 14 random trees x 6 windows:   "
        f"{result['generation_window_steps_per_s'] / 1e6:8.1f} M window-steps/s per core",
        f"one paper-scale iteration (600 + 80 generations):      "
        f"{result['paper_iteration_s']:8.2f} s",
        f"paper-scale run, {result['iterations']} iterations ({kind}):"
        f" {result['paper_run_s']:8.1f} s",
    ])
