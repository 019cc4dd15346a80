"""Plants for the closed loop: six prefix trees (a discovered model or a truth model), and
what the controller reads from the model it is designed on (the hover linearisation).

`Plant` holds the flat arrays of gpquad.control.pid_kernel. `design_point` finds, from the
model alone, which input drives roll, pitch, yaw and thrust (the input with the largest
|d acc / d input| on p_dot, q_dot, r_dot and a_z at hover), the signed sensitivities, the
hover inputs (Newton on p_dot = q_dot = r_dot = a_z = 0 at rest) and g_x = d a_x / d theta,
g_y = d a_y / d phi.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from gpquad.control.pid_kernel import constant_input_accelerations
from gpquad.data.simulator import TruthModel
from gpquad.engine.kernels.tree_eval import check_stack
from gpquad.engine.lag import lag_alpha
from gpquad.engine.tree.encoding import Tree, stack_rows
from gpquad.engine.tree.export import from_sympy
from gpquad.engine.variables import TARGET_NAMES, target_index
from gpquad.errors import GpquadError

AXES = ("roll", "pitch", "yaw", "thrust")
AXIS_TARGET = {"roll": "p_dot", "pitch": "q_dot", "yaw": "r_dot", "thrust": "a_z"}


@dataclass
class Plant:
    """codes (6, M), values (6, M), sizes (6,), delays (6, K n_in) for K taps per input,
    trim (n_in,), dt (s); alphas (6,) the equations' lag factors (gpquad.engine.lag; the
    hover design point does not depend on them: a lag's static gain is 1); integrator and
    substeps: the scheme that flies it (gpquad.engine.kernels.step)."""

    name: str
    input_names: tuple[str, ...]
    codes: np.ndarray
    values: np.ndarray
    sizes: np.ndarray
    delays: np.ndarray
    trim: np.ndarray
    dt: float
    alphas: np.ndarray = field(default_factory=lambda: np.ones(6))
    integrator: str = "euler"
    substeps: int = 1

    def arrays(self) -> tuple:
        return self.codes, self.values, self.sizes, self.delays, self.trim, self.dt

    def accelerations(self, state, inputs) -> np.ndarray:
        """The six accelerations in `state` (9,) with raw `inputs` held constant."""
        return constant_input_accelerations(
            self.codes,
            self.values,
            self.sizes,
            self.delays,
            self.trim,
            np.asarray(state, float),
            np.asarray(inputs, float),
        )


def plant_from_trees(name: str, trees: dict[str, Tree], input_names, trim, dt: float) -> Plant:
    """A plant of one tree per target; a target without a tree has zero acceleration.
    Trees may read several taps of an input (gpquad.engine.taps)."""
    codes, values, sizes, delays = stack_rows(
        {target_index(t): tree for t, tree in trees.items()}, 6, min_slots=len(input_names)
    )
    check_stack(codes, sizes)
    return Plant(
        name,
        tuple(input_names),
        codes,
        values,
        sizes,
        delays,
        np.asarray(trim, dtype=float),
        float(dt),
    )


def model_plant(model, form: str = "simplified") -> Plant:
    """The discovered model's equations (inputs minus the model's trim).

    form "simplified": the sympy-simplified equations of model.json's `expr`, re-encoded;
    "tree": the evolved trees exactly as the fitness kernels evaluate them, with protected
    division (|b| < 1e-6 gives 1). The two differ where a protected denominator crosses
    zero: the quickstart's q_dot tree (-100.85 / (34.02 / u_P) - q) / 0.3025 is
    -3.31 q - 9.80 u_P as an equation, but the tree gives q_dot = -333 rad/s^2 whenever
    |u_P - trim| < 1e-6, which noise around hover hits now and then."""
    if form == "tree":
        trees = {t: e.tree for t, e in model.equations.items()}
    else:
        trees = {
            t: from_sympy(e.sympy(), e.delays, model.input_names)
            for t, e in model.equations.items()
        }
    trim = [model.trim.get(n, 0.0) for n in model.input_names]
    plant = plant_from_trees("model", trees, model.input_names, trim, model.dt)
    for t, e in model.equations.items():
        plant.alphas[target_index(t)] = lag_alpha(e.lag, model.dt)
    plant.integrator, plant.substeps = model.integrator, model.substeps
    return plant


def truth_plant(equations: dict[str, str], input_names, dt: float) -> Plant:
    """The reference simulator's true equations (raw inputs) as a plant."""
    truth = TruthModel(equations, input_names)
    trees = {
        t: from_sympy(truth.exprs[t], truth.delays[t], input_names)
        for t in TARGET_NAMES
        if t in truth.exprs
    }
    return plant_from_trees("truth", trees, input_names, np.zeros(len(input_names)), dt)


