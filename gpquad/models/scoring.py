"""Common scoring of identified models: RSE of integrated states on validation windows.

Any model with `simulate(dataset, starts, n_steps) -> states (W, n_steps + 1, 9)` can be
scored: GP run folders (`gpquad.models.equations.DiscoveredModel`) and baseline run folders
(`gpquad.baselines.flyable`). Every model flies from the recorded state at each window
start with the recorded inputs, over the same tiling of the dataset's validation ranges
(`gpquad.engine.evolve.windows.tile`).

    RSE_s = sum_{w,k} (s_hat[w,k] - s[w,k])^2 / sum_{w,k} (s[w,k] - mean(s))^2

for each integrated state s in (u, v, w, p, q, r), over windows w and steps k = 1..n.
RSE 0 is perfect; 1 is no better than predicting the validation mean.

API: `validation_windows`, `rse`, `score_model`, `load_run`, `run_dataset`, `compare`,
`format_table`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gpquad.data.dataset import Dataset, build_dataset
from gpquad.engine.evolve.windows import tile
from gpquad.errors import GpquadError
from gpquad.study.store import read_json

SCORED_STATES = ("u", "v", "w", "p", "q", "r")
SCORED_INDEX = (3, 4, 5, 6, 7, 8)
#: A flight has diverged when a scored state is non-finite or beyond this many times the
#: largest |value| the data hold (at least 1).
DIVERGENCE_FACTOR = 10.0


def validation_windows(
    dataset: Dataset, horizon_steps: int, max_delay: int = 0
) -> tuple[np.ndarray, int]:
    """Non-overlapping window starts over the validation ranges, and their step count."""
    starts, steps = tile(dataset.validation, horizon_steps, max_delay)
    if steps == 0 or len(starts) == 0:
        raise GpquadError(
            f"no validation range fits a window of {horizon_steps} steps; give "
            "more validation data or a shorter horizon",
            field="horizon",
        )
    return starts, steps


def rse_denominator(data: np.ndarray) -> np.ndarray:
    """RSE's denominator: sum of squared deviations from the mean, per last-axis column."""
    flat = data.reshape(-1, data.shape[-1])
    return ((flat - flat.mean(axis=0)) ** 2).sum(axis=0)


def rse(pred: np.ndarray, data: np.ndarray) -> np.ndarray:
    """RSE per scored state (6,) of predicted vs recorded states (W, n + 1, 9).

    Non-finite predictions (a diverged model) give RSE = inf for that state.
    """
    p = pred[:, 1:, SCORED_INDEX]
    d = data[:, 1:, SCORED_INDEX]
    den = rse_denominator(d)
    with np.errstate(over="ignore", invalid="ignore"):
        num = ((p - d) ** 2).reshape(-1, 6).sum(axis=0)
    num = np.where(np.isfinite(num), num, np.inf)
    return num / np.maximum(den, 1e-300)


def divergence_bound(scored: np.ndarray) -> np.ndarray:
    """The bound of each scored state (S,) from its recorded values (..., S)."""
    flat = np.abs(scored).reshape(-1, scored.shape[-1])
    return DIVERGENCE_FACTOR * np.maximum(flat.max(axis=0), 1.0)


def diverged(pred: np.ndarray, bound: np.ndarray) -> np.ndarray:
    """(n_windows,) True where a scored state is non-finite or beyond its bound."""
    p = pred[:, :, SCORED_INDEX]
    with np.errstate(invalid="ignore"):
        bad = ~np.isfinite(p) | (np.abs(p) > bound[None, None, :])
    return bad.any(axis=(1, 2))


def windows_bound(dataset: Dataset, starts, steps: int) -> np.ndarray:
    """One divergence bound for every scored state: DIVERGENCE_FACTOR x the largest |state|
    the windows of `dataset` record."""
    idx = np.asarray(starts)[:, None] + np.arange(steps + 1)[None, :]
    largest = np.abs(dataset.arrays.states[idx][:, :, SCORED_INDEX]).max()
    return np.full(len(SCORED_INDEX), DIVERGENCE_FACTOR * largest)


def flown_score(model, dataset: Dataset, starts, steps: int, bound: np.ndarray) -> dict:
    """{state: RSE, "diverged": n} of `model` flown over the windows of `dataset` (its own
    input view): the RSE over the windows that do not diverge (NaN when all do), NaN for a
    state the data does not measure."""
    truth = dataset.arrays.states[np.asarray(starts)[:, None] + np.arange(steps + 1)[None, :]]
    with np.errstate(all="ignore"):
        pred = model.simulate(dataset, starts, steps)
    bad = diverged(pred, bound)
    values = rse(pred[~bad], truth[~bad]) if (~bad).any() else np.full(len(SCORED_STATES), np.nan)
    out: dict = {
        s: float("nan") if dataset.unmeasured(s) else float(v)
        for s, v in zip(SCORED_STATES, values, strict=True)
    }
    out["diverged"] = int(bad.sum())
    return out


