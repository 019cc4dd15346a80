"""Which variables an equation may read: the leaves of the search.

Every input and every state that the data measures, less the names the config excludes
(`evolution.exclude_leaves`). With `evolution.keep_tracked`, an excluded state stays allowed
when an input tracks it: the input is then the state's set-point and the dynamics depend
on the state relative to it. Example: psi is excluded by recommended.toml (body-frame
dynamics do not depend on the heading, and a model fitted to one flight's headings does not
carry over), but under angle-mode inputs the yaw loop is r_dot = k (u_Y - psi) - c r.

"Tracks" is measured on the training data: the input explains at least TRACK_EXPLAINED of
the state's variance as it is (var(state - input) <= (1 - TRACK_EXPLAINED) var(state), same
units, no fitted gain) and their correlation is at least TRACK_CORRELATION. Measured on the
benchmark's data: psi vs the heading set-point u_Y of rotorpy's angle mode 0.46 / 0.79
explained, correlation 0.79 / 0.90 (crazyflie / hummingbird); at rate level (rotorpy, PX4
S250 and AquaQuad logs, the reference simulators) psi against any input <= 0.19 explained,
correlation <= 0.45.
"""

from __future__ import annotations

import numpy as np

from gpquad.engine.taps import base_input
from gpquad.engine.variables import STATE_NAMES

TRACK_EXPLAINED = 0.3
TRACK_CORRELATION = 0.6


def tracked_states(dataset, names) -> dict[str, str]:
    """State name -> the input that tracks it, for the states among `names`."""
    rows = (
        np.concatenate([np.arange(a, b) for a, b in dataset.train])
        if dataset.train
        else np.zeros(0, dtype=np.int64)
    )
    out = {}
    if len(rows) < 3:
        return out
    states, inputs = dataset.arrays.states[rows], dataset.arrays.inputs[rows]
    for name in names:
        if name not in STATE_NAMES:
            continue
        x = states[:, STATE_NAMES.index(name)]
        if not np.var(x) > 0:
            continue
        for j, input_name in enumerate(dataset.input_names):
            u = inputs[:, j]
            if not np.var(u) > 0:
                continue
            explained = 1.0 - np.var(x - u) / np.var(x)
            if explained >= TRACK_EXPLAINED and np.corrcoef(x, u)[0, 1] >= TRACK_CORRELATION:
                out[name] = input_name
                break
    return out


def measured_variables(dataset, exclude=(), keep_tracked: bool = False) -> tuple[int, ...] | None:
    """Leaf variables a model may read: every input and every state the data measures, less
    the names in `exclude` (those an input tracks stay, with keep_tracked); None: all. A log
    without, say, horizontal velocity keeps u and v out of its equations."""
    names = list(STATE_NAMES) + list(dataset.input_names)
    if keep_tracked:
        exclude = [n for n in exclude if n not in tracked_states(dataset, exclude)]
    left_out = [
        i
        for i, name in enumerate(names)
        if base_input(name) in exclude
        or (name in ("u", "v", "w", "p", "q", "r") and dataset.unmeasured(name))
    ]
    if not left_out:
        return None
    if len(left_out) == len(names):
        from gpquad.errors import GpquadError

        raise GpquadError(
            f"every variable {names} is excluded or unmeasured: an equation "
            "needs at least one to read; shorten exclude_leaves",
            field="evolution.exclude_leaves",
        )
    return tuple(i for i in range(len(names)) if i not in left_out)
