"""The steps that make six per-equation searches one model, in the order
`evolution.finish` lists them: "symmetrize" (gpquad.models.symmetrize), "refine"
(gpquad.models.refine), "repair" (gpquad.models.stability) and "joint_fit"
(gpquad.models.joint_fit); then the printed precision (gpquad.models.precision). Every
fit path (`gpquad run`, `sweep`, `benchmark`, `gpquad.fit`) finishes its model here.

The leading steps that work on each equation alone (`leading_steps`: "symmetrize", and
"refine" but for its full-model check) are `finish_equation`'s, one equation at a time: a
fit may start them as soon as an equation's search ends, while the other searches go on
(gpquad.study.fit), and hand them to `finish_model` as `early`. The model is the same
either way.
"""

from __future__ import annotations

import dataclasses
import time
from typing import NamedTuple

from gpquad.engine.threads import one_blas_thread, thread_map
from gpquad.engine.variables import TARGET_NAMES
from gpquad.models.joint_fit import joint_refit
from gpquad.models.precision import finish_rows, with_printed_digits, without_negligible_terms
from gpquad.models.refine import kept_refinements, refine, refine_equation
from gpquad.models.stability import repair_stability
from gpquad.models.stiffness import model_substeps
from gpquad.models.symmetrize import symmetrize, symmetrize_equation, symmetrized

#: The steps whose work is each equation's own, up to a full-model check ("refine"'s
#: keep_what_flies, made by finish_model).
PER_EQUATION = ("symmetrize", "refine")


class EquationFinish(NamedTuple):
    """One equation through the leading steps (finish_equation)."""

    found: object  # the equation as the search found it
    stages: tuple  # without its negligible terms, then after each leading step
    reports: tuple  # each leading step's report entry (None: nothing to report)
    seconds: float  # wall time of finish_equation


def leading_steps(finish) -> tuple[str, ...]:
    """The first steps of `finish` done equation by equation: those of PER_EQUATION before
    any other step, up to and including the first "refine" (its full-model check follows)."""
    lead: list[str] = []
    for name in finish:
        if name not in PER_EQUATION:
            break
        lead.append(name)
        if name == "refine":
            break
    return tuple(lead)


def _flipped(dataset, vehicle) -> tuple:
    return () if vehicle is None else vehicle.flipped(dataset.input_names)


def finish_equation(equation, dataset, evolution, vehicle=None, workers: int = 1) -> EquationFinish:
    """`equation` without its negligible terms (on finish_rows), then through the leading
    steps of `evolution.finish` (leading_steps), alone. workers: threads of its refinement
    (the same result for any number). Called with BLAS on one thread, as finish_model is
    (gpquad.engine.threads): a limit entered and left by each of several threads would
    lift it under the others."""
    t0 = time.perf_counter()
    flipped = _flipped(dataset, vehicle)
    rows = finish_rows(equation, dataset, evolution.max_delay)
    current = without_negligible_terms(equation, dataset.arrays, rows) if len(rows) else equation
    stages, reports = [current], []
    for name in leading_steps(evolution.finish):
        current, entry = equation_step(name, current, dataset, evolution, flipped, workers)
        stages.append(current)
        reports.append(entry)
    return EquationFinish(equation, tuple(stages), tuple(reports), time.perf_counter() - t0)


def equation_step(name, equation, dataset, evolution, flipped, workers: int = 1):
    """(equation, report entry or None) of the PER_EQUATION step `name` on one equation."""
    if name == "symmetrize" and flipped:
        return symmetrize_equation(equation, dataset, evolution, flipped)
    if name == "refine" and evolution.refine_for(equation.target) > 0:
        return refine_equation(equation, dataset, evolution, flipped, workers)
    return equation, None


def _symmetrized(model, dataset, evolution, flipped, done):
    if not flipped:
        return model
    model, report = symmetrized(model, done)
    return dataclasses.replace(model, symmetrized=report)


def _refined(model, dataset, evolution, flipped, done):
    if not any(evolution.refine_for(t) for t in model.equations):
        return model
    refined = {t: entry for t, entry in done.items() if entry[1] is not None}
    model, report = kept_refinements(model, refined, dataset, flipped)
    return dataclasses.replace(model, refined=report)


def _symmetrize(model, dataset, evolution, flipped, workers):
    if not flipped:
        return model
    model, report = symmetrize(model, dataset, evolution, flipped)
    return dataclasses.replace(model, symmetrized=report)


def _refine(model, dataset, evolution, flipped, workers):
    if not any(evolution.refine_for(t) for t in model.equations):
        return model
    model, report = refine(model, dataset, evolution, flipped, workers)
    return dataclasses.replace(model, refined=report)


def _repair(model, dataset, evolution, flipped, workers):
    if not all(t in model.equations for t in TARGET_NAMES):
        return model
    repaired, report = repair_stability(model, dataset, mirror=flipped)
    return dataclasses.replace(repaired, stability=report)


def _joint_fit(model, dataset, evolution, flipped, workers):
    if not all(t in model.equations for t in TARGET_NAMES):
        return model
    refitted, report = joint_refit(model, dataset, workers=workers)
    return dataclasses.replace(refitted, joint_fit=report)


#: The model's part of each leading step, from its equations' (equation, entry) results.
ASSEMBLE = {"symmetrize": _symmetrized, "refine": _refined}
#: Each step made on the whole model (the per-equation ones after a full-model step).
STEPS = {"symmetrize": _symmetrize, "refine": _refine, "repair": _repair, "joint_fit": _joint_fit}


@one_blas_thread
def finish_model(
    model, dataset, evolution, vehicle=None, on_step=None, workers: int = 1, early=None
):
    """The model after `evolution.finish`'s steps, in their order, with the significant
    digits its printed equations need. `vehicle` (the config's [vehicle], or None: no
    mirror) says which inputs a left-right mirror flips; "repair" and "joint_fit" need
    all six equations and leave a partial model as it is. `on_step(name)` is called
    before each step (progress), and before the equations' own steps ("equations") when
    it makes them. `early`: {target: EquationFinish} made already (finish_equation of the
    model's equation); the others are made here. workers: threads a step may use (the
    equations, the refinement's candidates, the joint refit's Jacobian); the result is the
    same for any number. After each step an RK4 model flies with as many steps per sample
    as its stiffest loop needs (never fewer than before)."""
    flipped = _flipped(dataset, vehicle)
    if not evolution.finish:
        return with_printed_digits(model, dataset)
    done = {t: e for t, e in (early or {}).items() if e.found is model.equations.get(t)}
    todo = [t for t in model.equations if t not in done]
    if todo and on_step is not None:
        on_step("equations")

    def one(target):
        return finish_equation(model.equations[target], dataset, evolution, vehicle, workers)

    done.update(zip(todo, thread_map(one, todo, workers), strict=True))
    model = dataclasses.replace(model, equations={t: done[t].stages[0] for t in model.equations})
    lead = leading_steps(evolution.finish)
    for k, name in enumerate(evolution.finish):
        if on_step is not None:
            on_step(name)
        if k < len(lead):
            results = {t: (done[t].stages[k + 1], done[t].reports[k]) for t in model.equations}
            model = ASSEMBLE[name](model, dataset, evolution, flipped, results)
        else:
            model = STEPS[name](model, dataset, evolution, flipped, workers)
        # a refit stiff loop is flown, from here on and by the model's users, with the RK4
        # steps per sample it was fitted with (gpquad.models.stiffness)
        model = dataclasses.replace(model, substeps=model_substeps(model, dataset))
    return with_printed_digits(model, dataset)
