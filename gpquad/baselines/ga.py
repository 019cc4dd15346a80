"""Real-valued GA with an optional gradient operator (ga-gradient paper, section 3).

One generation: elitism (the best `elite` chromosomes survive unchanged); fitness-
proportional (roulette) selection of parents; the gradient operator
theta <- theta - alpha * grad I(theta) on the selected parents (skipped by the
"traditional" GA); weighted-average crossover; bounded (non-uniform, Michalewicz)
mutation. Chromosomes live in the unit box z = (theta - low) / (high - low), so the
gradient step is diagonally preconditioned by the box widths.

Step size: a fixed alpha is fragile (the useful step spans orders of magnitude between
loops and data sets), so each parent takes an Armijo backtracking line search that starts
from twice the median step accepted in the previous generation.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

#: Armijo sufficient-decrease constant and backtracking factor.
ARMIJO_C = 1e-4
BACKTRACK = 0.5


@dataclass(frozen=True)
class GAParams:
    """GA settings (see module docstring)."""

    population: int = 40
    generations: int = 200
    elite: int = 2
    crossover_prob: float = 0.8
    mutation_prob: float = 0.1
    mutation_shape: float = 2.0  # b of the non-uniform mutation (larger: faster shrinking)
    gradient: bool = True
    max_backtracks: int = 40


@dataclass
class GAResult:
    """Best chromosome per generation (G+1, n_p), its cost (G+1,), evaluations, steps.

    cumulative_evaluations (G+1,): cost evaluations I(theta) used up to each generation
    (a gradient evaluation counts as one; it also returns I).
    """

    best: np.ndarray
    best_cost: np.ndarray
    evaluations: int
    cumulative_evaluations: np.ndarray
    step_sizes: list[float] = field(default_factory=list)

    @property
    def theta(self) -> np.ndarray:
        return self.best[-1]


CostFn = Callable[[np.ndarray], np.ndarray]  # theta (P, n_p) -> I (P,)
GradFn = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]  # -> (I (P,), grad (P, n_p))


def initial_population(rng: np.random.Generator, size: int, n_params: int) -> np.ndarray:
    """Uniform chromosomes in the unit box: (size, n_params)."""
    return rng.random((size, n_params))


def roulette(rng: np.random.Generator, cost: np.ndarray, n: int) -> np.ndarray:
    """Indices of n parents drawn with probability proportional to 1 / (1 + I / median I)."""
    scale = max(float(np.median(cost)), 1e-300)
    fitness = 1.0 / (1.0 + cost / scale)
    return rng.choice(len(cost), size=n, p=fitness / fitness.sum())


def gradient_step(
    z: np.ndarray, cost: Callable, grad_z: Callable, alpha0: float, max_backtracks: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Armijo-backtracked steepest-descent step for each row of z (P, n) in the unit box.

    cost(z) -> I (P,); grad_z(z) -> (I, dI/dz).
    Returns (new z, new cost, accepted step (0 if none), evaluations).
    """
    c0, g = grad_z(z)
    evals = len(z)
    alpha = np.full(len(z), alpha0)
    new_z, new_c = z.copy(), c0.copy()
    pending = np.ones(len(z), dtype=bool)
    accepted = np.zeros(len(z))
    for _ in range(max_backtracks):
        idx = np.flatnonzero(pending)
        if idx.size == 0:
            break
        trial = np.clip(z[idx] - alpha[idx, None] * g[idx], 0.0, 1.0)
        c = cost(trial)
        evals += idx.size
        decrease = np.einsum("ij,ij->i", g[idx], z[idx] - trial)
        ok = c <= c0[idx] - ARMIJO_C * decrease
        good = idx[ok]
        new_z[good], new_c[good], accepted[good] = trial[ok], c[ok], alpha[good]
        pending[good] = False
        alpha[idx[~ok]] *= BACKTRACK
    return new_z, new_c, accepted, evals