def model_view(dataset: Dataset, trim: dict[str, float]) -> Dataset:
    """The dataset with its (raw) inputs shifted by a model's trim: inputs - trim."""
    if not any(trim.values()):
        return dataset
    offsets = np.array([trim.get(n, 0.0) for n in dataset.input_names])
    arrays = dataset.arrays._replace(inputs=np.ascontiguousarray(dataset.arrays.inputs - offsets))
    return dataclasses.replace(dataset, arrays=arrays)


@dataclass
class Score:
    rse: dict[str, float]
    mean_rse: float
    n_windows: int
    steps: int


def score_model(
    model, dataset: Dataset, horizon_steps: int, trim: dict | None = None, max_delay: int = 0
) -> Score:
    """Fly `model` over the validation windows of `dataset` (raw inputs) and score it."""
    missing = [n for n in model.input_names if n not in dataset.input_names]
    if missing or tuple(model.input_names) != tuple(dataset.input_names):
        raise GpquadError(
            f"the model reads inputs {list(model.input_names)} but the scoring data "
            f"has {list(dataset.input_names)}",
            field="compare",
        )
    check_same_rate(model, dataset.dt, None)
    starts, steps = validation_windows(dataset, horizon_steps, max_delay)
    view = model_view(dataset, trim or {})
    pred = model.simulate(view, starts, steps)
    idx = starts[:, None] + np.arange(steps + 1)[None, :]
    values = rse(pred, dataset.arrays.states[idx])
    return Score(
        dict(zip(SCORED_STATES, map(float, values), strict=True)),
        float(np.mean(values)),
        len(starts),
        steps,
    )


@dataclass
class RunInfo:
    """A run folder seen by the scorer."""

    path: Path
    kind: str  # "gp" or the baseline method
    model: object  # has simulate(dataset, starts, n_steps) and input_names
    n_parameters: int
    fit_time_s: float
    trim: dict
    max_delay: int


def load_run(run_dir) -> RunInfo:
    """Read a GP or baseline run folder (model.json + run.json)."""
    from gpquad.models.model_checks import naming

    run_dir = Path(run_dir)
    fix = "give a folder written by `gpquad run` or `gpquad baseline`"
    d = read_json(run_dir / "model.json", "run folder", fix)
    info = (
        read_json(run_dir / "run.json", "run folder", fix)
        if (run_dir / "run.json").is_file()
        else {}
    )
    if d.get("kind") == "baseline":
        from gpquad.baselines.flyable import from_model_dict

        with naming(run_dir / "model.json"):
            model = from_model_dict(d)
        return RunInfo(
            run_dir,
            d["method"],
            model,
            model.n_parameters,
            float(info.get("fit_time_s", np.nan)),
            {},
            0,
        )
    from gpquad.models.equations import DiscoveredModel

    with naming(run_dir / "model.json"):
        model = DiscoveredModel.from_dict(d)
    max_delay = max([int(np.max(e.tree.delays, initial=0)) for e in model.equations.values()] + [0])
    return RunInfo(
        run_dir,
        "gp",
        model,
        model.n_parameters,
        float(info.get("wall_time_s", np.nan)),
        dict(model.trim),
        max_delay,
    )


def run_dataset(run_dir) -> Dataset:
    """The scoring data of a run folder, with raw inputs (trim 'none').

    Baseline folders list their flight files in run.json ("scoring_data"); GP folders are
    re-read from config.json (re-flying the reference simulator if it has no files).
    """
    run_dir = Path(run_dir)
    info_path = run_dir / "run.json"
    info = read_json(
        info_path, "run folder", "give a folder written by `gpquad run` or `gpquad baseline`"
    )
    if "scoring_data" in info:
        from gpquad.data.flight import read_flight_file

        sd = _scoring_data(info["scoring_data"], run_dir, info_path)
        flights = [read_flight_file(run_dir / f, tuple(sd["inputs"])) for f in sd["files"]]
        return build_dataset(flights, validation_fraction=sd["validation_fraction"])
    from gpquad.data.io import load_dataset
    from gpquad.study.config import config_from_dict

    table = dict(info["config"])
    table["data"] = {**table["data"], "trim": "none"}
    table.pop("base_dir", None)
    return load_dataset(config_from_dict(table, str(info_path)))


