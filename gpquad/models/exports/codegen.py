"""The shared code generator of the exports: the prefix tree walked as the kernels walk it.

`fold` evaluates a prefix tree right to left over a stack, exactly as
gpquad.engine.kernels.tree_eval.eval_lanes does, but with caller-given functions for the
leaves, the constants and the operators; it builds source text (python, C), sympy or CasADi
expressions. Each binary node becomes one operation on its two children's values, so a
generated expression performs the kernel's floating-point operations in the kernel's
order: the python and C exports give the kernel's numbers, not only its equation.

`ModelSpec` gathers what every export needs from a DiscoveredModel: per target its tree,
its leaves (state or input column, delay in samples) and its lag factor, with dt, the
inputs, the trim and the longest delay read.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from gpquad.engine.kernels.step import lag_rate
from gpquad.engine.lag import lag_alpha
from gpquad.engine.tree.encoding import Tree
from gpquad.engine.tree.operators import ADD, CONST, DIV, DIV_EPS, MUL, SUB, VAR_BASE
from gpquad.engine.variables import N_STATE, STATE_NAMES, TARGET_NAMES, TARGET_STATE
from gpquad.errors import GpquadError

#: Operator code -> infix symbol of the generated sources (division is protected apart).
INFIX = {ADD: "+", SUB: "-", MUL: "*"}


@dataclass(frozen=True)
class Leaf:
    """A variable leaf: state `index` (0..8), or input column `index` read `delay` samples
    back (kind "input")."""

    kind: str
    index: int
    delay: int = 0


def fold(
    tree: Tree,
    n_inputs: int,
    leaf: Callable[[Leaf], object],
    const: Callable[[float], object],
    binary: Callable[[int, object, object], object],
):
    """The tree's value built bottom-up: leaf(Leaf) and const(value) for the leaves,
    binary(code, left, right) for each operator node (code ADD, SUB, MUL or DIV), visiting
    the nodes right to left as the kernels do. Input leaf slot j reads input column
    j % n_inputs at the tree's delay of slot j (gpquad.engine.taps)."""
    stack: list = []
    for i in range(tree.size - 1, -1, -1):
        code = int(tree.codes[i])
        if code >= VAR_BASE:
            k = code - VAR_BASE
            if k < N_STATE:
                stack.append(leaf(Leaf("state", k)))
            else:
                slot = k - N_STATE
                stack.append(leaf(Leaf("input", slot % n_inputs, int(tree.delays[slot]))))
        elif code == CONST:
            stack.append(const(float(tree.values[i])))
        else:
            left = stack.pop()
            right = stack.pop()
            stack.append(binary(code, left, right))
    if len(stack) != 1:
        raise ValueError("not one complete prefix tree")
    return stack[0]


def leaves(tree: Tree, n_inputs: int) -> list[Leaf]:
    """The tree's variable leaves, in prefix order (repeats kept)."""
    found: list[Leaf] = []

    def collect(leaf_: Leaf):
        found.append(leaf_)
        return None

    fold(tree, n_inputs, collect, lambda v: None, lambda c, a, b: None)
    return found[::-1]


def float_literal(value: float) -> str:
    """The shortest literal that reads back as exactly `value` (python and C99 alike)."""
    if not math.isfinite(value):
        raise GpquadError(
            f"a constant of the model is {value}; an export needs finite "
            "constants (refit or re-run the model)",
            field="prefix",
        )
    text = repr(float(value))
    return f"({text})" if text.startswith("-") else text


def source_expression(
    tree: Tree, n_inputs: int, leaf: Callable[[Leaf], str], pdiv: str = "_pdiv"
) -> str:
    """Infix source text of the tree (python or C): each operator node one parenthesised
    operation, division a call pdiv(left, right) of the protected division."""

    def binary(code, left, right):
        if code == DIV:
            return f"{pdiv}({left}, {right})"
        return f"({left} {INFIX[code]} {right})"

    return fold(tree, n_inputs, leaf, float_literal, binary)


@dataclass(frozen=True)
class TargetSpec:
    """One target's equation as the exports see it."""

    target: str
    tree: Tree
    #: Time constant (s) of the first-order lag, 0 = none; alpha = 1 - exp(-dt / tau).
    tau: float
    alpha: float
    #: 1 / tau as the RK4 kernels compute it (gpquad.engine.kernels.step.lag_rate); 0 = none.
    rate: float
    #: The equation in one line (gpquad.models.equations.Equation.text), for comments.
    text: str
    #: {input name: delays (samples) the equation reads it at}.
    delays: dict[str, list[int]]


@dataclass(frozen=True)
class ModelSpec:
    """A DiscoveredModel reduced to what the exports write; targets in TARGET_NAMES order.
    A target without an equation is the constant 0 (as DiscoveredModel.fly flies it)."""

    dt: float
    input_names: tuple[str, ...]
    trim: tuple[float, ...]
    targets: tuple[TargetSpec, ...]
    #: The longest delay any equation reads (rows of input history before the current one).
    history: int
    #: The scheme fly() uses (gpquad.engine.kernels.step): "euler" (eq. 2) or "rk4" with
    #: `substeps` classical RK4 steps per sample.
    integrator: str = "euler"
    substeps: int = 1

    @property
    def n_inputs(self) -> int:
        return len(self.input_names)


