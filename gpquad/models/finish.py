"""The steps that make a model of six per-equation searches one model: stability repair
(gpquad.models.stability), joint refit (gpquad.models.joint_fit) and printed precision
(gpquad.models.precision)."""

from __future__ import annotations

import dataclasses

from gpquad.engine.threads import one_blas_thread
from gpquad.engine.variables import TARGET_NAMES
from gpquad.models.joint_fit import joint_refit
from gpquad.models.precision import with_printed_digits
from gpquad.models.refine import refine
from gpquad.models.stability import repair_stability
from gpquad.models.symmetrize import symmetrize


def mirror_inputs(evolution, dataset) -> tuple[str, ...]:
    """The inputs the stability repair flips in its mirrored flights (gpquad.data.mirror):
    `evolution.mirror_inputs` when the dataset has all of them, else none (off)."""
    names = tuple(evolution.mirror_inputs)
    return names if names and all(n in dataset.input_names for n in names) else ()


@one_blas_thread
def finish_model(model, dataset, evolution):
    """The model after the full-model steps the config asks for, when all six equations
    are there: the refined equations (`evolution.refine_terms`, model.refined), the
    stability repair (`evolution.stability_repair`) and full-model front
    selection (`evolution.front_selection`; with the mirrored flights of
    `evolution.mirror_inputs`), their report in model.stability, then the
    joint refit (`evolution.joint_fit`, model.joint_fit); with
    the significant digits its printed equations need."""
    flipped = mirror_inputs(evolution, dataset)
    if evolution.symmetric_equations and flipped:
        model, report = symmetrize(model, dataset, evolution, flipped)
        model = dataclasses.replace(model, symmetrized=report)
    if any(evolution.refine_for(t) for t in model.equations):
        model, report = refine(model, dataset, evolution, flipped)
        model = dataclasses.replace(model, refined=report)
    if all(t in model.equations for t in TARGET_NAMES):
        if evolution.stability_repair or evolution.front_selection:
            repaired, report = repair_stability(model, dataset,
                                                select=evolution.front_selection,
                                                mirror=flipped)
            model = dataclasses.replace(repaired, stability=report)
        if evolution.joint_fit:
            refitted, report = joint_refit(model, dataset)
            model = dataclasses.replace(refitted, joint_fit=report)
    return with_printed_digits(model, dataset)
