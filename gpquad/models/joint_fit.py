"""Joint refit of a full model's constants on six-equation rollouts (the "joint_fit" step).

Each equation is identified with the other five accelerations taken from the data (paper
section 3.2), so each is right with the data's states around it. Flown together, a small
error in one (say an attitude loop) is integrated by the others (the velocities), and the
full model drifts. This step refits the constants of every equation at once on the error
of the full model, every state integrated:

    minimise  sum_s  sum_{w,k} (x_s[w,k] - data_s[w,k])^2 / sum_{w,k} (data_s - mean)^2

over the measured states s of (u, v, w, p, q, r): the sum of the benchmark's RSEs. It is
gpquad's Levenberg-Marquardt fit (`gpquad.engine.evolve.lm.levenberg_marquardt`, whose
result does not depend on earlier fits in the process, as MINPACK's did; each Jacobian
triangularised through its normal equations), with the Jacobian at every
JACOBIAN_REFRESH-th step and Broyden's update of it in between: a continuous-time model's
from one sensitivity flight of the full model (gpquad.models.joint_jacobian), an eq. 2
model's by forward differences, one rollout per constant;
on non-overlapping training windows of a growing horizon (JOINT_HORIZONS_S, each fit
starting from the last, so that the short windows keep it in the basin of the
per-equation constants); each later fit keeps the shorter windows'
residuals beside its own, so that the model stays right over one second as well as over
ten (measured on rotorpy-angle: fitting the 10 s windows alone made the 1 s RSE of p, q
40 % worse) and thirty: the velocities integrate the attitude, and a model refitted on
10 s windows alone can drift beyond them (rotorpy-rate;
docs/decisions/2026-11-26-joint-refit-horizon.md). The horizon stops growing once a fit
flies the model to round-off (every state's RSE at each horizon below the selection's
RSE_RESOLUTION, squared, on average): it has no drift left to correct. Structures are
not changed.

Each horizon's fit is a candidate: the one with the lowest error on the validation windows
below is kept if it is significantly better than the model as it was. Where drift matters
(rotorpy-rate) the 30 s fit wins there; where the validation pieces are short and only the
rates are measured (betaflight-gecko) the 10 s fit does.
The refit is kept only if it lowers the same error on the validation windows (or, with
no validation data, on the training windows) at the longest horizon they fit, flown as a
reader flies the printed ODEs (`as_flown_by_readers`: RK4 with 8 steps per sample for a
continuous-time model, so that constants that fly only by one RK4 step's damping are
not kept), by more than the
windows' spread explains (`significant_drop`: mean paired drop > 2 standard errors, or
every window lower and the sum at most half), the report says which windows, with both
errors. A marginal drop is not enough because the
refit moves every constant: where one equation has a wrong term, the refit shifts the
others' constants to make up for it (measured on rigid-body, seed 3: a_y kept a
substitute term, the refit lowered the validation error by 11 % and moved the exact
0.7 p q of r_dot to 0.741). The second way in is for drops that the t statistic
misses because they are skewed: on the held-out vehicle (rotorpy-heldout-angle, seed 3)
the refit lowered all 11 validation windows, 0.144 -> 0.036 in sum, but one window held
three quarters of the drop and the t statistic was 1.5; refused, the model flew r to RSE
2.5 at 7 s on the test flight. A 120 s validation flight has only four 30 s windows, too
few for a real drop to look significant (rotorpy-rate, hummingbird, seed 2: 0.43 -> 0.36,
refused; the model kept flew u, v, w to RSE 0.19 at 7 s): the refit is also kept when the
longest windows' error does not rise and the drop is significant on the CHECK_HORIZON_S
windows. No random draw: the result is a function of model and data.
Equations whose state the log does not measure keep their constants.
"""

from __future__ import annotations

import dataclasses
import itertools
import time
from typing import Any

import numpy as np

from gpquad.data.score import readers_scheme
from gpquad.engine.evolve.lm import (
    broyden_jacobian,
    forward_difference,
    levenberg_marquardt,
    normal_triangularize,
)
from gpquad.engine.evolve.selection import RSE_RESOLUTION
from gpquad.engine.evolve.windows import spread, tile
from gpquad.engine.threads import chunks, thread_map
from gpquad.engine.tree.encoding import Tree
from gpquad.engine.tree.operators import CONST
from gpquad.engine.variables import TARGET_NAMES, TARGET_STATE
from gpquad.models.joint_jacobian import has_sensitivities, sensitivity_jacobian
from gpquad.models.scoring import SCORED_INDEX, SCORED_STATES, rse_denominator
from gpquad.models.stiffness import model_substeps

