"""Full models from a sweep's runs (paper section 3.2), flown over validation windows.

- The *best model* takes, for every equation, the run with the lowest error; the error is
  the validation (or training) error named by ``sweep.selection``.
- Full model k (k < ``sweep.full_models``) is, per equation, either the best of a bootstrap
  resample of the runs (``assembly = "bootstrap"``: the paper's "best of 30 repetitions",
  repeated, without running 30 x 30 identifications) or the run of repetition k
  (``assembly = "repetition"``).
- Every model integrates all six predicted accelerations from a recorded initial state,
  driven only by the recorded inputs plus Gaussian noise of SD = ``sweep.input_noise`` x
  max |input| (trim-subtracted, training data), as in the paper.
- Metrics, per model and horizon (``sweep.horizons_s``): RSE of u, v, w, p, q, r over
  non-overlapping validation windows, and the number of diverged windows.

Writes, in the sweep folder: model.json (+ equations.tex/.md) of the best model,
models/full-<k>/model.json, models/median/model.json, assembly.json (members, metrics,
sizes) and predictions.npz (one random validation window of ``sweep.window_s`` for the
prediction figure). Nothing here imports matplotlib.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gpquad.data.dataset import Dataset
from gpquad.engine.evolve.windows import WindowSpace, tile
from gpquad.engine.variables import STATE_NAMES, TARGET_NAMES
from gpquad.errors import GpquadError
from gpquad.models import scoring
from gpquad.models.envelope import training_envelope
from gpquad.models.equations import DiscoveredModel, Equation
from gpquad.models.finish import finish_model
from gpquad.models.model_checks import naming
from gpquad.models.scoring import diverged
from gpquad.study.config import Config, load_folder_config
from gpquad.study.runner import write_model
from gpquad.study.seeding import ASSEMBLY_CHILD, assembly_seed
from gpquad.study.store import atomic_write_bytes, write_json
from gpquad.study.sweep_folders import RunKey, run_dir

#: States scored by RSE (the integrated velocities and rates), indices into STATE_NAMES.
SCORED = scoring.SCORED_INDEX
BEST_NOISE_CHILD = ASSEMBLY_CHILD + 1
WINDOW_CHILD = ASSEMBLY_CHILD + 2


@dataclass
class RunResult:
    """A finished run of the sweep."""

    target: str
    repetition: int
    equation: Equation
    train_error: float
    validation_error: float

    def score(self, selection: str) -> float:
        e = self.validation_error if selection == "validation" else self.train_error
        return e if np.isfinite(e) else np.inf


def load_runs(out, targets, runs: int, input_names, trim) -> dict[str, list[RunResult]]:
    """Finished runs of every target; an error names the first missing one."""
    found: dict[str, list[RunResult]] = {}
    for t in targets:
        found[t] = []
        for k in range(runs):
            path = run_dir(Path(out), RunKey(t, k)) / "result.json"
            if not path.exists():
                raise GpquadError(
                    "run not finished; run the same `gpquad sweep` command again to complete it",
                    source=str(path),
                )
            with naming(path):
                d = json.loads(path.read_text())
                eq = Equation.from_dict(t, d["equation"], input_names, trim)
                found[t].append(
                    RunResult(t, k, eq, float(d["train_error"]), float(d["validation_error"]))
                )
    return found


def _root_child(seed: int, child: int) -> np.random.SeedSequence:
    return np.random.SeedSequence(int(seed)).spawn(child + 1)[child]


def pick_best(results: list[RunResult], selection: str) -> RunResult:
    """Lowest selection error; ties go to the lowest repetition."""
    return min(results, key=lambda r: (r.score(selection), r.repetition))


def members(runs: dict[str, list[RunResult]], cfg: Config) -> list[dict[str, int]]:
    """Repetition chosen per target for each full model."""
    sw = cfg.sweep
    out = []
    for k in range(sw.full_models):
        if sw.assembly == "repetition":
            out.append({t: k for t in runs})
            continue
        rng = np.random.default_rng(assembly_seed(cfg.seed, k))
        chosen = {}
        for t in TARGET_NAMES:  # fixed order: draws do not depend on the configured targets
            if t not in runs:
                continue
            n = len(runs[t])
            sample = [runs[t][i] for i in rng.integers(0, n, size=n)]
            chosen[t] = pick_best(sample, sw.selection).repetition
        out.append(chosen)
    return out


def model_of(choice: dict[str, int], runs, dataset: Dataset, cfg: Config) -> DiscoveredModel:
    """The full model of the chosen repetitions (jointly refitted if evolution.joint_fit)."""
    eqs = {t: runs[t][k].equation for t, k in choice.items()}
    model = DiscoveredModel(
        eqs,
        dataset.input_names,
        dataset.trim,
        dataset.dt,
        cfg.seed,
        cfg.to_dict(),
        envelope=training_envelope(dataset),
    )
    return finish_model(model, dataset, cfg.evolution, cfg.vehicle)


def noise_sd(dataset: Dataset, fraction: float) -> np.ndarray:
    """Per-input noise SD: fraction x max |trim-subtracted input| over the training data."""
    rows = np.concatenate([np.arange(a, b) for a, b in dataset.train])
    return fraction * np.abs(dataset.arrays.inputs[rows]).max(axis=0)


def horizon_windows(dataset: Dataset, seconds: float, max_delay: int) -> tuple[np.ndarray, int]:
    """Non-overlapping validation windows of `seconds` (shorter if validation is shorter)."""
    steps = max(1, int(round(seconds / dataset.dt)))
    return tile(dataset.validation, steps, max_delay)


def fly(
    model: DiscoveredModel,
    dataset: Dataset,
    starts,
    steps: int,
    sd: np.ndarray,
    rng: np.random.Generator | None,
) -> np.ndarray:
    """States (n_windows, steps + 1, 9) of the model, with input noise if rng is given."""
    noise = None
    if rng is not None and np.any(sd > 0):
        noise = rng.standard_normal((len(starts), steps, len(sd))) * sd
    with np.errstate(all="ignore"):
        return model.simulate(dataset, starts, steps, input_noise=noise)


def truth(dataset: Dataset, starts, steps: int) -> np.ndarray:
    """Recorded states over the windows: (n_windows, steps + 1, 9)."""
    idx = np.asarray(starts)[:, None] + np.arange(steps + 1)[None, :]
    return dataset.arrays.states[idx]


def rse(pred: np.ndarray, data: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """RSE of each scored state over the kept (not diverged) windows, as
    `gpquad.models.scoring.rse` defines it (steps 1..n); NaN when no window is kept."""
    if not keep.any():
        return np.full(len(SCORED), np.nan)
    return scoring.rse(pred[keep], data[keep])


def evaluate(model: DiscoveredModel, dataset: Dataset, cfg: Config, seed_seq) -> dict:
    """RSE per scored state and diverged windows for every horizon."""
    sw = cfg.sweep
    rng = np.random.default_rng(seed_seq) if sw.input_noise > 0 else None
    sd = noise_sd(dataset, sw.input_noise)
    maxabs = np.abs(dataset.arrays.states[:, SCORED]).max(axis=0)
    bound = sw.divergence_factor * np.maximum(maxabs, 1.0)
    out = {}
    for h in sw.horizons_s:
        starts, steps = horizon_windows(dataset, h, cfg.evolution.max_delay)
        key = f"{h:g}s"
        if len(starts) == 0:
            out[key] = {"windows": 0, "steps": 0, "rse": {}, "diverged": 0}
            continue
        pred = fly(model, dataset, starts, steps, sd, rng)
        data = truth(dataset, starts, steps)
        div = diverged(pred, bound)
        r = rse(pred, data, ~div)
        out[key] = {
            "windows": int(len(starts)),
            "steps": int(steps),
            "seconds": float(steps * dataset.dt),
            "rse": {STATE_NAMES[j]: float(v) for j, v in zip(SCORED, r, strict=True)},
            "diverged": int(div.sum()),
        }
    return out


def ranking_score(metrics: dict, cfg: Config) -> float:
    """Mean RSE over the scored states at the figure's horizon (inf if any window diverged)."""
    h = min(cfg.sweep.horizons_s, key=lambda x: abs(x - cfg.sweep.window_s))
    m = metrics[f"{h:g}s"]
    if m.get("diverged", 0) or not m["rse"]:
        return np.inf
    vals = np.array(list(m["rse"].values()))
    vals = vals[np.isfinite(vals)]
    return float(vals.mean()) if vals.size else np.inf


