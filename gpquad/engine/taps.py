"""Input taps: an equation may read one input at several delays (`evolution.input_taps`).

The paper gives each input one evolvable delay per equation. A vehicle whose moments lag
its commands (a motor time constant of two samples, a filtered log) is a low-order filter
of the input history, which one delayed sample cannot express but a few can:
p_dot = 110 u_R(t-1) - 70 u_R(t-3) - 40 p. With K taps every input appears K times among
the leaves, each copy ("tap") with its own evolvable delay. The search's kernels see K
copies of the input columns (`with_taps`, once per run); the rollout and PID kernels read
leaf slot j from input column j % n_inputs. Tap 0 keeps the input's own
name; tap k >= 1 is named `<input>__tap<k>` inside the engine and in model.json's
"delays", and is written `<input>(t-d)` in every equation text, like tap 0.
"""

from __future__ import annotations

import dataclasses
import re

import numpy as np

from gpquad.engine.tree.encoding import Tree
from gpquad.engine.tree.operators import VAR_BASE
from gpquad.engine.variables import N_STATE

#: Taps an equation may have per input (config bound).
MAX_TAPS = 6
_TAP = "__tap"
_TAP_RE = re.compile(r"^(.*)__tap(\d+)$")


def tap_name(name: str, k: int) -> str:
    """The leaf name of tap k of input `name` (tap 0 is the input itself)."""
    return name if k == 0 else f"{name}{_TAP}{k}"


def tap_names(input_names, taps: int) -> tuple[str, ...]:
    """Leaf names of `taps` taps of every input: all inputs' tap 0, then tap 1, ..."""
    return tuple(tap_name(n, k) for k in range(taps) for n in input_names)


def base_input(name: str) -> str:
    """The input a tap reads: u_R__tap2 -> u_R (other names unchanged)."""
    m = _TAP_RE.match(name)
    return m.group(1) if m else name


def tap_index(name: str) -> int:
    """k of a tap name (0 for a plain name)."""
    m = _TAP_RE.match(name)
    return int(m.group(2)) if m else 0


def taps_of(n_delays: int, n_inputs: int) -> int:
    """Taps of a tree with `n_delays` delay slots over `n_inputs` inputs."""
    return max(1, n_delays // n_inputs) if n_inputs else 1


def tile_inputs(inputs: np.ndarray, taps: int) -> np.ndarray:
    """(N, taps * n_inputs): the input columns repeated, one block per tap."""
    if taps == 1:
        return inputs
    return np.ascontiguousarray(np.tile(inputs, (1, taps)))


def with_taps(dataset, taps: int):
    """The dataset as the engine's kernels see it: inputs tiled, tap names."""
    if taps == 1:
        return dataset
    arrays = dataset.arrays._replace(inputs=tile_inputs(dataset.arrays.inputs, taps))
    trim = {tap_name(n, k): v for k in range(taps) for n, v in dataset.trim.items()}
    return dataclasses.replace(
        dataset, arrays=arrays, input_names=tap_names(dataset.input_names, taps), trim=trim
    )


def initial_delays(n_inputs: int, taps: int, max_delay: int) -> np.ndarray:
    """Delays of a fresh tree: tap k of every input at delay min(k, max_delay), so that
    the taps start as distinct samples of the input history; evolution moves them."""
    return np.minimum(np.repeat(np.arange(taps, dtype=np.int64), n_inputs), max_delay)


def canonical_taps(tree, n_inputs: int):
    """The same equation with its taps renumbered: for each input, the taps the tree reads
    come first, in ascending delay (tap 0 = the smallest delay), then the unread ones.

    Evolution may leave an equation reading only tap 2 of u_Y; renumbered, it reads u_Y
    itself, so a one-delay equation has the paper's layout whatever the taps, and two
    equations with the same terms have the same tree slots. Exact (a relabelling)."""
    n_slots = len(tree.delays)
    taps = taps_of(n_slots, n_inputs)
    if taps == 1:
        return tree
    codes = np.asarray(tree.codes)
    used = {int(c) - VAR_BASE - N_STATE for c in codes if c >= VAR_BASE + N_STATE}
    new_slot = np.arange(n_slots)
    for j in range(n_inputs):
        slots = [k * n_inputs + j for k in range(taps)]
        order = sorted(slots, key=lambda s: (s not in used, tree.delays[s] if s in used else 0, s))
        for k, s in enumerate(order):
            new_slot[s] = k * n_inputs + j
    if np.array_equal(new_slot, np.arange(n_slots)):
        return tree
    new_codes = codes.copy()
    leaf = codes >= VAR_BASE + N_STATE
    new_codes[leaf] = VAR_BASE + N_STATE + new_slot[codes[leaf] - VAR_BASE - N_STATE]
    delays = np.empty(n_slots, dtype=np.int64)
    delays[new_slot] = tree.delays
    return Tree(new_codes, tree.values, delays)