#: Window lengths of the growing horizon (s); the last one, shortened to the longest
#: validation range if need be, decides acceptance.
JOINT_HORIZONS_S = (1.0, 10.0, 30.0)
#: Window length (s) of the full-model checks before the refit (the stability repair,
#: the refinement's keep_what_flies).
CHECK_HORIZON_S = 10.0
#: At most this many windows per horizon (evenly spread over the training data).
MAX_WINDOWS = 120
#: The fit's budget per horizon: residual evaluations (not counting the Jacobians) as a
#: multiple of (constants + 1).
EVALS_PER_CONSTANT = 12
#: The fit stops when a step's actual and predicted drops of the objective are below this
#: fraction (lm.levenberg_marquardt's ftol; docs/decisions/2026-11-27-joint-jacobian.md).
FTOL = 1e-5
#: The fit's stall rule (steps, relative drop), of the same form as lm.STALL and
#: refine_problem.STALL: a fit stops once that many steps taken together lowered the
#: objective by at most that fraction of it (docs/decisions/2026-11-27-joint-stall.md).
JOINT_STALL = (3, 1e-3)
#: The fit's Jacobian is made by forward differences (one rollout per constant) at every
#: JACOBIAN_REFRESH-th point it asks for one, and by Broyden's secant update of the last
#: one in between (lm.broyden_jacobian; docs/decisions/2026-11-27-jacobians.md).
JACOBIAN_REFRESH = 5
#: A residual entry is clipped to this many state SDs, so that a window that diverges
#: while a constant is perturbed gives a large, finite error rather than NaN.
RESIDUAL_CLIP = 1e3
#: The refit is kept when the paired drop of the judged windows' errors is this many
#: standard errors above zero (a one-sided test at about 2.5 %).
SIGNIFICANCE = 2.0
#: ... or when every judged window's error dropped and their sum fell to this fraction.
LARGE_DROP = 0.5


def is_whole(model, dataset) -> bool:
    """Whether the model flies every measured state by an equation of its own: each target
    has one, or the data do not measure its state (such a target is not identified,
    gpquad.study.fit.measured_targets, and its flights take the data's acceleration)."""
    return all(t in model.equations or dataset.unmeasured(TARGET_STATE[t]) for t in TARGET_NAMES)


def constant_nodes(model) -> list[tuple[str, np.ndarray]]:
    """(target, indices of its CONST nodes) for each target the model has an equation for."""
    return [
        (t, np.flatnonzero(model.equations[t].tree.codes == CONST))
        for t in TARGET_NAMES
        if t in model.equations
    ]


def with_constants(model, slots, x: np.ndarray):
    """The model with the constants of `slots` set from the flat vector x."""
    eqs, at = dict(model.equations), 0
    for target, idx in slots:
        eq = eqs[target]
        values = eq.tree.values.copy()
        values[idx] = x[at : at + len(idx)]
        at += len(idx)
        eqs[target] = dataclasses.replace(eq, tree=Tree(eq.tree.codes, values, eq.tree.delays))
    return dataclasses.replace(model, equations=eqs)


class FullModelError:
    """Normalised residuals of a full model over fixed windows of a dataset; the windows
    are flown in up to `workers` threads (each window's arithmetic is its own: the same
    residuals for any number)."""

    def __init__(self, dataset, starts: np.ndarray, steps: int, states: list[int], workers=1):
        self.dataset, self.starts, self.steps = dataset, starts, steps
        self.cols = [SCORED_INDEX[i] for i in states]
        idx = starts[:, None] + np.arange(1, steps + 1)[None, :]
        self.data = dataset.arrays.states[idx][:, :, self.cols]  # (W, steps, S)
        self.scale = 1.0 / np.sqrt(np.maximum(rse_denominator(self.data), 1e-300))
        self.chunks = chunks(len(starts), workers)

    def residuals(self, model) -> np.ndarray:
        if len(self.chunks) < 2:
            return self.residuals_of(model.simulate(self.dataset, self.starts, self.steps))
        parts = thread_map(
            lambda chunk: model.simulate(self.dataset, self.starts[chunk], self.steps),
            self.chunks,
            len(self.chunks),
        )
        return self.residuals_of(np.concatenate(parts))

    def residuals_of(self, flown: np.ndarray) -> np.ndarray:
        """The residuals of states flown over the windows (W, steps + 1, 9)."""
        pred = flown[:, 1:, :][:, :, self.cols]
        with np.errstate(invalid="ignore", over="ignore"):
            r = (pred - self.data) * self.scale
        r = np.where(np.isfinite(r), r, RESIDUAL_CLIP)
        return np.clip(r, -RESIDUAL_CLIP, RESIDUAL_CLIP).ravel()

    def jacobian_of(self, flown: np.ndarray, sens: np.ndarray) -> np.ndarray:
        """The Jacobian of residuals_of(flown) from the sensitivities of u, v, w, p, q, r
        (W, steps + 1, 6, n) flown with it (gpquad.models.joint_jacobian); zero rows where
        a residual is clipped or not finite."""
        rows = [c - SCORED_INDEX[0] for c in self.cols]
        live = np.abs(self.residuals_of(flown)).reshape(self.data.shape) < RESIDUAL_CLIP
        with np.errstate(invalid="ignore", over="ignore"):
            jac = sens[:, 1:][:, :, rows, :] * self.scale[None, None, :, None]
        jac = np.where(live[..., None] & np.isfinite(jac), jac, 0.0)
        return jac.reshape(-1, jac.shape[-1])

    def error(self, model) -> float:
        """Sum over the states of their RSE (the objective)."""
        r = self.residuals(model)
        return float(r @ r)

    def window_errors(self, model) -> np.ndarray:
        """Each window's share of `error` (W,): they sum to it."""
        r = self.residuals(model).reshape(len(self.starts), -1)
        return (r * r).sum(axis=1)


