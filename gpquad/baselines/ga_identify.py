"""Per-loop identification of the 12-state model with the GA, and the convergence study."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from gpquad.baselines import quad12
from gpquad.baselines.ga import GAParams, GAResult, generations_to, initial_population, run_ga
from gpquad.baselines.ga_config import GAConfig, theta_of
from gpquad.baselines.symbolic import finite_difference


@dataclass
class LoopData:
    """One loop's problem: model rows, parameter names, X (N, 12), U (N, 4), D (N, n_rows)."""

    model: quad12.ParametricModel
    names: tuple[str, ...]
    X: np.ndarray
    U: np.ndarray
    D: np.ndarray

    def cost(self, theta):
        return self.model.cost(self.X, self.U, self.D, theta)

    def gradient(self, theta):
        return self.model.gradient(self.X, self.U, self.D, theta)


def simulate(
    cfg: GAConfig, noise_sd=(), seed_offset: int = 0
) -> tuple[quad12.Quad12Record, quad12.Quad12Record]:
    """(truth record, measured record with state noise) of the configured simulator."""
    s = cfg.simulator
    rng = np.random.default_rng(np.random.SeedSequence([s.seed, seed_offset]))
    rec = quad12.simulate_quad12(
        theta_of(s.true_params, quad12.PARAMS),
        duration_s=s.duration_s,
        rate_hz=s.rate_hz,
        substeps=s.substeps,
        excitation_sd=np.array(s.excitation_sd),
        tau_s=s.excitation_tau_s,
        gains=np.array(s.pilot_gains),
        v_hover=s.v_hover,
        rng=rng,
    )
    if len(noise_sd) == 0 or not np.any(noise_sd):
        return rec, rec
    X = rec.X + rng.standard_normal(rec.X.shape) * np.asarray(noise_sd)
    return rec, quad12.Quad12Record(rec.t, X, rec.V, rec.v_hover)


def loop_data(rec: quad12.Quad12Record, loop: str, stop: int, difference: str) -> LoopData:
    """Samples 0..stop-1 of a record as one loop's equation-error problem."""
    model, names = quad12.loop_model(loop)
    X = rec.X[:stop]
    D = finite_difference(X, rec.dt, difference)
    rows = [quad12.STATES.index(r) for r in model.rows]
    return LoopData(model, names, X[:-1], rec.u[: stop - 1], D[:, rows])


def ga_params(cfg: GAConfig, gradient: bool) -> GAParams:
    g = cfg.ga
    return GAParams(
        population=g.population,
        generations=g.generations,
        elite=g.elite,
        crossover_prob=g.crossover_prob,
        mutation_prob=g.mutation_prob,
        mutation_shape=g.mutation_shape,
        gradient=gradient,
        max_backtracks=g.max_backtracks,
    )


def identify_loops(
    cfg: GAConfig, rec: quad12.Quad12Record, gradient: bool, seed: int
) -> tuple[dict[str, GAResult], dict[str, LoopData], dict[str, float]]:
    """Run the GA on every configured loop; returns results, problems and fit time per loop (s).

    The initial population of loop i is drawn from SeedSequence([seed, i, 0]) and the GA's
    stream from SeedSequence([seed, i, 1]), so both GA variants start alike.
    """
    stop = len(rec.t) - int(round(cfg.validation_fraction * len(rec.t)))
    results, problems, times = {}, {}, {}
    for i, loop in enumerate(cfg.ga.loops):
        prob = loop_data(rec, loop, stop, cfg.ga.difference)
        low = np.array([cfg.ga.bounds[p][0] for p in prob.names])
        high = np.array([cfg.ga.bounds[p][1] for p in prob.names])
        init = initial_population(
            np.random.default_rng(np.random.SeedSequence([seed, i, 0])),
            cfg.ga.population,
            len(prob.names),
        )
        t0 = time.perf_counter()
        results[loop] = run_ga(
            prob.cost,
            prob.gradient,
            low,
            high,
            init,
            ga_params(cfg, gradient),
            np.random.default_rng(np.random.SeedSequence([seed, i, 1])),
        )
        times[loop] = time.perf_counter() - t0
        problems[loop] = prob
    return results, problems, times


def assemble(cfg: GAConfig, results: dict[str, GAResult], problems) -> dict[str, float]:
    """Fitted parameters of every identified loop (name -> value)."""
    out = {}
    for loop, res in results.items():
        out.update({n: float(v) for n, v in zip(problems[loop].names, res.theta, strict=True)})
    return out


def relative_error_curve(cfg: GAConfig, results, problems, names=None) -> np.ndarray:
    """RMS relative parameter error of the best chromosome per generation, over `names`."""
    truth = cfg.simulator.true_params
    parts = []
    for loop, res in results.items():
        sel = [j for j, n in enumerate(problems[loop].names) if names is None or n in names]
        tru = np.array([truth[problems[loop].names[j]] for j in sel])
        parts.append(((res.best[:, sel] - tru) / tru) ** 2)
    return np.sqrt(np.mean(np.hstack(parts), axis=1))


def convergence_study(cfg: GAConfig, progress=None) -> dict:
    """Generations to `study.fraction` of the initial parameter error, gradient vs traditional.

    Each seed s uses the same initial populations and random streams for both variants.
    Returns per-seed generations (None = not reached), cost evaluations (whole run and up to
    the threshold, all loops), and the error curves.
    """
    rec, _ = simulate(cfg)
    out = {"seeds": list(range(cfg.study.seeds)), "fraction": cfg.study.fraction}
    for label, grad in (("gradient", True), ("traditional", False)):
        gens = {loop: [] for loop in list(cfg.ga.loops) + ["all"]}
        evals, curves, to_threshold = [], [], []
        for seed in range(cfg.study.seeds):
            results, problems, _ = identify_loops(cfg, rec, grad, seed)
            for loop in cfg.ga.loops:
                curve = relative_error_curve(cfg, {loop: results[loop]}, problems)
                gens[loop].append(generations_to(curve, cfg.study.fraction))
            curve = relative_error_curve(cfg, results, problems)
            g_all = generations_to(curve, cfg.study.fraction)
            gens["all"].append(g_all)
            if g_all is not None:
                to_threshold.append(
                    int(sum(r.cumulative_evaluations[g_all] for r in results.values()))
                )
            curves.append(curve.tolist())
            evals.append(int(sum(r.evaluations for r in results.values())))
            if progress:
                progress(
                    f"  {label:11s} seed {seed:2d}: generations to "
                    f"{cfg.study.fraction:.0%} of initial error {gens['all'][-1]}"
                )
        out[label] = {
            "generations": gens,
            "evaluations": evals,
            "curves": curves,
            "evaluations_to_threshold": to_threshold,
            "summary": summarise(gens, cfg.ga.generations),
        }
    return out


def summarise(gens: dict[str, list], cap: int) -> dict:
    """Median, quartiles and range of generations (unreached counted as > cap)."""
    out = {}
    for loop, values in gens.items():
        arr = np.array([cap + 1 if v is None else v for v in values], float)
        out[loop] = {
            "median": float(np.median(arr)),
            "q25": float(np.percentile(arr, 25)),
            "q75": float(np.percentile(arr, 75)),
            "min": float(arr.min()),
            "max": float(arr.max()),
            "not_reached": int(sum(v is None for v in values)),
        }
    return out
