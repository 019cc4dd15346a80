"""Models to score beside a discovered one, flown the same way: the zero model (every
acceleration zero) and, for rate set-point inputs, the set-point model (each body rate
equals its set-point one sample later). A score means little without them: on rate
set-point inputs the set-point model alone often looks excellent."""

from __future__ import annotations

import numpy as np

from gpquad.engine.tree.encoding import Tree
from gpquad.engine.tree.operators import CONST, MUL, SUB, VAR_BASE
from gpquad.engine.variables import STATE_NAMES, TARGET_NAMES
from gpquad.models.equations import DiscoveredModel, Equation

#: Rate equation -> (its rate, the set-point input of the paper's names).
SETPOINTS = {"p_dot": ("p", "u_R"), "q_dot": ("q", "u_P"), "r_dot": ("r", "u_Y")}


def zero_model(input_names, dt: float) -> DiscoveredModel:
    """Every acceleration zero: states hold their initial values (angles follow rates)."""
    zero = Tree.from_lists([CONST], [0.0], np.zeros(len(input_names), dtype=np.int64))
    eqs = {t: Equation(t, zero, tuple(input_names), np.nan, np.nan) for t in TARGET_NAMES}
    return DiscoveredModel(eqs, tuple(input_names), {}, float(dt), 0, {})


def setpoint_model(input_names, dt: float) -> DiscoveredModel | None:
    """p, q, r reach their set-points u_R, u_P, u_Y in one step (rate_dot = (u - rate) / dt),
    the other accelerations zero; None when the inputs are not named so."""
    names = tuple(input_names)
    if not all(u in names for _, u in SETPOINTS.values()):
        return None
    model = zero_model(names, dt)
    n_state = len(STATE_NAMES)
    for target, (rate, setpoint) in SETPOINTS.items():
        codes = [
            MUL,
            CONST,
            SUB,
            VAR_BASE + n_state + names.index(setpoint),
            VAR_BASE + STATE_NAMES.index(rate),
        ]
        values = [0.0, 1.0 / dt, 0.0, 0.0, 0.0]
        tree = Tree.from_lists(codes, values, np.zeros(len(names), dtype=np.int64))
        model.equations[target] = Equation(target, tree, names, np.nan, np.nan)
    return model


def is_rate_level(flight_info: list[dict]) -> bool:
    """Whether the data's inputs are rate set-points (the log pipeline's input level)."""
    return {info.get("input_level") for info in flight_info} == {"rates"}


def reference_models(input_names, dt: float, flight_info: list[dict]) -> dict:
    """{name: model} to score beside a discovered one: "zero", and "set-point" where the
    inputs are rate set-points named for it."""
    out = {"zero": zero_model(input_names, dt)}
    setpoint = setpoint_model(input_names, dt)
    if setpoint is not None and is_rate_level(flight_info):
        out["set-point"] = setpoint
    return out
