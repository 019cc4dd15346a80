"""Where a model was trained: the range of every state and input over its training samples,
and how much of other data lies outside it (`gpquad score` reports it).

Equations are fitted where the training flights went; outside that range nothing in the
data constrained them (a product such as r w can change the sign of a damping there).
Scoring cannot say the model is wrong there, but it can say that it is extrapolating. A
range is a coarse envelope: an a_z fitted to a px4-s250 log (a_z = 12.91 r w -
3.586 w, damping w only for r < 0.28 rad/s) diverged where r stayed positive for long,
rare in training (2.3 % of its samples) but inside its range.
"""

from __future__ import annotations

import numpy as np

from gpquad.engine.variables import STATE_NAMES

#: Signals with more than this fraction of the scored samples outside the training range
#: are reported.
REPORT_FRACTION = 0.01


def training_envelope(dataset) -> dict[str, list[float]]:
    """{name: [min, max]} of every state and (trimmed) input over the training ranges."""
    rows = np.concatenate([np.arange(a, b) for a, b in dataset.train] or [np.zeros(0, int)])
    if rows.size == 0:
        return {}
    values = np.column_stack([dataset.arrays.states[rows], dataset.arrays.inputs[rows]])
    names = list(STATE_NAMES) + list(dataset.input_names)
    return {
        n: [float(np.nanmin(values[:, k])), float(np.nanmax(values[:, k]))]
        for k, n in enumerate(names)
        if np.isfinite(values[:, k]).any()
    }


def outside_envelope(envelope: dict, dataset, rows) -> list[dict]:
    """Signals of `dataset` (states, inputs as the model sees them) whose values at `rows`
    leave the envelope on more than REPORT_FRACTION of them: name, fraction, the training
    range and the range seen, largest fraction first."""
    rows = np.asarray(rows, dtype=np.int64)
    columns = {n: dataset.arrays.states[rows, k] for k, n in enumerate(STATE_NAMES)}
    columns.update({n: dataset.arrays.inputs[rows, k] for k, n in enumerate(dataset.input_names)})
    out = []
    for name, (lo, hi) in envelope.items():
        values = columns.get(name)
        if values is None or values.size == 0:
            continue
        fraction = float(np.mean((values < lo) | (values > hi)))
        if fraction > REPORT_FRACTION:
            out.append(
                {
                    "signal": name,
                    "fraction": fraction,
                    "training": [lo, hi],
                    "seen": [float(values.min()), float(values.max())],
                }
            )
    return sorted(out, key=lambda d: -d["fraction"])