def significant_drop(before: np.ndarray, after: np.ndarray) -> bool:
    """True when the windows' errors dropped by more than their spread explains: the mean
    paired drop exceeds SIGNIFICANCE standard errors, or every window dropped and the sum
    fell to at most LARGE_DROP of itself (one window: it must drop)."""
    before, after = np.asarray(before, dtype=float), np.asarray(after, dtype=float)
    drop = before - after
    if drop.size < 2:
        return bool(drop.sum() > 0)
    if np.all(drop > 0) and after.sum() <= LARGE_DROP * before.sum():
        return True
    return bool(drop.mean() > SIGNIFICANCE * drop.std(ddof=1) / np.sqrt(drop.size))


def horizon_starts(dataset, ranges, seconds: float, history: int, limit: int | None):
    """Non-overlapping window starts of `seconds` over `ranges` (at most `limit` of them,
    evenly spread), and their step count."""
    steps = max(1, int(round(seconds / dataset.dt)))
    starts, got = tile(ranges, steps, history)
    if limit is not None:
        starts = spread(starts, limit)
    return starts, got


def measured_states(dataset) -> list[int]:
    """Indices into SCORED_STATES of the states every flight of the dataset measures."""
    return [i for i, s in enumerate(SCORED_STATES) if not dataset.unmeasured(s)]


def model_history(model) -> int:
    """Input samples a model reads before a window's start (its largest delay)."""
    return max(int(e.tree.delays.max()) for e in model.equations.values())


def as_flown_by_readers(model):
    """The model flown as a reader's simulator flies its printed equations
    (gpquad.data.score.readers_scheme)."""
    integrator, substeps = readers_scheme(model.integrator, model.substeps)
    if (integrator, substeps) == (model.integrator, model.substeps):
        return model
    return dataclasses.replace(model, integrator=integrator, substeps=substeps)


def judged_windows(dataset, model, seconds: float) -> tuple[np.ndarray, int, str]:
    """Window starts and steps of `seconds` over the validation ranges, else the training
    ranges, and which ("validation" or "training"): where full models are judged."""
    history = model_history(model)
    starts, steps = horizon_starts(dataset, dataset.validation, seconds, history, None)
    if len(starts):
        return starts, steps, "validation"
    starts, steps = horizon_starts(dataset, dataset.train, seconds, history, None)
    return starts, steps, "training"


