"""Configs written for older versions of gpquad: renamed keys are moved with a one-line
note, removed ones are dropped with a note when they asked for what gpquad now does anyway,
and refused with one line saying what to write otherwise."""

from __future__ import annotations

import copy

from gpquad.errors import GpquadError

#: evolution.<old> -> evolution.gp.<same>: the paper's variation probabilities.
MOVED_TO_GP = (
    "p_leaf",
    "p_constant_leaf",
    "const_low",
    "const_high",
    "const_variance",
    "p_const_perturb",
    "p_delay",
)
#: evolution.<old> -> evolution.<new>.
RENAMED = {"final_selection": "selection", "local_search_evals": "nelder_mead_evals"}
#: Options measured and not adopted (docs/decisions): their value that changes nothing.
REMOVED = {
    "front_selection": False,
    "attitude_weight": 0.0,
    "angle_tangents": False,
    "fit_horizons": [],
}
#: The finishing steps that were switches, in their place in evolution.finish.
FINISH_SWITCHES = {
    "symmetric_equations": "symmetrize",
    "stability_repair": "repair",
    "joint_fit": "joint_fit",
}


def migrate(table: dict, source: str, dt: float | None = None) -> tuple[dict, list[str]]:
    """(the table in today's keys, notes). `dt`: the data's sample period when known (a run
    folder's config), to convert a window in steps to seconds."""
    ev = table.get("evolution")
    if not isinstance(ev, dict):
        return table, []
    table = copy.deepcopy(table)
    ev = table["evolution"]
    notes: list[str] = []

    def note(text: str) -> None:
        notes.append(f"{source}: {text}")

    def refuse(key: str, text: str) -> GpquadError:
        return GpquadError(text, source=source, field=f"evolution.{key}")

    if "window_steps" in ev:
        steps = ev.pop("window_steps")
        if dt is None:
            raise refuse(
                "window_steps",
                f"the window is now in seconds: write window_s = "
                f"{steps} x the sample period (at 25 Hz: window_s = {steps * 0.04:g})",
            )
        ev.setdefault("window_s", steps * dt)
        note(f"evolution.window_steps = {steps} is now evolution.window_s = {steps * dt:g}")
    if "test_offset_max" in ev:
        ev.pop("test_offset_max")
        note("evolution.test_offset_max is dropped: tests move by up to half a window")
    for key in MOVED_TO_GP:
        if key in ev:
            ev.setdefault("gp", {})[key] = ev.pop(key)
            note(f"evolution.{key} is now evolution.gp.{key}")
    for old, new in RENAMED.items():
        if old in ev:
            ev[new] = ev.pop(old)
            note(f"evolution.{old} is now evolution.{new}")
    _migrate_constant_fit(ev, note, refuse)
    for key, inert in REMOVED.items():
        if key in ev:
            value = ev.pop(key)
            if value != inert and not (isinstance(inert, list) and list(value) == inert):
                raise refuse(
                    key,
                    "was measured and not adopted (docs/decisions), and is removed; delete the key",
                )
            note(f"evolution.{key} is removed (it was off); delete the key")
    if any(k in ev for k in FINISH_SWITCHES):
        on = {step for key, step in FINISH_SWITCHES.items() if ev.pop(key, False)}
        if _refines(ev.get("refine_terms", 0)):
            on.add("refine")
        order = ("symmetrize", "refine", "repair", "joint_fit")
        ev["finish"] = [s for s in order if s in on]
        note(
            f"symmetric_equations, stability_repair and joint_fit are now evolution.finish = "
            f"{ev['finish']}"
        )
    if "mirror_inputs" in ev:
        flipped = ev.pop("mirror_inputs")
        vehicle = table.setdefault("vehicle", {})
        vehicle.setdefault("mirror_inputs", flipped)
        vehicle.setdefault("symmetric", bool(flipped))
        note("evolution.mirror_inputs is now vehicle.mirror_inputs")
    return table, notes


def _refines(value) -> bool:
    return any(value.values()) if isinstance(value, dict) else bool(value)


def _migrate_constant_fit(ev: dict, note, refuse) -> None:
    """local_search + constant_fit ("nelder-mead" | "gauss-newton") -> constant_fit."""
    if "local_search" not in ev and ev.get("constant_fit") not in ("gauss-newton",):
        return
    search = ev.pop("local_search", None)
    fit = ev.get("constant_fit", "nelder-mead")
    if search == "delays":
        raise refuse(
            "local_search",
            'local_search = "delays" is removed; write constant_fit = '
            '"lm" (delays and constants) or "none"',
        )
    if search == "none":
        if fit == "gauss-newton":
            raise refuse(
                "local_search",
                'local_search = "none" with constant_fit = '
                '"gauss-newton" is no longer offered; write constant_fit = "lm" '
                '(local search by LM) or "none"',
            )
        ev["constant_fit"] = "none"
    else:
        ev["constant_fit"] = "lm" if fit == "gauss-newton" else fit
    note(f'evolution.local_search and constant_fit are now constant_fit = "{ev["constant_fit"]}"')
