"""Loop gains that identified roll and pitch equations imply, against rotorpy's controller.

On the rotorpy angle-mode flights (gpquad.benchmark.rotorpy_flights) the vehicle's own
attitude law is known. rotorpy's `cmd_ctatt` commands the moment

    M = I (-kp_att e - kd_att w) + w x I w,   e = vee(0.5 (R_des^T R - R^T R_des)),

so the inertia cancels: the commanded angular acceleration is w_dot = -kp_att e - kd_att w,
in rad/s^2 per rad and per rad/s, whatever the vehicle's inertia. For small angles e is the
attitude minus the set-point, and the frame flip to NED/FRD (q -> -q, theta -> -theta, the
pitch set-point likewise) keeps the signs, so in the log's variables

    p_dot = -kd_att p - kp_att phi + kp_att u_R,   q_dot = -kd_att q - kp_att theta + kp_att u_P,

reached through the motors' first-order lag tau_m. The inputs are the set-point angles in
rad (rotorpy_flights.to_ned_frame) and the data's trim is "none", so no input scale enters.

The gains an equation implies are defined by linearisation at hover: every state 0, the
attitude set-points 0 and u_T = 1 (the thrust set-point is thrust / weight). For the roll
equation: rate gain = -d f / d p, angle gain = -d f / d phi, set-point gain = the sum of
d f / d u_R over every delay at which the equation reads u_R (its taps; a peer's lagged
features u_R_l0 .. u_R_l5); pitch likewise with q, theta, u_P. A printed first-order lag
(tau d(p_dot)/dt + p_dot = f) does not change them and is shown beside them. The JSON also
holds each tap's gain and their gain-weighted mean delay (samples), which means little when
the taps alternate in sign. Each gain's error is relative
to the controller's (kd_att, kp_att, kp_att).
"""

from __future__ import annotations

import sympy as sp

from gpquad.benchmark.fidelity import parse_line
from gpquad.engine.taps import base_input
from gpquad.engine.tree.arithmetic import parse_in_symbols
from gpquad.engine.tree.export import parse_equation

#: The loops compared: equation -> (rate, angle, set-point input).
LOOPS = {"p_dot": ("p", "phi", "u_R"), "q_dot": ("q", "theta", "u_P")}
#: The operating point of the linearisation (raw inputs; every state is 0).
HOVER_INPUTS = {"u_T": 1.0}


def _linearise(expr: sp.Expr, inputs_of: dict, loop: tuple[str, str, str]) -> dict:
    """Rate, angle and set-point gains of f at hover; inputs_of: symbol -> (input, delay)."""
    rate, angle, setpoint = loop
    point = {s: 0.0 for s in expr.free_symbols}
    for s, (name, _) in inputs_of.items():
        if s in point:
            point[s] = HOVER_INPUTS.get(name, 0.0)

    def partial(symbol) -> float:
        return float(sp.diff(expr, symbol).subs(point)) if symbol in expr.free_symbols else 0.0

    by_name = {str(s): s for s in expr.free_symbols}
    taps: dict[int, float] = {}
    for s, (name, delay) in inputs_of.items():
        if name == setpoint and s in expr.free_symbols:
            taps[delay] = taps.get(delay, 0.0) + partial(s)
    total = sum(taps.values())
    return {
        "rate": -partial(by_name[rate]) if rate in by_name else 0.0,
        "angle": -partial(by_name[angle]) if angle in by_name else 0.0,
        "setpoint": total,
        "setpoint_taps": {str(d): g for d, g in sorted(taps.items())},
        "setpoint_delay_samples": (
            sum(d * g for d, g in taps.items()) / total if taps and total != 0.0 else None
        ),
    }


def implied_gains(method: str, line: str, target: str, input_names) -> dict:
    """The gains (module notes) of one printed equation: gpquad's line 'p_dot = ...' in raw
    inputs, or a peer's expression in the lagged features; "lag_s" is the printed lag."""
    loop = LOOPS[target]
    if method == "gpquad":
        rhs, lag = parse_line(line, target)
        expr, delays = parse_equation(rhs, tuple(input_names), source=target)
        inputs_of = {
            s: (base_input(str(s)), delays.get(str(s), 0))
            for s in expr.free_symbols
            if base_input(str(s)) in input_names
        }
    else:
        lag = 0.0
        expr = parse_in_symbols(line, None, caret_power=True, field=target)
        inputs_of = {}
        for s in expr.free_symbols:
            name, _, k = str(s).rpartition("_l")
            if name in input_names and k.isdigit():
                inputs_of[s] = (name, int(k))
    return {**_linearise(expr, inputs_of, loop), "lag_s": lag}


