"""Input levels: which of a log's signals are the model's inputs (`data.inputs`).

The paper identifies "a lumped model of the quadrotor plus the stabilisation controller" whose
inputs are the commands to the stabilisation loops; the user chooses the level. A reader
lists, for each level its log supports, the signal behind each input name:

- "rates": rate set-points (rad/s) and collective thrust: the paper's level, and the default
  wherever the log has them;
- "torque": the rate controller's torque and thrust outputs (PX4 mixer inputs);
- "sticks": the pilot's RC commands, scaled to [-1, 1] (throttle as logged);
- "motors": motor outputs (normalised) or measured motor speeds where logged.

Rates, torque and sticks give the paper's names u_P, u_R, u_Y, u_T (pitch, roll, yaw,
collective) so that equations read the same at every level; motors give motor_0 .. motor_3.
`data.inputs` may also be an explicit list of names: a name mapped under `[data.columns]` reads
that signal, a name the reader lists as a signal reads it directly, and one of the paper's
names otherwise takes the default level's signal.
"""

from __future__ import annotations

from gpquad.engine.variables import DEFAULT_INPUTS
from gpquad.errors import GpquadError

LEVELS = ("rates", "torque", "sticks", "motors")
#: Levels tried, in order, when `data.inputs` is left at the paper's default names.
DEFAULT_ORDER = ("rates", "torque", "sticks", "motors")


def paper_names(pitch: str, roll: str, yaw: str, thrust: str) -> dict[str, str]:
    """The paper's input names mapped to four signals (in DEFAULT_INPUTS order)."""
    return dict(zip(DEFAULT_INPUTS, (pitch, roll, yaw, thrust), strict=True))


def is_default(data) -> bool:
    """True when `data.inputs` is the paper's default names with no column map for them."""
    return (
        isinstance(data.inputs, tuple)
        and tuple(data.inputs) == DEFAULT_INPUTS
        and not any(n in data.columns for n in DEFAULT_INPUTS)
    )


def default_level(levels: dict[str, dict[str, str]]) -> str | None:
    return next((lv for lv in DEFAULT_ORDER if lv in levels), None)


def resolve_inputs(
    data, levels: dict[str, dict[str, str]], available, source: str
) -> tuple[dict[str, str], str]:
    """Input name -> signal column, and a label of the choice ("rates", "explicit", ...).

    levels: what the reader supports, level -> {input name: column}; available: every column
    of the log's table. Unknown levels and names are one-line errors naming data.inputs or
    data.columns.<name> and listing what is available.
    """
    available = set(available) - {"t"}
    supported = [lv for lv in LEVELS if lv in levels]
    choice = data.inputs
    if is_default(data):
        choice = default_level(levels) or choice
    if isinstance(choice, str):
        if choice not in LEVELS:
            raise GpquadError(
                f"unknown input level '{choice}'; choose one of {list(LEVELS)} "
                "or list signal names",
                source=source,
                field="data.inputs",
            )
        if choice not in levels:
            raise GpquadError(
                f"this log has no signals for input level '{choice}' (it supports "
                f"{supported}); choose another level or list signal names from "
                f"{sorted(available)}",
                source=source,
                field="data.inputs",
            )
        return dict(levels[choice]), choice
    fallback = levels.get(default_level(levels) or "", {})
    out = {}
    for name in choice:
        col = data.columns.get(name)
        if col is None:
            col = name if name in available else fallback.get(name)
        if col is None:
            raise GpquadError(
                f"no signal for input '{name}'; use a signal name, an input level "
                f'{supported}, or map it with [data.columns] {name} = "<column>" '
                f"(available: {sorted(available)})",
                source=source,
                field=f"data.columns.{name}",
            )
        if col not in available:
            raise GpquadError(
                f"input '{name}' maps to unknown signal '{col}' (available: {sorted(available)})",
                source=source,
                field=f"data.columns.{name}",
            )
        out[name] = col
    return out, "explicit"


def describe_levels(
    levels: dict[str, dict[str, str]], chosen: str, units: dict[str, str] | None = None
) -> list[str]:
    """Text lines: every supported level and what each input maps to; the chosen one marked."""
    units = units or {}
    lines = []
    for lv in LEVELS:
        if lv not in levels:
            lines.append(f"    {lv:<7} not in this log")
            continue
        pairs = ", ".join(f"{n} = {c}{units.get(c, '')}" for n, c in levels[lv].items())
        mark = "  <- used" if lv == chosen else ""
        lines.append(f"    {lv:<7} {pairs}{mark}")
    return lines


def check_input_rates(
    info: list[dict], inputs: dict[str, str], stream_columns: dict, min_hz: float = 25.0
) -> list[str]:
    """Notes for input streams logged below `min_hz` (too slow to identify delays)."""
    notes = []
    for row in info:
        cols = stream_columns.get(row["stream"], ())
        used = sorted(n for n, c in inputs.items() if c in cols)
        if used and row["rate_hz"] < min_hz:
            notes.append(
                f"inputs {', '.join(used)} come from '{row['stream']}' logged at "
                f"{row['rate_hz']:.1f} Hz, below {min_hz:g} Hz: too slow to identify "
                "input delays of one 25 Hz step"
            )
    return notes