def _scoring_data(sd, run_dir: Path, info_path: Path) -> dict:
    """run.json's scoring_data, checked: files are relative paths that stay inside the run
    folder (no "..", no absolute path, no link out of it), inputs are names."""

    def bad(message: str, field: str):
        raise GpquadError(
            f"{message}; give a folder written by `gpquad baseline`",
            source=str(info_path),
            field=f"scoring_data.{field}",
        )

    if not isinstance(sd, dict) or not isinstance(sd.get("files"), list) or not sd["files"]:
        bad("scoring_data lists its flight files", "files")
    inside = run_dir.resolve()
    for i, name in enumerate(sd["files"]):
        if (
            not isinstance(name, str)
            or Path(name).is_absolute()
            or ".." in Path(name).parts
            or inside not in (run_dir / name).resolve().parents
        ):
            bad(f"{str(name)[:60]!r} is not a file inside the run folder", f"files[{i}]")
    inputs = sd.get("inputs")
    if not isinstance(inputs, list) or not inputs or not all(isinstance(n, str) for n in inputs):
        bad("inputs is a list of input names", "inputs")
    fraction = sd.get("validation_fraction")
    if isinstance(fraction, bool) or not isinstance(fraction, (int, float)) or not 0 < fraction < 1:
        bad(
            f"validation_fraction is a number between 0 and 1, not {fraction!r}",
            "validation_fraction",
        )
    return sd


def check_same_rate(model, dt: float, source: str | None) -> None:
    """A model whose delays count samples of another rate would read the wrong samples:
    refuse a log sampled at another rate than the model's dt (one line)."""
    model_dt = getattr(model, "dt", None)
    if model_dt is not None and abs(dt - model_dt) > 1e-6 * model_dt:
        raise GpquadError(
            f"the log is sampled at {1 / dt:.6g} Hz after the pipeline, the run's "
            f"equations at {1 / model_dt:.6g} Hz (their delays count samples); "
            "set data.resample_hz or data.downsample to give the run's rate",
            source=source,
            field="dt",
        )


#: Longest compare window (samples).
MAX_HORIZON_STEPS = 1_000_000


def compare(run_dirs, horizon_steps: int, data_from=None) -> list[dict]:
    """One row per run: RSE per state, mean RSE, parameter count and fit time.

    All runs are scored on the validation windows of one dataset: that of `data_from`
    (a run folder) or of the first run. A run whose inputs the data lacks gets an error row.
    """
    if not run_dirs:
        raise GpquadError("give at least one run folder", field="compare")
    if (
        isinstance(horizon_steps, bool)
        or not isinstance(horizon_steps, (int, np.integer))
        or not 1 <= horizon_steps <= MAX_HORIZON_STEPS
    ):
        raise GpquadError(
            f"the window length is a whole number of samples from 1 to "
            f"{MAX_HORIZON_STEPS}, not {horizon_steps}",
            field="--horizon",
        )
    dataset = run_dataset(data_from or run_dirs[0])
    rows = []
    for run_dir in run_dirs:
        run = load_run(run_dir)
        row = {
            "run": str(run.path),
            "kind": run.kind,
            "n_parameters": run.n_parameters,
            "fit_time_s": run.fit_time_s,
        }
        try:
            score = score_model(run.model, dataset, horizon_steps, run.trim, run.max_delay)
        except GpquadError as exc:
            row.update({f"rse_{s}": np.nan for s in SCORED_STATES}, mean_rse=np.nan, note=str(exc))
        else:
            row.update(
                {f"rse_{s}": v for s, v in score.rse.items()},
                mean_rse=score.mean_rse,
                windows=score.n_windows,
                steps=score.steps,
                note="",
            )
        rows.append(row)
    return rows


def format_table(rows: list[dict]) -> str:
    """Markdown table of compare() rows."""
    head = (
        ["run", "kind"] + [f"RSE {s}" for s in SCORED_STATES] + ["mean RSE", "params", "fit time s"]
    )
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        cells = [Path(r["run"]).name, r["kind"]]
        cells += [f"{r[f'rse_{s}']:.4g}" for s in SCORED_STATES]
        cells += [f"{r['mean_rse']:.4g}", str(r["n_parameters"]), f"{r['fit_time_s']:.3g}"]
        lines.append("| " + " | ".join(cells) + " |")
    notes = [f"- {Path(r['run']).name}: {r['note']}" for r in rows if r.get("note")]
    return "\n".join(lines + ([""] + notes if notes else [])) + "\n"