@dataclass
class DesignPoint:
    """What the controller knows of the model: channels, sensitivities, hover, g_x, g_y."""

    chan: np.ndarray  # (4,) input index of roll, pitch, yaw, thrust
    gain: np.ndarray  # (4,) d acc / d input on those channels (signed)
    hover: np.ndarray  # (n_in,) raw hover inputs
    g_x: float
    g_y: float

    @property
    def scale(self) -> np.ndarray:
        return 1.0 / self.gain

    def to_dict(self, input_names) -> dict:
        return {
            "channels": {a: input_names[c] for a, c in zip(AXES, self.chan, strict=True)},
            "sensitivity": {a: float(g) for a, g in zip(AXES, self.gain, strict=True)},
            "hover_inputs": dict(zip(input_names, self.hover.tolist(), strict=True)),
            "g_x": self.g_x,
            "g_y": self.g_y,
        }


def _jacobian(plant: Plant, state, inputs, step: np.ndarray) -> np.ndarray:
    """d acc / d input (6, n_in) by central differences."""
    jac = np.empty((6, len(inputs)))
    for j, h in enumerate(step):
        up, down = inputs.copy(), inputs.copy()
        up[j] += h
        down[j] -= h
        jac[:, j] = (plant.accelerations(state, up) - plant.accelerations(state, down)) / (2 * h)
    return jac


def design_point(plant: Plant, input_span: np.ndarray, source: str = "model") -> DesignPoint:
    """Linearise the plant at rest about its trim; raise if the inputs do not map one-to-one
    onto roll, pitch, yaw and thrust."""
    n_in = len(plant.input_names)
    if n_in < 4:
        raise GpquadError(
            f"the model has {n_in} inputs; the PID needs roll, pitch, yaw and thrust inputs",
            source=source,
            field="input_names",
        )
    rest = np.zeros(9)
    step = 1e-3 * np.maximum(np.asarray(input_span, float), 1e-6)
    hover = plant.trim.copy()
    rows = [target_index(AXIS_TARGET[a]) for a in AXES]
    jac = _jacobian(plant, rest, hover, step)
    chan = np.array([int(np.argmax(np.abs(jac[r]))) for r in rows], dtype=np.int64)
    if len(set(chan.tolist())) < 4 or np.any(np.abs(jac[rows, chan]) < 1e-9):
        names = [plant.input_names[c] for c in chan]
        raise GpquadError(
            "the model's inputs do not map one-to-one onto roll (p_dot), pitch (q_dot), yaw "
            f"(r_dot) and thrust (a_z): largest sensitivities on {names}; identify all four "
            "equations with their inputs",
            source=source,
            field="targets",
        )
    for _ in range(5):  # Newton: p_dot = q_dot = r_dot = a_z = 0 at rest
        acc = plant.accelerations(rest, hover)[rows]
        sub = _jacobian(plant, rest, hover, step)[np.ix_(rows, chan)]
        try:
            hover[chan] -= np.linalg.solve(sub, acc)
        except np.linalg.LinAlgError:
            break
    jac = _jacobian(plant, rest, hover, step)
    gain = jac[rows, chan]
    tilt = 1e-3
    gx = _state_derivative(plant, hover, 1, 0, tilt)
    gy = _state_derivative(plant, hover, 0, 1, tilt)
    for name, g in (("d a_x / d theta", gx), ("d a_y / d phi", gy)):
        if not abs(g) > 1e-3:
            raise GpquadError(
                f"the model has {name} = {g:.3g} at hover: tilting does not move "
                "it, so the outer loops cannot steer it",
                source=source,
                field="targets",
            )
    return DesignPoint(chan, gain, hover, gx, gy)


def _state_derivative(plant: Plant, hover, state_index: int, target: int, h: float) -> float:
    up, down = np.zeros(9), np.zeros(9)
    up[state_index], down[state_index] = h, -h
    return float(
        (plant.accelerations(up, hover)[target] - plant.accelerations(down, hover)[target])
        / (2 * h)
    )