def joint_refit(model, dataset, horizons_s=JOINT_HORIZONS_S, workers: int = 1):
    """(model, report): the model with its constants refitted jointly, or the model as it
    was when that does not lower the full-model error at the longest horizon. workers:
    threads for the flights' windows and the forward differences' columns (the same result
    for any number).

    The fit flies the model with the RK4 steps per sample its stiffest loop needs
    (gpquad.models.stiffness.model_substeps); the model keeps its own scheme.

    report: {"accepted", "horizon_s", "judged_on" ("validation" or "training"),
    "error_before", "error_after" (sum of the measured states' RSE there), "states",
    "constants", "rollouts" (full-model flights over the training windows, forward
    differences' included), "sensitivity_flights" (a continuous-time model's Jacobians),
    "substeps" (of the fit's flights), "stages" ({horizon: judged error of the
    fit that ended there}), "fitted_to_s" (the horizon of the fit judged best, the one
    kept if it is significantly better), "time_s"}.
    """
    t0 = time.perf_counter()
    states = measured_states(dataset)
    fitted_targets = {
        t for t in TARGET_NAMES if TARGET_STATE[t] in {SCORED_STATES[i] for i in states}
    }
    slots = [(t, idx) for t, idx in constant_nodes(model) if t in fitted_targets and len(idx)]
    x0 = (
        np.concatenate([model.equations[t].tree.values[idx] for t, idx in slots])
        if slots
        else np.zeros(0)
    )
    history = model_history(model)
    report: dict[str, Any] = {
        "accepted": False,
        "horizon_s": float(horizons_s[-1]),
        "states": [SCORED_STATES[i] for i in states],
        "constants": int(x0.size),
        "rollouts": 0,
    }
    # windows of the longest horizon, shortened to the longest validation range if need be
    judge_starts, judge_steps, judged_on = judged_windows(dataset, model, horizons_s[-1])
    report["horizon_s"] = round(float(judge_steps * dataset.dt), 9)
    if x0.size == 0 or not states or len(judge_starts) == 0 or not is_whole(model, dataset):
        report.update(
            judged_on=None, error_before=None, error_after=None, time_s=time.perf_counter() - t0
        )
        return model, report
    judge = FullModelError(dataset, judge_starts, judge_steps, states, workers)
    read_before = as_flown_by_readers(model)
    before_w = judge.window_errors(read_before)
    before = float(before_w.sum())
    x = x0.copy()
    objectives, staged = [], []
    rollouts = itertools.count()  # thread-safe: the Jacobian's columns may run in threads
    sensitivities = itertools.count()  # sensitivity flights (RK4 models' Jacobians)
    # flown with as many RK4 steps per sample as its stiffest loop needs to be its ODE
    flown = dataclasses.replace(model, substeps=model_substeps(model, dataset))
    report["substeps"] = flown.substeps
    for seconds in horizons_s:
        starts, steps = horizon_starts(dataset, dataset.train, seconds, history, MAX_WINDOWS)
        if len(starts) == 0:
            continue
        objectives.append(FullModelError(dataset, starts, steps, states, workers))

        def residuals(v, objectives=tuple(objectives)):
            next(rollouts)
            m = with_constants(flown, slots, v)
            return np.concatenate([o.residuals(m) for o in objectives])

        if has_sensitivities(flown):
            value, jacobian = sensitivity_jacobian(
                residuals,
                lambda v: with_constants(flown, slots, v),
                slots,
                dataset,
                tuple(objectives),
                workers,
                sensitivities,
            )
        else:
            value, jacobian = forward_difference(residuals, workers)
        jacobian = broyden_jacobian(value, jacobian, JACOBIAN_REFRESH)
        x = levenberg_marquardt(
            value,
            x,
            jacobian,
            EVALS_PER_CONSTANT * (x.size + 1),
            FTOL,
            stall=JOINT_STALL,
            triangularize=normal_triangularize,
        )
        staged.append((float(seconds), x))
        reached = value(x)
        if float(reached @ reached) < len(objectives) * len(states) * RSE_RESOLUTION**2:
            break  # flown to round-off (selection's resolution): nothing left to drift
    report["rollouts"] = next(rollouts)
    report["sensitivity_flights"] = next(sensitivities)
    # each horizon's fit is a candidate; the validation windows choose among them
    judged = []
    for seconds, x in staged or [(0.0, x0)]:  # (none without a training window: no change)
        refitted = with_constants(model, slots, x)
        judged.append((judge.window_errors(as_flown_by_readers(refitted)), seconds, refitted))
    after_w, stage_s, refitted = min(judged, key=lambda j: float(j[0].sum()))
    accepted = significant_drop(before_w, after_w) or (
        float(after_w.sum()) <= before
        and drops_on_shorter_windows(dataset, states, judge_steps, read_before, refitted)
    )
    report.update(
        accepted=accepted,
        judged_on=judged_on,
        error_before=before,
        error_after=float(after_w.sum()),
        fitted_to_s=stage_s,
        stages={f"{s:g}": float(w.sum()) for w, s, _ in judged},
        time_s=time.perf_counter() - t0,
    )
    return (refitted if accepted else model), report


def drops_on_shorter_windows(dataset, states, judged_steps: int, before, refitted) -> bool:
    """Whether `refitted` flies the CHECK_HORIZON_S windows (more of them than the longest
    ones, so that a real drop can look significant) significantly better than `before`
    (already as readers fly it); False when those windows are no shorter than the judged
    ones (the same test, already made)."""
    starts, steps, _ = judged_windows(dataset, refitted, CHECK_HORIZON_S)
    if steps >= judged_steps or len(starts) == 0:
        return False
    short = FullModelError(dataset, starts, steps, states)
    return significant_drop(
        short.window_errors(before), short.window_errors(as_flown_by_readers(refitted))
    )


def joint_fit_summary(report: dict) -> str:
    """One line for the user: what the joint refit did."""
    if report.get("error_before") is None:
        return "joint refit: not made (no measured state or no window fits)"
    verdict = "kept" if report["accepted"] else "not kept (not significantly better)"
    return (
        f"joint refit of {report['constants']} constants on full-model rollouts: "
        f"{verdict}; {report['judged_on']} error (sum of the RSE of "
        f"{', '.join(report['states'])} over {report['horizon_s']:g} s windows) "
        f"{report['error_before']:.4g} -> {report['error_after']:.4g}"
    )
