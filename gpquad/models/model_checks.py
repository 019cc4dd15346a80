"""Checks of a model record read from a file (model.json, a finished target's record, a
sweep's result.json): every field a hand edit or a damaged file can make unusable is
refused with one GpquadError naming the field, before anything is flown or printed.

Expressions in the record (`expr`, `candidates[].expr`) are read with the equations' own
parser (gpquad.engine.tree.arithmetic), never evaluated as Python.
"""

from __future__ import annotations

import math
import re
from contextlib import contextmanager

import numpy as np
import sympy as sp

from gpquad.engine.taps import MAX_TAPS, base_input, tap_index, tap_names
from gpquad.engine.tree.arithmetic import parse_in_symbols
from gpquad.engine.tree.encoding import Tree, is_valid, tree_depth
from gpquad.engine.tree.export import from_sympy, to_sympy
from gpquad.engine.tree.operators import VAR_BASE
from gpquad.engine.variables import STATE_NAMES, TARGET_NAMES, terminal_names
from gpquad.errors import GpquadError

#: Largest input delay (samples) a model record may hold.
MAX_MODEL_DELAY = 10_000
#: Largest tree (nodes) and depth a model record may hold.
MAX_MODEL_NODES = 4095
MAX_MODEL_DEPTH = 64
#: Largest |constant| of a model record's tree.
MAX_CONSTANT = 1e15
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
FIX = "restore the file gpquad wrote"


def fail(message: str, field: str):
    raise GpquadError(f"{message}; {FIX}", field=field)


def checked_input_names(names) -> tuple[str, ...]:
    """The model's input names: a non-empty list of distinct names that are not states."""
    if not isinstance(names, list) or not names:
        fail("the model needs a list of one or more input names", "input_names")
    for i, name in enumerate(names):
        if not isinstance(name, str) or not _NAME.fullmatch(name) or "__tap" in name:
            fail(f"{name!r} is not an input name (letters, digits and _)", f"input_names[{i}]")
        if name in STATE_NAMES:
            fail(f"{name!r} is a state, not an input", f"input_names[{i}]")
    if len(set(names)) != len(names):
        fail("an input is named twice", "input_names")
    return tuple(names)


def checked_targets(targets) -> dict:
    """The targets table: an object keyed by target names (empty for a run interrupted
    before its first equation)."""
    if not isinstance(targets, dict):
        fail("the model needs an object {target: equation}", "targets")
    unknown = [t for t in targets if t not in TARGET_NAMES]
    if unknown:
        fail(
            f"unknown target {unknown[0]!r}; the targets are {list(TARGET_NAMES)}",
            f"targets.{unknown[0]}",
        )
    for t, e in targets.items():
        if not isinstance(e, dict):
            fail("an equation is an object", f"targets.{t}")
    return targets


def checked_number(value, field: str, *, positive: bool = False) -> float:
    if (
        isinstance(value, bool)
        or not isinstance(value, (int, float))
        or not math.isfinite(value)
        or (positive and value <= 0)
    ):
        fail(f"{value!r} is not a {'positive ' if positive else ''}finite number", field)
    return float(value)


def checked_trim(trim, input_names) -> dict:
    if not isinstance(trim, dict):
        fail("the trim is an object {input: value}", "trim")
    for name, value in trim.items():
        if name not in input_names:
            fail(f"trim of {name!r}, which is not an input {list(input_names)}", f"trim.{name}")
        checked_number(value, f"trim.{name}")
    return trim


def checked_delays(delays, input_names, field: str) -> dict[str, int]:
    """{leaf name: delay}: inputs or their taps, whole numbers 0..MAX_MODEL_DELAY."""
    if not isinstance(delays, dict):
        fail("the delays are an object {input: samples}", field)
    for name, d in delays.items():
        if base_input(name) not in input_names or tap_index(name) >= MAX_TAPS:
            fail(f"delay of {name!r}, which is not an input {list(input_names)}", f"{field}.{name}")
        if isinstance(d, bool) or not isinstance(d, int) or not 0 <= d <= MAX_MODEL_DELAY:
            fail(
                f"a delay is a whole number of samples from 0 to {MAX_MODEL_DELAY}, not {d!r}",
                f"{field}.{name}",
            )
    return delays


