"""`gpquad score RUN_DIR --data LOG` and `gpquad data export LOG --out FILE`.

Scoring flies a run's equations over the windows of another flight (or the held-out part of
one it trained on) with `gpquad.models.scoring`'s definition: RSE of the integrated states u, v, w,
p, q, r over non-overlapping windows of `--horizon-s`, each from the recorded state with the
recorded inputs. A state the log does not measure is NaN; a window is diverged when the
prediction is non-finite or leaves 10 x the data's largest |state|. Signals that leave the
run's training range on more than 1 % of the scored samples are listed
(gpquad.models.envelope). When the run's vehicle is left-right symmetric (`vehicle`), the
windows are also flown mirrored left-right (gpquad.data.mirror) and their diverged count is
reported: an equation that holds only on the side of the flights the training log flew.

With integrator "rk4" the same windows are also flown in continuous time, the equations
integrated by RK4 with FIDELITY_SUBSTEPS steps per sample (gpquad.engine.kernels.step), as a
reader flies printed ODEs in their own simulator; its RSE is printed beside the run's own
(the scheme the run was fitted with, model.json's integrator; eq. 2 by default).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from gpquad.errors import GpquadError

PARTS = ("auto", "all", "validation")
#: `--integrator`: the run's own scheme only, or also RK4 (continuous-time fidelity).
INTEGRATORS = ("own", "rk4")
#: RK4 steps per sample of the continuous-time score.
FIDELITY_SUBSTEPS = 8


def readers_scheme(integrator: str, substeps: int) -> tuple[str, int]:
    """The scheme a reader's simulator flies a model's printed equations with: ODEs
    (integrator "rk4") by RK4 with at least FIDELITY_SUBSTEPS steps per sample; eq. 2
    models, which are discrete-time, by eq. 2."""
    if integrator == "rk4":
        return "rk4", max(substeps, FIDELITY_SUBSTEPS)
    return integrator, substeps


def _part(cfg, path: Path, part: str) -> str:
    """Which windows to score: the whole log, or the held-out part of a training log."""
    from gpquad.data.io import held_out_paths

    if part != "auto":
        return part
    if path in held_out_paths(cfg):
        return "all"
    if cfg.data.files and path in cfg.data_paths():
        if not isinstance(cfg.data.validation, str):
            raise GpquadError(
                "this log trained the run whole (data.validation lists other "
                "files); give --part all to score it anyway",
                source=str(path),
                field="--part",
            )
        return "validation"
    return "all"


def score_log(
    run_dir,
    log,
    horizon_s: float = 7.0,
    fmt: str | None = None,
    part: str = "auto",
    check: bool = True,
    integrator: str = "own",
) -> dict:
    """RSE per state, window counts and what was scored (see the module docstring)."""
    from gpquad.data.dataset import build_dataset
    from gpquad.data.integration_check import screen_segments
    from gpquad.data.io import READERS, guess_format
    from gpquad.models.scoring import (
        SCORED_STATES,
        check_same_rate,
        diverged,
        load_run,
        model_view,
        rse,
        validation_windows,
        windows_bound,
    )
    from gpquad.study.config import load_folder_config

    if part not in PARTS:
        raise GpquadError(f"choose one of {list(PARTS)}", field="--part")
    if not (np.isfinite(horizon_s) and horizon_s > 0):
        raise GpquadError(
            f"must be a finite number of seconds > 0, not {horizon_s}", field="--horizon-s"
        )
    if integrator not in INTEGRATORS:
        raise GpquadError(f"choose one of {list(INTEGRATORS)}", field="--integrator")
    run = load_run(run_dir)
    cfg = load_folder_config(run_dir)
    path = Path(log).resolve()
    if not path.exists():
        raise GpquadError("no such file or folder", source=str(log), field="--data")
    if not (path.is_file() or path.is_dir()):
        raise GpquadError(
            "not a regular file or folder (a pipe or a device)", source=str(log), field="--data"
        )
    fmt = fmt or guess_format(path)
    if fmt not in READERS:
        raise GpquadError(
            f"unknown format '{fmt}'; known: {sorted(READERS)}", source=str(log), field="--format"
        )
    which = _part(cfg, path, part)
    data = dataclasses.replace(cfg.data, format=fmt, files=(str(path),))
    flights = READERS[fmt](path, data)
    dropped: list[str] = []
    if data.check_before_run and check:
        flights, dropped, _ = screen_segments(
            flights,
            data.check_steps,
            data.check_max_rse,
            source=str(log),
            field="--data",
            skip_hint="give --no-check to score it anyway",
        )
    dataset = build_dataset(
        flights,
        validation_fraction=data.validation_fraction,
        held_out=None if which == "validation" else [True] * len(flights),
    )
    if tuple(run.model.input_names) != tuple(dataset.input_names):
        raise GpquadError(
            f"the run's equations read inputs {list(run.model.input_names)} but "
            f"the log gives {list(dataset.input_names)}; score with the run's "
            "input level",
            source=str(log),
            field="data.inputs",
        )
    check_same_rate(run.model, dataset.dt, str(log))
    steps = max(1, int(round(horizon_s / dataset.dt)))
    starts, steps = validation_windows(dataset, steps, run.max_delay)
    view = model_view(dataset, run.trim)
    pred = run.model.simulate(view, starts, steps)
    truth = dataset.arrays.states[starts[:, None] + np.arange(steps + 1)[None, :]]
    bound = windows_bound(dataset, starts, steps)
    n_diverged = int(diverged(pred, bound).sum())
    values = rse(pred, truth)
    flipped = cfg.vehicle.flipped(dataset.input_names)
    mirrored = None
    if flipped and all(n in dataset.input_names for n in flipped):
        mirrored = {
            "inputs": list(flipped),
            "diverged": mirrored_diverged(run.model, view, starts, steps, bound, flipped),
        }
    outside = []
    if run.model.envelope:
        from gpquad.models.envelope import outside_envelope

        rows = np.unique(starts[:, None] + np.arange(steps + 1)[None, :])
        outside = outside_envelope(run.model.envelope, view, rows)

    def measured(values):
        return {
            s: float("nan") if dataset.unmeasured(s) else float(v)
            for s, v in zip(SCORED_STATES, values, strict=True)
        }

    continuous = None
    if integrator == "rk4":
        rk4 = dataclasses.replace(run.model, integrator="rk4", substeps=FIDELITY_SUBSTEPS)
        pred_rk4 = rk4.simulate(view, starts, steps)
        continuous = {
            "substeps": FIDELITY_SUBSTEPS,
            "rse": measured(rse(pred_rk4, truth)),
            "diverged": int(diverged(pred_rk4, bound).sum()),
        }
    baselines = reference_scores(run.model, dataset, starts, steps, bound)
    return {
        "run": str(run_dir),
        "data": str(log),
        "format": fmt,
        "part": which,
        "horizon_s": steps * dataset.dt,
        "steps": int(steps),
        "windows": int(len(starts)),
        "diverged": n_diverged,
        "rse": measured(values),
        "integrator": {"scheme": run.model.integrator, "substeps": run.model.substeps},
        "rk4": continuous,
        "input_names": list(dataset.input_names),
        "segments": [f.name for f in flights],
        "dropped": dropped,
        "outside_training": outside,
        "mirrored": mirrored,
        "baselines": baselines,
    }


def reference_scores(model, dataset, starts, steps: int, bound) -> dict:
    """{name: {state: RSE or NaN (not measured), "diverged": n}} of the reference models
    (gpquad.models.reference_models) flown over the same windows of the raw data."""
    from gpquad.models.reference_models import reference_models
    from gpquad.models.scoring import flown_score

    models = reference_models(model.input_names, model.dt, dataset.flight_info)
    return {name: flown_score(m, dataset, starts, steps, bound) for name, m in models.items()}


def mirrored_diverged(model, dataset, starts, steps: int, bound, flipped) -> int:
    """Windows of `dataset` (the model's input view) that diverge flown mirrored left-right
    with the inputs `flipped` changing sign (gpquad.models.scoring.diverged with the recorded
    windows' `bound`: a mirror changes signs, not magnitudes)."""
    from gpquad.data.mirror import mirror_dataset
    from gpquad.models.scoring import diverged

    pred = model.simulate(mirror_dataset(dataset, flipped), starts, steps)
    return int(diverged(pred, bound).sum())


def _cell(v: float) -> str:
    """An RSE for the table: '-' where the log does not measure the state, '!' above 1."""
    if not np.isfinite(v):
        return f"{'-':>9}"
    return f"{v:>8.4g}{'!' if v > 1 else ' '}"


def format_score(result: dict) -> str:
    head = f"{'':10}" + "".join(f"{s:>9}" for s in result["rse"])
    rows = [("model", result["rse"])]
    if result.get("rk4"):
        rows.append((f"rk4 x{result['rk4']['substeps']}", result["rk4"]["rse"]))
    rows += [(n, {s: r[s] for s in result["rse"]}) for n, r in result.get("baselines", {}).items()]
    table = [f"{name:10}" + "".join(_cell(v) for v in values.values()) for name, values in rows]
    lines = [
        f"score of {result['run']} on {result['data']} ({result['part']} part, "
        f"{len(result['segments'])} segment(s), inputs {', '.join(result['input_names'])})",
        f"RSE of the integrated states over {result['windows']} window(s) of "
        f"{result['steps']} steps ({result['horizon_s']:.2f} s); "
        f"{result['diverged']} diverged; - = not measured by the log; ! = RSE above 1, "
        "no better than the data's mean; zero: every acceleration zero"
        + (
            "; set-point: each rate follows its set-point"
            if "set-point" in result.get("baselines", {})
            else ""
        )
        + (
            f"; rk4 x{result['rk4']['substeps']}: the printed equations flown in "
            f"continuous time ({result['rk4']['diverged']} diverged)"
            if result.get("rk4")
            else ""
        ),
        head,
        *table,
    ]
    lines.extend(f"warning: {d}" for d in result["dropped"])
    mirrored = result.get("mirrored")
    if mirrored:
        line = (
            f"mirrored left-right ({', '.join(mirrored['inputs'])} flipped): "
            f"{mirrored['diverged']} of {result['windows']} window(s) diverged"
        )
        if mirrored["diverged"]:
            line += (
                "; an equation holds only on the side of the flights the training log "
                "flew (vehicle.mirror_inputs)"
            )
        lines.append(line)
    lines.extend(
        f"note: {o['signal']} leaves the training range on {100 * o['fraction']:.1f} % "
        f"of the scored samples (training {o['training'][0]:.3g}..{o['training'][1]:.3g}"
        f", here {o['seen'][0]:.3g}..{o['seen'][1]:.3g}): the equations extrapolate "
        "there"
        for o in result.get("outside_training", [])
    )
    return "\n".join(lines)
