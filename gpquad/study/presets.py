"""Named engine presets: TOML tables laid under a config's own (`preset = "paper"`).

The defaults of gpquad.study.config are the recommended engine, so "recommended" is empty.
"paper" is De Nardi and Holland's method as section 2.2 and 3.2 describe it (eq. 2, one
explicit step per sample)
(../shared/seeds/coevolutionary-gp-rotorcraft.txt): mutation-only hill climbers, one delay
per input, 30 s windows, no local search and no finishing steps.
"""

from __future__ import annotations

import copy

from gpquad.errors import GpquadError

PRESETS: dict[str, dict] = {
    "recommended": {},
    "paper": {
        "data": {"trim": "mean"},
        "vehicle": {"symmetric": False},
        "evolution": {
            "iterations": 30,
            "stall_iterations": 0,
            "window_s": 30.0,
            "max_depth": 5,
            "max_degree": 0,
            "input_taps": 1,
            "simplify_tolerance": 0.0,
            "constant_fit": "none",
            "selection": "prune",
            "prune_tolerance": 0.0,
            "linear_seed": False,
            "term_search": False,
            "exclude_leaves": [],
            "keep_tracked": False,
            "finish": [],
            "refine_terms": 0,
            "integrator": "euler",
        },
        # the paper's median model (Table 1) is a discrete-time model: eq. 2 defines it
        "simulator": {"integrator": "euler"},
    },
}


def _merged(base: dict, top: dict) -> dict:
    """`top` laid over `base`, table by table (a key of `top` wins)."""
    out = copy.deepcopy(base)
    for key, value in top.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = _merged(out[key], value)
        else:
            out[key] = value
    return out


def with_preset(table: dict, source: str) -> dict:
    """The config table with its `preset` (default "recommended") laid underneath."""
    name = table.get("preset", "recommended")
    if name not in PRESETS:
        raise GpquadError(
            f"unknown preset '{name}'; choose one of {sorted(PRESETS)}",
            source=source,
            field="preset",
        )
    return _merged(PRESETS[name], table)
