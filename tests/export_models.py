"""Models and helpers shared by the export tests (tests/test_exports*.py).

- hand_model(): taps, delays, a lag, trim and a protected division that the inputs of
  hand_inputs() drive to |denominator| < DIV_EPS (an euler model);
- rk4_model(): an RK4 model (4 substeps) with delays, two lags and products of states and
  inputs; in_scheme(): a model flown by another scheme;
- median_model(): the reference simulator's median model, with a quickstart-like trim;
- load_python(), compile_c(), fly_c(): run the python and C exports;
- assert_flies_like(): the 1e-12 relative comparison every export is held to.
"""

from __future__ import annotations

import ctypes
import dataclasses
import importlib.util
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from gpquad.engine.kernels.tree_eval import eval_on_samples
from gpquad.engine.tree.encoding import Tree
from gpquad.engine.tree.operators import ADD, CONST, DIV, MUL, SUB, VAR_BASE
from gpquad.engine.variables import STATE_NAMES
from gpquad.models.equations import DiscoveredModel, Equation
from gpquad.models.exports import export
from gpquad.models.exports.codegen import model_spec

INPUTS = ("u_P", "u_R", "u_Y", "u_T")
FIXTURES = Path(__file__).parent / "fixtures"
_OPS = {"+": ADD, "-": SUB, "*": MUL, "/": DIV}


def _prefix(node, codes: list, values: list) -> None:
    """Prefix codes of a nested tuple: (op, left, right), float, state name, or
    ("in", slot) for input leaf slot (gpquad.engine.taps)."""
    if isinstance(node, float):
        codes.append(CONST)
        values.append(node)
    elif isinstance(node, str):
        codes.append(VAR_BASE + STATE_NAMES.index(node))
        values.append(0.0)
    elif node[0] == "in":
        codes.append(VAR_BASE + len(STATE_NAMES) + node[1])
        values.append(0.0)
    else:
        codes.append(_OPS[node[0]])
        values.append(0.0)
        _prefix(node[1], codes, values)
        _prefix(node[2], codes, values)


def equation(target, node, delays, trim, lag=0.0) -> Equation:
    codes: list = []
    values: list = []
    _prefix(node, codes, values)
    return Equation(
        target, Tree.from_lists(codes, values, delays), INPUTS, 0.1, 0.2, dict(trim), [], 4, lag
    )


HAND_TRIM = {"u_P": 0.25, "u_R": -0.05, "u_Y": 0.1, "u_T": 0.5}


def hand_model() -> DiscoveredModel:
    """Two taps per input (slots 0-3 tap 0 of u_P u_R u_Y u_T, slots 4-7 tap 1), delays up
    to 4, a lag on p_dot, trim, a constant 0.1 + 0.2 (float noise if printed in full) and
    q_dot's 0.3 / (u_P - 0.5), protected where the trimmed u_P is within 1e-6 of 0.5."""
    t = HAND_TRIM
    delays = [0, 1, 2, 4, 0, 3, 0, 0]
    eqs = {
        "a_x": equation(
            "a_x",
            ("+", ("-", ("*", 9.81, "theta"), ("*", 0.1, "u")), ("*", 0.01, "psi")),
            delays,
            t,
        ),
        "a_y": equation("a_y", ("-", ("*", -9.81, "phi"), ("*", 0.1, "v")), delays, t),
        "a_z": equation("a_z", ("-", ("-", ("*", 20.0, ("in", 3)), "w"), 9.81), delays, t),
        "p_dot": equation(
            "p_dot",
            ("-", ("-", ("*", 10.0, ("in", 1)), ("*", 3.0, ("in", 5))), ("*", 4.0, "p")),
            delays,
            t,
            lag=0.05,
        ),
        "q_dot": equation(
            "q_dot", ("-", ("/", 0.3, ("-", ("in", 0), 0.5)), ("*", 3.0, "q")), delays, t
        ),
        "r_dot": equation(
            "r_dot", ("+", ("*", -1.9, "r"), ("*", 0.1 + 0.2, ("*", -7.8, ("in", 2)))), delays, t
        ),
    }
    return DiscoveredModel(eqs, INPUTS, dict(t), 0.04, 1, {})


