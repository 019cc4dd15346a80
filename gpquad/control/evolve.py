"""Evolve the PID gains with CMA-ES (the `cma` package) on random courses flown by the model.

Search space: x_i = log10(gain_i / nominal_i) in [-span, +span]. Each generation draws
`courses_per_generation` new random courses and their input noise from the run's Generator,
shared by the whole population (common random numbers); a candidate's fitness is its mean
course fitness (gpquad.control.courses), CMA-ES minimises its negative. CMA-ES draws its
samples through the `randn` option from a Generator seeded from the run's seed, so the
same seed gives the same gains (cma's own `seed` option is set too and recorded).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from gpquad.control.config import PidConfig
from gpquad.control.courses import random_course
from gpquad.control.pid import Controller, fly, input_noise
from gpquad.control.plant import Plant


@dataclass
class Evolution:
    controller: Controller
    best_fitness: float
    history: list[dict] = field(default_factory=list)  # per generation: best, median, sigma
    evaluations: int = 0
    wall_time_s: float = 0.0
    cma_version: str = ""


def gains_of(x, cfg: PidConfig) -> np.ndarray:
    return np.asarray(cfg.nominal_gains) * 10.0 ** np.asarray(x, float)


def evaluate(plant: Plant, controller: Controller, courses, noises, d0: float) -> float:
    """Mean fitness of one controller over courses with their noise."""
    return float(
        np.mean(
            [
                fly(plant, controller, w, n).score.fitness(d0)
                for w, n in zip(courses, noises, strict=True)
            ]
        )
    )


def evolve_gains(
    plant: Plant, start: Controller, cfg: PidConfig, noise_sd: np.ndarray, seed: int, say=None
) -> Evolution:
    """Run CMA-ES for cfg.generations. The result is the better, on 4 fresh courses, of the
    final distribution mean and the best candidate seen (on its own generation's courses)."""
    from gpquad.extras import require

    cma = require("cma", "tuning the PID gains (CMA-ES)")

    seq = np.random.SeedSequence([seed, 12])
    course_rng, cma_rng = (np.random.default_rng(s) for s in seq.spawn(2))
    n = len(cfg.nominal_gains)
    opts = {
        "seed": int(seed) + 1,
        "popsize": cfg.popsize,
        "maxiter": cfg.generations,
        "bounds": [[-cfg.log10_span] * n, [cfg.log10_span] * n],
        "verbose": -9,
        "randn": lambda *shape: cma_rng.standard_normal(shape),
        "tolfun": 0.0,
        "tolx": 0.0,
        "tolfunhist": 0.0,
        "tolstagnation": 10**9,
    }
    es = cma.CMAEvolutionStrategy(np.zeros(n), cfg.sigma0, opts)
    started = time.perf_counter()
    best_x, best_f, history, evals = np.zeros(n), -np.inf, [], 0
    for gen in range(cfg.generations):
        courses = [random_course(cfg.course, course_rng) for _ in range(cfg.courses_per_generation)]
        noises = [input_noise(course_rng, w, cfg, plant.dt, noise_sd) for w in courses]
        xs = es.ask()
        fits = [
            evaluate(
                plant, start.with_gains(gains_of(x, cfg)), courses, noises, cfg.deviation_scale_m
            )
            for x in xs
        ]
        evals += len(xs)
        es.tell(xs, [-f for f in fits])
        i = int(np.argmax(fits))
        if fits[i] > best_f:
            best_f, best_x = fits[i], np.asarray(xs[i], float)
        history.append(
            {
                "generation": gen + 1,
                "best": float(fits[i]),
                "median": float(np.median(fits)),
                "sigma": float(es.sigma),
            }
        )
        if say is not None and ((gen + 1) % 10 == 0 or gen + 1 == cfg.generations):
            say(
                f"  generation {gen + 1:3d}/{cfg.generations}: best fitness {fits[i]:.4f}, "
                f"median {np.median(fits):.4f}"
            )
    courses = [random_course(cfg.course, course_rng) for _ in range(4)]
    noises = [input_noise(course_rng, w, cfg, plant.dt, noise_sd) for w in courses]
    finalists = [np.asarray(es.result.xfavorite, float), best_x]
    scores = [
        evaluate(plant, start.with_gains(gains_of(x, cfg)), courses, noises, cfg.deviation_scale_m)
        for x in finalists
    ]
    k = int(np.argmax(scores))
    return Evolution(
        start.with_gains(gains_of(finalists[k], cfg)),
        float(scores[k]),
        history,
        evals + 2 * len(courses),
        time.perf_counter() - started,
        cma.__version__,
    )
