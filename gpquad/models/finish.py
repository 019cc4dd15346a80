"""The steps that make six per-equation searches one model, in the order
`evolution.finish` lists them: "symmetrize" (gpquad.models.symmetrize), "refine"
(gpquad.models.refine), "repair" (gpquad.models.stability) and "joint_fit"
(gpquad.models.joint_fit); then the printed precision (gpquad.models.precision). Every
fit path (`gpquad run`, `sweep`, `benchmark`, `gpquad.fit`) finishes its model here."""

from __future__ import annotations

import dataclasses

from gpquad.engine.threads import one_blas_thread
from gpquad.models.joint_fit import is_whole, joint_refit
from gpquad.models.precision import with_printed_digits, without_negligible
from gpquad.models.refine import refine
from gpquad.models.stability import repair_stability
from gpquad.models.stiffness import model_substeps
from gpquad.models.symmetrize import symmetrize


def _symmetrize(model, dataset, evolution, flipped, workers, each):
    if not flipped:
        return model
    model, report = symmetrize(model, dataset, evolution, flipped, each)
    return dataclasses.replace(model, symmetrized=report)


def _refine(model, dataset, evolution, flipped, workers, each):
    if not any(evolution.refine_for(t) for t in model.equations):
        return model
    model, report = refine(model, dataset, evolution, flipped, workers, each)
    return dataclasses.replace(model, refined=report)


def _repair(model, dataset, evolution, flipped, workers, each):
    if not is_whole(model, dataset):
        return model
    repaired, report = repair_stability(model, dataset, mirror=flipped)
    return dataclasses.replace(repaired, stability=report)


def _joint_fit(model, dataset, evolution, flipped, workers, each):
    if not is_whole(model, dataset):
        return model
    refitted, report = joint_refit(model, dataset, workers=workers)
    return dataclasses.replace(refitted, joint_fit=report)


STEPS = {"symmetrize": _symmetrize, "refine": _refine, "repair": _repair, "joint_fit": _joint_fit}


@one_blas_thread
def finish_model(
    model, dataset, evolution, vehicle=None, on_step=None, workers: int = 1, each=None
):
    """The model after `evolution.finish`'s steps, in their order, with the significant
    digits its printed equations need. `vehicle` (the config's [vehicle], or None: no
    mirror) says which inputs a left-right mirror flips; "repair" and "joint_fit" need
    an equation for every target whose state the data measure (joint_fit.is_whole) and
    leave a partial model as it is. `on_step(name)` is called
    before each step (progress). workers: threads a step may use (the refinement's
    equations, the joint refit's Jacobian); the result is the same for any number. After
    each step an RK4 model flies with as many steps per sample as its stiffest loop needs
    (never fewer than before). each(kind, equation, compute): how the per-equation results of
    "symmetrize" and "refine" are had (gpquad.models.early_finish.EarlyFinish: taken from
    the work begun during the searches where their input is the same)."""
    flipped = () if vehicle is None else vehicle.flipped(dataset.input_names)
    if evolution.finish:
        model = without_negligible(model, dataset)
    for name in evolution.finish:
        if on_step is not None:
            on_step(name)
        model = STEPS[name](model, dataset, evolution, flipped, workers, each)
        # a refit stiff loop is flown, from here on and by the model's users, with the RK4
        # steps per sample it was fitted with (gpquad.models.stiffness)
        model = dataclasses.replace(model, substeps=model_substeps(model, dataset))
    return with_printed_digits(model, dataset)