def controller_gains(vehicle: str) -> dict:
    """rotorpy's attitude gains of a vehicle: rate kd_att, angle and set-point kp_att
    (rad/s^2 per rad/s and per rad) and its motor time constant (s)."""
    from gpquad.benchmark.rotorpy_flights import vehicle_params
    from gpquad.benchmark.rotorpy_model import DEFAULT_KD_ATT, DEFAULT_KP_ATT

    params, _ = vehicle_params(vehicle)
    kp = float(params.get("kp_att", DEFAULT_KP_ATT))
    kd = float(params.get("kd_att", DEFAULT_KD_ATT))
    return {"rate": kd, "angle": kp, "setpoint": kp, "motor_tau_s": float(params["tau_m"])}


def cell_gains(cell: dict, vehicles, input_names) -> dict:
    """{vehicle: {target: implied gains with "error" (relative, per gain)}} of one cell
    fitted per vehicle."""
    out: dict = {}
    texts = cell.get("equations_raw_inputs") or cell["equations"]
    for vehicle in vehicles:
        truth = controller_gains(vehicle)
        out[vehicle] = {}
        for target in LOOPS:
            gains = implied_gains(cell["method"], texts[vehicle][target], target, input_names)
            gains["error"] = {
                k: (gains[k] - truth[k]) / truth[k] for k in ("rate", "angle", "setpoint")
            }
            out[vehicle][target] = gains
    return out


def applies(source: dict) -> bool:
    """Whether a scenario is rotorpy angle mode with untrimmed inputs (module notes)."""
    return (
        isinstance(source, dict)
        and source.get("kind") == "rotorpy"
        and source.get("mode") == "angle"
        and (source.get("config") or {}).get("trim", "none") == "none"
    )


def benchmark_gains(info: dict, cells: list[dict]) -> dict:
    """{scenario: {"controller": {vehicle: gains}, "cells": [{method, seed, gains}]}} of the
    rotorpy angle-mode scenarios of a benchmark (benchmark.json's `info`); zero is left out
    (it implies no loop), and so is every scenario when rotorpy is not installed."""
    from gpquad.benchmark.rotorpy_flights import INPUT_NAMES

    out: dict = {}
    for name, source in info.get("scenarios", {}).items():
        if not applies(source):
            continue
        vehicles = source.get("vehicles") or []
        try:
            controller = {v: controller_gains(v) for v in vehicles}
        except ImportError:  # rotorpy's parameter files are not installed here
            continue
        rows = [
            {
                "method": c["method"],
                "seed": c["seed"],
                "gains": cell_gains(c, vehicles, INPUT_NAMES),
            }
            for c in cells
            if c["scenario"] == name and c["method"] != "zero"
        ]
        out[name] = {"controller": controller, "cells": rows}
    return out


def markdown(gains: dict) -> str:
    """Per scenario: one row per method, seed, vehicle and loop: the implied rate, angle
    and set-point gains (relative error) beside the controller's, and the printed lag
    beside the motor's (the set-point's taps and mean delay are in the JSON only: taps of
    alternating sign, as a fitted input filter has, make a mean delay meaningless)."""
    head = [
        "method",
        "seed",
        "vehicle",
        "loop",
        "rate gain (kd_att)",
        "angle gain (kp_att)",
        "set-point gain (kp_att)",
        "lag s (motor tau_m)",
        "worst error",
    ]
    lines = []
    for scenario, s in gains.items():
        lines += [f"### {scenario}", "", "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        for row in s["cells"]:
            for vehicle, loops in row["gains"].items():
                truth = s["controller"][vehicle]
                for target, g in loops.items():
                    err = g["error"]
                    cells = [row["method"], str(row["seed"]), vehicle, target]
                    cells += [
                        f"{g[k]:.4g} ({truth[k]:.4g}, {100 * err[k]:+.0f} %)"
                        for k in ("rate", "angle", "setpoint")
                    ]
                    cells += [
                        f"{g['lag_s']:.3g} ({truth['motor_tau_s']:.3g})",
                        f"{100 * max(abs(e) for e in err.values()):.0f} %",
                    ]
                    lines.append("| " + " | ".join(cells) + " |")
        lines.append("")
    return "\n".join(lines)