def rk4_model(substeps: int = 4) -> DiscoveredModel:
    """A continuous-time model (integrator "rk4"): delays up to 3, lags on p_dot (30 ms) and
    r_dot (0.1 s), products state x state (q w, r theta) and input x input / state
    (u_T(t-1) u_R, u_P q), a protected division, trim."""
    t = HAND_TRIM
    delays = [0, 1, 2, 0, 0, 3, 0, 1]
    eqs = {
        "a_x": equation(
            "a_x", ("-", ("*", 9.81, "theta"), ("+", ("*", 0.2, "u"), ("*", "q", "w"))), delays, t
        ),
        "a_y": equation("a_y", ("-", ("*", -9.81, "phi"), ("*", 0.15, "v")), delays, t),
        "a_z": equation(
            "a_z", ("-", ("*", 12.0, ("*", ("in", 7), ("in", 1))), ("+", "w", 0.4)), delays, t
        ),
        "p_dot": equation(
            "p_dot",
            (
                "-",
                ("+", ("*", 30.0, ("-", ("in", 1), "phi")), ("*", -8.0, ("in", 5))),
                ("*", 5.0, "p"),
            ),
            delays,
            t,
            lag=0.03,
        ),
        "q_dot": equation(
            "q_dot",
            ("-", ("*", ("in", 0), ("-", 20.0, ("*", 2.0, "q"))), ("*", 25.0, "theta")),
            delays,
            t,
        ),
        "r_dot": equation(
            "r_dot",
            ("+", ("*", -2.5, "r"), ("-", ("*", 6.0, ("in", 2)), ("/", ("*", "r", "theta"), "u"))),
            delays,
            t,
            lag=0.1,
        ),
    }
    return DiscoveredModel(eqs, INPUTS, dict(t), 0.04, 1, {}, integrator="rk4", substeps=substeps)


def in_scheme(model: DiscoveredModel, integrator: str, substeps: int = 1) -> DiscoveredModel:
    """The same equations flown (and exported) with another scheme."""
    return dataclasses.replace(model, integrator=integrator, substeps=substeps)


def hand_inputs(n: int = 200, seed: int = 3) -> np.ndarray:
    """Raw inputs for hand_model: u_P (trimmed) exactly 0.5 and 0.5 + 1e-7 on some rows
    (the protected division), otherwise at least 0.1 away from 0.5."""
    rng = np.random.default_rng(seed)
    inputs = rng.normal(0.0, 0.3, size=(n, 4)) + np.array([0.0, -0.05, 0.1, 0.5])
    step = rng.choice([-0.3, -0.15, 0.15, 0.3], size=n)
    inputs[:, 0] = 0.75 + step
    inputs[10:14, 0] = 0.75
    inputs[40:43, 0] = 0.75 + 1e-7
    return inputs


def median_model() -> DiscoveredModel:
    """The simulator's median model (gpquad.study.config.SimulatorConfig) with a trim as a
    quickstart run subtracts (trim = "mean")."""
    from gpquad.engine.tree.export import from_sympy, parse_equation
    from gpquad.study.config import SimulatorConfig

    trim = {"u_P": 0.01, "u_R": -0.02, "u_Y": 0.0, "u_T": 0.35}
    eqs = {}
    for target, text in SimulatorConfig().equations.items():
        expr, delays = parse_equation(text, INPUTS)
        eqs[target] = Equation(
            target, from_sympy(expr, delays, INPUTS), INPUTS, 0.0, 0.0, dict(trim)
        )
    return DiscoveredModel(eqs, INPUTS, trim, 0.04, 1, {})


def fixture_model(name: str) -> DiscoveredModel:
    return DiscoveredModel.load(FIXTURES / name)


def assert_flies_like(states: np.ndarray, reference: np.ndarray, rtol: float = 1e-12) -> None:
    """states equal reference to rtol relative to each state's largest magnitude."""
    assert states.shape == reference.shape
    assert np.all(np.isfinite(reference)), "the reference flight diverged"
    scale = np.maximum(np.abs(reference).max(axis=0), 1e-3)
    worst = np.max(np.abs(states - reference) / scale)
    assert worst <= rtol, f"largest difference {worst:.3g} of the state's scale (> {rtol:g})"