def assemble_sweep(out, cfg: Config, dataset: Dataset, runs: int) -> Path:
    """Assemble, fly and score the best, the full and the median models; returns model.json."""
    out = Path(out)
    sw = cfg.sweep
    targets = [t for t in TARGET_NAMES if t in cfg.evolution.targets]
    results = load_runs(out, targets, runs, dataset.input_names, dataset.trim)
    best_choice = {t: pick_best(results[t], sw.selection).repetition for t in targets}
    made: dict[tuple, DiscoveredModel] = {}  # a choice made twice (bootstrap) is refitted once

    def model_for(choice):
        key = tuple(sorted(choice.items()))
        if key not in made:
            made[key] = model_of(choice, results, dataset, cfg)
        return made[key]

    best = model_for(best_choice)
    write_model(out, best)
    chosen = members(results, cfg)
    fulls = [model_for(c) for c in chosen]
    best_metrics = evaluate(best, dataset, cfg, _root_child(cfg.seed, BEST_NOISE_CHILD))
    full_metrics = []
    for k, m in enumerate(fulls):
        write_json(out / "models" / f"full-{k:03d}" / "model.json", m.to_dict())
        full_metrics.append(evaluate(m, dataset, cfg, assembly_seed(cfg.seed, k).spawn(1)[0]))
    scores = np.array([ranking_score(m, cfg) for m in full_metrics])
    order = sorted(range(len(fulls)), key=lambda i: (scores[i], i))
    median = order[(len(order) - 1) // 2]
    write_model(out / "models" / "median", fulls[median])
    info = {
        "selection": sw.selection,
        "assembly": sw.assembly,
        "runs": runs,
        "input_noise_fraction": sw.input_noise,
        "input_noise_sd": dict(
            zip(dataset.input_names, noise_sd(dataset, sw.input_noise).tolist(), strict=True)
        ),
        "best": {
            "members": best_choice,
            "metrics": best_metrics,
            "sizes": {t: best.equations[t].tree.size for t in targets},
        },
        "full_models": [
            {
                "members": c,
                "metrics": m,
                "score": float(s),
                "sizes": {t: fulls[k].equations[t].tree.size for t in targets},
            }
            for k, (c, m, s) in enumerate(zip(chosen, full_metrics, scores, strict=True))
        ],
        "median_index": int(median),
        "runs_errors": {
            t: [
                {
                    "repetition": r.repetition,
                    "train_error": r.train_error,
                    "validation_error": r.validation_error,
                    "size": r.equation.tree.size,
                }
                for r in results[t]
            ]
            for t in targets
        },
    }
    write_json(out / "assembly.json", json.loads(json.dumps(info, default=_jsonable)))
    write_predictions(out, cfg, dataset, best, fulls)
    return out / "model.json"


def _jsonable(x):
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    raise TypeError(type(x))


def write_predictions(
    out: Path, cfg: Config, dataset: Dataset, best: DiscoveredModel, fulls: list[DiscoveredModel]
) -> None:
    """One random validation window of sweep.window_s: data, best and every full model."""
    steps = max(1, int(round(cfg.sweep.window_s / dataset.dt)))
    try:
        space = WindowSpace(dataset.validation, steps, cfg.evolution.max_delay)
    except GpquadError:  # validation shorter than the window: use the longest that fits
        starts, steps = horizon_windows(dataset, cfg.sweep.window_s, cfg.evolution.max_delay)
        if len(starts) == 0:
            return
        space = WindowSpace(dataset.validation, steps, cfg.evolution.max_delay)
    rng = np.random.default_rng(_root_child(cfg.seed, WINDOW_CHILD))
    start = space.starts(space.random(rng, 1))
    sd = noise_sd(dataset, cfg.sweep.input_noise)
    noisy = cfg.sweep.input_noise > 0
    best_pred = fly(best, dataset, start, steps, sd, rng if noisy else None)[0]
    full_pred = np.stack(
        [fly(m, dataset, start, steps, sd, rng if noisy else None)[0] for m in fulls]
    )
    import io

    buf = io.BytesIO()
    np.savez(
        buf,
        t=np.arange(steps + 1) * dataset.dt,
        data=truth(dataset, start, steps)[0],
        best=best_pred,
        full=full_pred,
        start=start,
        dt=dataset.dt,
        state_names=np.array(STATE_NAMES),
        targets=np.array(sorted(best.equations)),
    )
    atomic_write_bytes(out / "predictions.npz", buf.getvalue())


def load_sweep_config(out) -> Config:
    """The config a sweep folder was run with."""
    return load_folder_config(out)


def reassemble(out) -> Path:
    """Rebuild the full models of a finished sweep from its folder."""
    from gpquad.data.io import load_dataset

    cfg = load_sweep_config(out)
    info = json.loads((Path(out) / "sweep.json").read_text())
    return assemble_sweep(out, cfg, load_dataset(cfg), int(info["runs"]))