def model_spec(model) -> ModelSpec:
    """The ModelSpec of a gpquad.models.equations.DiscoveredModel."""
    n_in = len(model.input_names)
    zero = Tree.from_lists([CONST], [0.0], np.zeros(n_in, dtype=np.int64))
    targets = []
    history = 0
    for target in TARGET_NAMES:
        eq = model.equations.get(target)
        tree = eq.tree if eq is not None else zero
        tau = float(eq.lag) if eq is not None else 0.0
        delays: dict[str, list[int]] = {}
        for leaf_ in leaves(tree, n_in):
            if leaf_.kind == "input":
                name = model.input_names[leaf_.index]
                delays.setdefault(name, [])
                if leaf_.delay not in delays[name]:
                    delays[name].append(leaf_.delay)
                history = max(history, leaf_.delay)
        text = eq.text() if eq is not None else f"{target} = 0 (no equation)"
        alpha = lag_alpha(tau, model.dt)
        targets.append(
            TargetSpec(
                target,
                tree,
                tau,
                alpha,
                lag_rate(alpha, model.dt),
                text,
                {n: sorted(d) for n, d in delays.items()},
            )
        )
    trim = tuple(float(model.trim.get(n, 0.0)) for n in model.input_names)
    return ModelSpec(
        float(model.dt),
        tuple(model.input_names),
        trim,
        tuple(targets),
        history,
        str(model.integrator),
        int(model.substeps or 1),
    )


def short_number(value: float) -> str:
    """A float for people: at most 6 significant digits, no float noise (0.04, not
    0.03999999999999915)."""
    return f"{value:.6g}"


def scheme_lines(spec: ModelSpec) -> list[str]:
    """The header's statement of the scheme that fly() uses and of the ODE that the
    equations are the right-hand side of."""
    if spec.integrator == "euler":
        return [
            "scheme: euler (the paper's eq. 2): one explicit step per sample of dt, the",
            "    equations evaluated at the sample's state; fly() is that map, the one the",
            "    equations were fitted through (flown by a fine continuous-time integrator",
            "    they give another model).",
        ]
    return [
        f"scheme: rk4, continuous time: fly() integrates the ODE below by {spec.substeps}",
        f"    classical RK4 step(s) per sample (h = dt / {spec.substeps} = "
        f"{short_number(spec.dt / spec.substeps)} s), as gpquad fitted",
        "    the equations: inputs (and delayed inputs, whole samples) held over each sample,",
        "    the attitude quaternion normalised at every stage and renormalised (first",
        "    order) after each step. Another accurate integrator of the ODE flies the",
        "    same model (to its own discretisation error).",
        "ODE: q_dot = q * (0, omega) / 2 (body -> world quaternion, omega = [p, q, r]),",
        "    [u, v, w]_dot = [a_x, a_y, a_z] - omega x [u, v, w],",
        "    [p, q, r]_dot = [p_dot, q_dot, r_dot], the equations' right-hand sides; a lagged",
        "    equation applies its lag state a instead, a_dot = (rhs - a) / tau.",
    ]


def describe(spec: ModelSpec) -> list[str]:
    """The comment header every code export carries: dt, inputs, trim, delays, lags and the
    equations in text (constants rounded for reading; the code holds them in full)."""
    lines = [
        f"dt = {short_number(spec.dt)} s"
        + (f" (exactly {spec.dt!r})" if short_number(spec.dt) != repr(spec.dt) else "")
        + "; delays in samples of dt",
        "state x = [" + ", ".join(STATE_NAMES) + "] (rad, m/s, rad/s; Euler ZYX)",
        "inputs, in order: " + ", ".join(spec.input_names) + " (raw units)",
        "trim (subtracted from each raw input before the equations): "
        + ", ".join(f"{n} {short_number(t)}" for n, t in zip(spec.input_names, spec.trim)),
        f"input history: {spec.history} past row(s) besides the current one; rows before the "
        "first input row are held at the first",
    ]
    lines += scheme_lines(spec)
    for t in spec.targets:
        state = TARGET_STATE[t.target]
        read = ", ".join(f"{n} at {d}" for n, d in t.delays.items()) or "none"
        if not t.tau > 0:
            lag = "no lag"
        elif spec.integrator == "euler":
            lag = (
                f"first-order lag tau = {short_number(t.tau)} s: tau d({t.target})/dt + "
                f"{t.target} = rhs, discretely a_k = a_(k-1) + alpha (rhs_k - a_(k-1)), "
                f"alpha = {short_number(t.alpha)}, a_(-1) = 0"
            )
        else:
            lag = (
                f"first-order lag tau = {short_number(t.tau)} s: the applied {t.target} is "
                f"the lag state a, tau da/dt = rhs - a, a = 0 at the start"
            )
        lines.append(f"{t.target} (d{state}/dt): inputs read (delays) {read}; {lag}")
        lines.append(f"    {t.text}")
    lines.append(f"protected division: |denominator| < {DIV_EPS:g} gives 1")
    return lines