def checked_tree(target: str, record: dict, input_names) -> Tree:
    """The record's prefix tree, checked: codes of this model's leaves, one complete tree,
    finite constants, a delay per leaf slot."""
    field = f"targets.{target}"
    delays = checked_delays(record.get("delays", {}), input_names, f"{field}.delays")
    prefix = record.get("prefix")
    if (
        not isinstance(prefix, dict)
        or not isinstance(prefix.get("codes"), list)
        or not isinstance(prefix.get("values"), list)
    ):
        fail("the equation needs its prefix tree {codes: [...], values: [...]}", f"{field}.prefix")
    codes, values = prefix["codes"], prefix["values"]  # type: ignore[index]
    taps = 1 + max((tap_index(n) for n in delays), default=0)
    leaves = len(terminal_names(tap_names(input_names, taps)))
    if not codes or len(codes) > MAX_MODEL_NODES:
        fail(f"a tree has 1 to {MAX_MODEL_NODES} nodes, not {len(codes)}", f"{field}.prefix")
    if len(values) != len(codes):
        fail(f"{len(codes)} codes but {len(values)} values", f"{field}.prefix.values")
    for i, c in enumerate(codes):
        if isinstance(c, bool) or not isinstance(c, int) or not 0 <= c < VAR_BASE + leaves:
            fail(
                f"code {c!r} is not an operator, a constant or one of the model's "
                f"{leaves} variables",
                f"{field}.prefix.codes[{i}]",
            )
    if not is_valid(codes):
        fail("the codes are not one complete prefix tree", f"{field}.prefix.codes")
    if tree_depth(codes) > MAX_MODEL_DEPTH:
        fail(f"the tree is deeper than {MAX_MODEL_DEPTH}", f"{field}.prefix.codes")
    for i, v in enumerate(values):
        if (
            isinstance(v, bool)
            or not isinstance(v, (int, float))
            or not math.isfinite(v)
            or abs(v) > MAX_CONSTANT
        ):
            fail(
                f"constant {v!r} is not a finite number of at most {MAX_CONSTANT:g}",
                f"{field}.prefix.values[{i}]",
            )
    slots = [int(delays.get(n, 0)) for n in tap_names(input_names, taps)]
    return Tree.from_lists(codes, values, slots)


def _leaf_symbols(input_names) -> dict[str, sp.Symbol]:
    names = list(STATE_NAMES) + list(tap_names(input_names, MAX_TAPS))
    return {n: sp.Symbol(n, real=True) for n in names}


def parse_candidate(target: str, i: int, candidate, input_names) -> tuple[Tree, dict]:
    """(tree, delays) of one front candidate {expr, delays, ...} of a model record."""
    field = f"targets.{target}.candidates[{i}]"
    if not isinstance(candidate, dict) or not isinstance(candidate.get("expr"), str):
        fail("a candidate is an object with its expr", field)
    delays = checked_delays(candidate.get("delays", {}), input_names, f"{field}.delays")
    expr = parse_in_symbols(candidate["expr"], _leaf_symbols(input_names), field=f"{field}.expr")
    return from_sympy(expr, delays, input_names), delays


def check_expr_agrees(target: str, text, tree: Tree, leaf_names, delays: dict) -> None:
    """Refuse an `expr` that is not the equation its prefix encodes (the prefix is what
    flies): both are evaluated at three points drawn from a fixed generator."""
    field = f"targets.{target}.expr"
    if not isinstance(text, str):
        fail("expr is the equation's text", field)
    symbols = {n: sp.Symbol(n, real=True) for n in list(STATE_NAMES) + list(leaf_names)}
    written = parse_in_symbols(text, symbols, field=field)
    encoded = to_sympy(tree, leaf_names)
    rng = np.random.default_rng(0)
    for _ in range(3):
        point = {n: float(v) for n, v in zip(STATE_NAMES, rng.uniform(0.5, 1.5, 9))}
        by_delay: dict[tuple[str, int], float] = {}
        for n in leaf_names:
            key = (base_input(n), delays.get(n, 0))
            point[n] = by_delay.setdefault(key, float(rng.uniform(0.5, 1.5)))
        values = [
            float(
                e.xreplace({sp.Symbol(n, real=True): sp.Float(v) for n, v in point.items()}).evalf()
            )
            for e in (written, encoded)
        ]
        a, b = values
        if not (math.isfinite(a) and math.isfinite(b)):
            continue
        if abs(a - b) > 1e-6 * max(1.0, abs(a), abs(b)):
            fail(
                f"expr '{text[:60]}' is not the equation its prefix encodes ({a:.6g} "
                f"against {b:.6g} at a test point); the prefix is what flies",
                field,
            )


@contextmanager
def naming(path):
    """Errors of reading the record in `path` (a GpquadError of a checked field, or a
    malformed record's KeyError, TypeError, ValueError) as one GpquadError naming the file."""
    try:
        yield
    except GpquadError as exc:
        if exc.source:
            raise
        raise GpquadError(str(exc), source=str(path)) from None
    except (KeyError, TypeError, ValueError, IndexError, AttributeError) as exc:
        raise GpquadError(
            f"damaged record (bad or missing entry {exc}); {FIX}", source=str(path)
        ) from None


__all__ = [
    "naming",
    "checked_input_names",
    "checked_targets",
    "checked_trim",
    "checked_number",
    "checked_tree",
    "parse_candidate",
    "check_expr_agrees",
]
