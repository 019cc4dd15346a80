"""Full-model front swaps: a model whose equations diverge, or fly badly, together.

Each equation is identified with the other accelerations taken from the data, so each can
be stable alone and the six together unstable: the attitude loops of angle-mode flights
can be fitted as stiff as the data allow (p_dot = -1800 phi - 80 p + ...
at 25 Hz; for that loop alone and the integrator's explicit step the discrete poles are at
|z| ~ 0.8, computed), and a coupling term of another equation (r theta, q u_R) is
enough to push one of them out of the unit circle once every state is integrated
(measured on rotorpy-angle, hummingbird: every equation flies alone, the full model
diverged in 21 of 42 seven-second windows).

When the full model diverges on the judged windows (validation, else training; the joint
refit's longest horizon), each equation's size/error front (`Equation.candidates`, the
run's other climbers) is searched greedily: every single swap of one equation for one of
its front's alternatives is flown, the swap with the fewest diverged windows (then the
lowest full-model error, `FullModelError`) is kept if it beats the current model, and
the search repeats until no window diverges or no swap helps. A model that does not diverge
is returned unchanged.

With `mirror` (`vehicle.mirror_inputs`: the roll and yaw commands of a left-right
symmetric vehicle), the judged windows are also flown mirrored (gpquad.data.mirror) and their
divergences count after those of the recorded windows: a swap is scored by (diverged
recorded windows, diverged mirrored windows, full-model error of the recorded windows), so
the mirror never trades a recorded flight's accuracy for its own and only decides between
models that fly the recorded flights equally.

No random draw: the result is a function of model and data.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from gpquad.data.mirror import mirror_dataset
from gpquad.engine.variables import TARGET_NAMES
from gpquad.models.joint_fit import (
    CHECK_HORIZON_S,
    FullModelError,
    is_whole,
    judged_windows,
    measured_states,
)
from gpquad.models.scoring import SCORED_INDEX, diverged, divergence_bound

#: At most this many rounds of single swaps (each round flies every alternative once).
MAX_ROUNDS = 6


class FullModelFlights:
    """(diverged windows, full-model error) of a model over fixed windows of a dataset."""

    def __init__(self, dataset, starts: np.ndarray, steps: int):
        self.error = FullModelError(dataset, starts, steps, measured_states(dataset))
        self.bound = divergence_bound(dataset.arrays.states[:, list(SCORED_INDEX)])

    def windows(self, model) -> tuple[int, np.ndarray]:
        """(diverged windows, each window's share of the full-model error)."""
        pred = model.simulate(self.error.dataset, self.error.starts, self.error.steps)
        n_div = int(diverged(pred, self.bound).sum())
        r = self.error.residuals_of(pred).reshape(len(self.error.starts), -1)
        return n_div, (r * r).sum(axis=1)


def _swap(model, target: str, equation):
    """The model with `equation` for `target`; the target's front stays with it."""
    kept = dataclasses.replace(equation, candidates=model.equations[target].candidates)
    return dataclasses.replace(model, equations={**model.equations, target: kept})


def repair_stability(model, dataset, seconds: float = CHECK_HORIZON_S, mirror=()):
    """(model, report): the model with equations swapped for front alternatives until its
    full-model flights stop diverging (or no swap helps); with `mirror` (input names), the
    mirrored flights count too (module notes). Unchanged when no swap is needed or helps.

    report: {"horizon_s", "judged_on", "windows", "diverged_before", "diverged_after",
    "error_before", "error_after", "swaps": [{"target", "from", "to", "why"}], "flights"},
    with mirror also "mirrored", "mirrored_diverged_before" and "_after"; why is
    "diverged" or "mirror diverged". None when the model lacks the equation of a measured
    state (joint_fit.is_whole) or no window fits.
    """
    if not is_whole(model, dataset):
        return model, None
    starts, steps, judged_on = judged_windows(dataset, model, seconds)
    if len(starts) == 0:
        return model, None
    flights = FullModelFlights(dataset, starts, steps)
    mirrored = FullModelFlights(mirror_dataset(dataset, mirror), starts, steps) if mirror else None

    def fly(candidate) -> tuple[tuple[int, int, float], np.ndarray]:
        n_div, windows = flights.windows(candidate)
        n_mirror = mirrored.windows(candidate)[0] if mirrored is not None else 0
        return (n_div, n_mirror, float(windows.sum())), windows

    best = fly(model)[0]
    report: dict[str, Any] = {
        "horizon_s": float(seconds),
        "judged_on": judged_on,
        "windows": int(len(starts)),
        "diverged_before": best[0],
        "error_before": best[2],
        "swaps": [],
        "flights": 1,
    }
    if mirrored is not None:
        report.update(mirrored=list(mirror), mirrored_diverged_before=best[1])
    alternatives = (
        {t: e.alternatives() for t, e in model.equations.items()} if best[0] or best[1] else {}
    )
    for _ in range(MAX_ROUNDS):
        if best[0] == 0 and best[1] == 0:
            break
        pick = None
        for target in TARGET_NAMES:
            for alt in alternatives.get(target, ()):
                score = fly(_swap(model, target, alt))[0]
                report["flights"] += 1
                if score < (pick[0] if pick else best):
                    pick = (score, target, alt)
        if pick is None:
            break
        score, target, alt = pick
        why = "diverged" if best[0] else "mirror diverged"
        report["swaps"].append(
            {"target": target, "from": model.equations[target].text(), "to": alt.text(), "why": why}
        )
        model, best = _swap(model, target, alt), score
    report.update(diverged_after=best[0], error_after=best[2])
    if mirrored is not None:
        report["mirrored_diverged_after"] = best[1]
    return model, report


def stability_summary(report: dict) -> str:
    """One line for the user: what the repair did."""
    n, before, after = report["windows"], report["diverged_before"], report["diverged_after"]
    mirror = ""
    if "mirrored" in report:
        m_before, m_after = report["mirrored_diverged_before"], report["mirrored_diverged_after"]
        mirror = f"; mirrored ({', '.join(report['mirrored'])} flipped): {m_before} diverged"
        if m_before:
            mirror_swaps = [
                s["target"] for s in report["swaps"] if s.get("why") == "mirror diverged"
            ]
            mirror += f", {m_after} after swapping {', '.join(mirror_swaps) or 'none'}"
    if not before:
        line = f"full model: no diverged window in {n} {report['horizon_s']:g} s flights"
        return line + mirror
    swapped = ", ".join(s["target"] for s in report["swaps"]) or "none"
    return (
        f"full model diverged in {before} of {n} {report['horizon_s']:g} s "
        f"{report['judged_on']} flights; equations swapped for front alternatives: "
        f"{swapped}; diverged after: {after}{mirror}"
    )