def crossover(
    rng: np.random.Generator, a: np.ndarray, b: np.ndarray, prob: float
) -> tuple[np.ndarray, np.ndarray]:
    """Weighted-average crossover of parent pairs (n, n_p) with probability prob."""
    w = rng.random((len(a), 1))
    do = rng.random((len(a), 1)) < prob
    c1 = np.where(do, w * a + (1 - w) * b, a)
    c2 = np.where(do, (1 - w) * a + w * b, b)
    return c1, c2


def mutate(
    rng: np.random.Generator,
    z: np.ndarray,
    prob: float,
    generation: int,
    generations: int,
    shape: float,
) -> np.ndarray:
    """Non-uniform mutation: genes move toward a box edge by a shrinking random fraction."""
    hit = rng.random(z.shape) < prob
    up = rng.random(z.shape) < 0.5
    s = rng.random(z.shape)
    frac = 1.0 - s ** ((1.0 - generation / max(generations, 1)) ** shape)
    moved = np.where(up, z + (1.0 - z) * frac, z - z * frac)
    return np.where(hit, moved, z)


def run_ga(
    cost: CostFn,
    gradient: GradFn,
    low: np.ndarray,
    high: np.ndarray,
    init_z: np.ndarray,
    params: GAParams,
    rng: np.random.Generator,
) -> GAResult:
    """Minimise I(theta) over the box [low, high]; init_z (P, n_p) in the unit box.

    The random draws do not depend on params.gradient, so the gradient and traditional
    GA see the same initial population and the same selection/crossover/mutation streams
    for the same rng seed.
    """
    width = high - low
    to_theta = lambda z: low + z * width  # noqa: E731

    def cost_z(z):
        return cost(to_theta(z))

    def grad_z(z):
        c, g = gradient(to_theta(z))
        return c, g * width

    z = np.array(init_z, dtype=float)
    c = cost_z(z)
    evals = len(z)
    P, G = params.population, params.generations
    n_off = P - params.elite
    n_pairs = (n_off + 1) // 2
    best = [to_theta(z[np.argmin(c)])]
    best_cost = [float(c.min())]
    cumulative = [evals]
    steps: list[float] = []
    alpha0 = None
    for gen in range(1, G + 1):
        order = np.argsort(c, kind="stable")
        elite_z, elite_c = z[order[: params.elite]], c[order[: params.elite]]
        parents = roulette(rng, c, 2 * n_pairs)
        pz, pc = z[parents], c[parents]
        if params.gradient:
            if alpha0 is None:
                _, g0 = grad_z(pz)
                alpha0 = 1.0 / max(float(np.median(np.linalg.norm(g0, axis=1))), 1e-300)
            pz, pc, acc, n = gradient_step(pz, cost_z, grad_z, 2.0 * alpha0, params.max_backtracks)
            evals += n
            if (acc > 0).any():
                alpha0 = float(np.median(acc[acc > 0]))
            steps.append(alpha0)
        c1, c2 = crossover(rng, pz[:n_pairs], pz[n_pairs:], params.crossover_prob)
        kids = np.vstack([c1, c2])[:n_off]
        kids = mutate(rng, kids, params.mutation_prob, gen, G, params.mutation_shape)
        kc = cost_z(kids)
        evals += len(kids)
        z = np.vstack([elite_z, kids])
        c = np.concatenate([elite_c, kc])
        i = int(np.argmin(c))
        best.append(to_theta(z[i]))
        best_cost.append(float(c[i]))
        cumulative.append(evals)
    return GAResult(np.array(best), np.array(best_cost), evals, np.array(cumulative), steps)


def generations_to(error: np.ndarray, fraction: float = 0.05) -> int | None:
    """First generation g with error[g] <= fraction * error[0], or None if never."""
    hit = np.flatnonzero(error <= fraction * error[0])
    return int(hit[0]) if hit.size else None