def load_python(source: str, path: Path):
    """Write the python export to `path` and import it as a module."""
    path.write_text(source)
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def compile_c(files: dict[str, str], folder: Path) -> ctypes.CDLL:
    """Compile the C export into a shared library with the system cc (skip without one)."""
    cc = shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")
    if cc is None:
        pytest.skip("no C compiler (cc, gcc or clang) on PATH to build the C export")
    for name, text in files.items():
        (folder / name).write_text(text)
    source = next(folder / n for n in files if n.endswith(".c"))
    lib = folder / (source.stem + ".so")
    done = subprocess.run(
        [
            cc,
            "-std=c99",
            "-O2",
            "-Wall",
            "-Wextra",
            "-Werror",
            "-pedantic",
            "-shared",
            "-fPIC",
            "-o",
            str(lib),
            str(source),
            "-lm",
        ],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
    return ctypes.CDLL(str(lib))


def kernel_commanded(model, states, inputs) -> np.ndarray:
    """Each equation's tree value by the numba kernel at every row of (states, raw inputs),
    rows before the first input held at the first: (n, 6)."""
    spec = model_spec(model)
    trimmed = inputs - np.array(spec.trim)
    padded = np.vstack([np.repeat(trimmed[:1], spec.history, axis=0), trimmed])
    padded_states = np.vstack([np.repeat(states[:1], spec.history, axis=0), states])
    rows = np.arange(spec.history, len(padded), dtype=np.int64)
    out = np.empty((len(states), 6))
    for i, t in enumerate(spec.targets):
        n_slots = len(t.tree.delays)
        taps = np.ascontiguousarray(np.tile(padded, (1, n_slots // padded.shape[1])))
        out[:, i] = eval_on_samples(
            t.tree.codes, t.tree.values, t.tree.size, t.tree.delays, padded_states, taps, rows
        )
    return out


def history_rows(inputs, k: int, history: int) -> np.ndarray:
    """Raw input rows k, k-1, ..., k-history (held at row 0)."""
    return np.array([inputs[max(k - d, 0)] for d in range(history + 1)])


_P = ctypes.POINTER(ctypes.c_double)


def _ptr(array):
    return None if array is None else array.ctypes.data_as(_P)


def fly_c(lib, inputs, x0, prefix: str = "gpquad") -> tuple[int, np.ndarray]:
    """(return code, states) of P_fly."""
    fly = getattr(lib, f"{prefix}_fly")
    fly.argtypes = [_P, ctypes.c_int, _P, _P]
    fly.restype = ctypes.c_int
    inputs = np.ascontiguousarray(inputs, dtype=float)
    x0 = np.ascontiguousarray(x0, dtype=float)
    states = np.full((len(inputs), 9), np.nan)
    code = fly(_ptr(inputs), len(inputs), _ptr(x0), _ptr(states))
    return code, states


def c_step(lib, name: str, state, history, previous=None, prefix: str = "gpquad") -> np.ndarray:
    """P_commanded (previous None) or P_accel of one state and raw input history."""
    out = np.zeros(6)
    args = [np.ascontiguousarray(state, dtype=float), np.ascontiguousarray(history, dtype=float)]
    if previous is not None:
        args.append(np.ascontiguousarray(previous, dtype=float))
    fn = getattr(lib, f"{prefix}_{name}")
    fn.argtypes = [_P] * (len(args) + 1)
    fn.restype = None
    fn(*[_ptr(a) for a in args], _ptr(out))
    return out


def c_rhs(lib, state, history, lag, prefix: str = "gpquad") -> tuple[np.ndarray, np.ndarray]:
    """(accelerations, lag_dot) of P_rhs; lag None passes NULL."""
    accel, lag_dot = np.full(6, np.nan), np.full(6, np.nan)
    fn = getattr(lib, f"{prefix}_rhs")
    fn.argtypes = [_P] * 5
    fn.restype = None
    state = np.ascontiguousarray(state, dtype=float)
    history = np.ascontiguousarray(history, dtype=float)
    lag = None if lag is None else np.ascontiguousarray(lag, dtype=float)
    fn(_ptr(state), _ptr(history), _ptr(lag), _ptr(accel), _ptr(lag_dot))
    return accel, lag_dot


def python_and_c(model, tmp_path, name="model"):
    """(python module, C library) of the model's exports."""
    module = load_python(export(model, "python"), tmp_path / f"{name}_export.py")
    lib = compile_c(export(model, "c", name=f"{name}_export"), tmp_path)
    return module, lib
