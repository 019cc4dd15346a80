"""Exports that are the model: python and C fly euler models as DiscoveredModel.fly_states
to the bit (tests/test_exports_rk4.py: RK4 models); sympy and casadi give the kernels'
one-step accelerations; the printed forms state dt."""

from __future__ import annotations

import re

import numpy as np
import pytest
import sympy as sp
from export_models import (
    assert_flies_like,
    c_step,
    compile_c,
    fixture_model,
    fly_c,
    hand_inputs,
    hand_model,
    history_rows,
    kernel_commanded,
    load_python,
    median_model,
    python_and_c,
    rk4_model,
)

from gpquad.cli.commands import main
from gpquad.engine.kernels.quaternion import rotation_matrix
from gpquad.engine.variables import TARGET_NAMES
from gpquad.models.exports import FORMATS, export, sympy_equations

X0 = np.array([0.05, -0.1, 3.0, 1.0, -0.5, 0.2, 0.1, -0.2, 0.3])


def _models():
    return {
        "hand": hand_model(),
        "median": median_model(),
        "px4_s250": fixture_model("px4_s250_model.json"),
        "betaflight_gecko": fixture_model("betaflight_gecko_model.json"),
    }


MODELS = _models()


def _inputs(name: str, n: int = 200) -> np.ndarray:
    if name == "hand":
        return hand_inputs(n)
    rng = np.random.default_rng(5)
    return rng.normal(0.0, 0.15, size=(n, 4)) + np.array([0.0, 0.0, 0.0, 0.4])


@pytest.mark.parametrize("name", list(MODELS))
def test_python_and_c_exports_fly_as_fly_states(name, tmp_path):
    model = MODELS[name]
    inputs = _inputs(name)
    reference = model.fly_states(inputs, X0)
    assert model.integrator == "euler"
    module, lib = python_and_c(model, tmp_path)
    assert module.INTEGRATOR == "euler" and "accel" in dir(module)
    code, states = fly_c(lib, inputs, X0)
    assert code == 0
    # euler exports stay bit-identical to eq. 2's rollout (itself pinned by
    # tests/test_euler_bit_identical.py), as before the RK4 exports
    np.testing.assert_array_equal(module.fly(inputs, X0), reference)
    np.testing.assert_array_equal(states, reference)
    # fly() is fly_states() plus eq. 2's position x' = x + R(q) V dt of those states, to
    # the bit as fly summed it before RK4 models flew theirs with the RK4 state
    flight = model.fly(inputs, X0)
    np.testing.assert_array_equal(flight.rates, reference[:, 6:9])
    np.testing.assert_array_equal(flight.pos, eq2_position(flight.quat, flight.vel, model.dt))


def eq2_position(quat: np.ndarray, vel: np.ndarray, dt: float) -> np.ndarray:
    """x_0 = 0, x_{k+1} = x_k + R(q_k) V_k dt, summed by np.cumsum."""
    mat = np.empty((3, 3))
    world = []
    for q, v in zip(quat, vel, strict=True):
        rotation_matrix(*q, mat)
        world.append(mat @ v)
    return np.vstack([np.zeros(3), np.cumsum(np.array(world)[:-1] * dt, axis=0)])


def test_hand_model_hits_the_protected_division(tmp_path):
    """Rows 10-13 and 40-42 put q_dot's denominator at 0 and 1e-7: the kernel gives 0.3 / b
    = 1 there, and so does every export (an unprotected division would be inf or 3e6)."""
    model = hand_model()
    inputs = hand_inputs()
    states = model.fly_states(inputs, X0)
    kernel = kernel_commanded(model, states, inputs)
    q = TARGET_NAMES.index("q_dot")
    np.testing.assert_allclose(
        kernel[[10, 13, 40, 42], q] + 3.0 * states[[10, 13, 40, 42], 7], 1.0, rtol=1e-12
    )
    module, lib = python_and_c(model, tmp_path)
    for k in (10, 40):
        hist = history_rows(inputs, k, module.HISTORY)
        assert module.commanded(states[k], hist)[q] == kernel[k, q]
        assert c_step(lib, "commanded", states[k], hist)[q] == kernel[k, q]


@pytest.mark.parametrize("name", ["hand", "betaflight_gecko"])
def test_one_step_accelerations_match_the_kernel(name, tmp_path):
    """commanded() of python, C, sympy's lambdify and the script's equations equal the
    kernel's tree values; accel() filters the lagged ones from `previous`."""
    model = MODELS[name]
    inputs = _inputs(name, 60)
    states = model.fly_states(inputs, X0)
    kernel = kernel_commanded(model, states, inputs)
    module, lib = python_and_c(model, tmp_path)
    form = sympy_equations(model, raw=True)
    lambdas = {t: form.lambdify(t) for t in form.rhs}
    namespace: dict = {}
    exec(compile(export(model, "sympy", raw=True), "sympy_export", "exec"), namespace)
    alpha = np.array(module.ALPHA)
    previous = np.linspace(-1.0, 1.0, 6)
    for k in range(0, 60, 7):
        hist = history_rows(inputs, k, module.HISTORY)
        np.testing.assert_array_equal(module.commanded(states[k], hist), kernel[k])
        np.testing.assert_array_equal(c_step(lib, "commanded", states[k], hist), kernel[k])
        want = np.where(alpha < 1.0, previous + alpha * (kernel[k] - previous), kernel[k])
        np.testing.assert_array_equal(module.accel(states[k], hist, previous), want)
        np.testing.assert_array_equal(c_step(lib, "accel", states[k], hist, previous), want)
        args = list(states[k]) + [
            inputs[max(k - d, 0), model.input_names.index(n)] for n, d in form.inputs.values()
        ]
        for t, f in lambdas.items():
            i = TARGET_NAMES.index(t)
            assert float(f(*args)) == pytest.approx(kernel[k, i], rel=1e-9, abs=1e-12)
    for t in form.rhs:
        assert sp.simplify(namespace["rhs"][t] - form.rhs[t]) == 0
        assert namespace["equations"][t] == form.equations[t]


def test_sympy_form_carries_delays_lags_trim_and_dt():
    model = hand_model()
    form = sympy_equations(model)
    names = {s.name for s in form.inputs}
    assert {"u_R(t-1)", "u_R(t-3)", "u_T(t-4)", "u_Y(t-2)", "u_P"} <= names
    assert form.inputs[sp.Symbol("u_R(t-3)", real=True)] == ("u_R", 3)
    assert form.lags == {"p_dot": 0.05} and form.dt == 0.04 and form.trim == model.trim
    lagged = form.equations["p_dot"]
    assert lagged.lhs.has(sp.Derivative) and sp.Float(0.05) in lagged.lhs.atoms(sp.Float)
    assert form.equations["q_dot"].lhs == sp.Symbol("q_dot", real=True)
    assert form.equations["q_dot"].rhs.has(sp.Piecewise)  # the protected division
    assert model.to_sympy() == form.equations
    assert model.to_sympy(raw=True) == sympy_equations(model, raw=True).equations
    raw = sympy_equations(model, raw=True)
    u_p = sp.Symbol("u_P", real=True)
    q = sp.Symbol("q", real=True)
    at = {u_p: 0.4, q: 0.5}
    assert float(form.rhs["q_dot"].subs(at)) == pytest.approx(0.3 / (0.4 - 0.5) - 1.5)
    assert float(raw.rhs["q_dot"].subs({u_p: 0.4 + 0.25, q: 0.5})) == pytest.approx(
        float(form.rhs["q_dot"].subs(at))
    )


def test_the_comparison_catches_a_perturbed_constant(tmp_path):
    """A constant of the generated code changed by 1e-7 relative fails assert_flies_like,
    in python and in C."""
    model = hand_model()
    inputs = hand_inputs()
    reference = model.fly_states(inputs, X0)
    python = export(model, "python")
    head, body = python.split("def _commanded", 1)
    bad = head + "def _commanded" + body.replace("20.0", repr(20.0 * (1 + 1e-7)), 1)
    assert bad != python
    module = load_python(bad, tmp_path / "bad_export.py")
    with pytest.raises(AssertionError, match="largest difference"):
        assert_flies_like(module.fly(inputs, X0), reference)
    files = export(model, "c", name="bad_export")
    files["bad_export.c"] = files["bad_export.c"].replace(
        "(20.0 * h[", f"({20.0 * (1 + 1e-7)!r} * h[", 1
    )
    lib = compile_c(files, tmp_path)
    with pytest.raises(AssertionError, match="largest difference"):
        assert_flies_like(fly_c(lib, inputs, X0)[1], reference)


def test_c_fly_refuses_bad_arguments(tmp_path):
    lib = compile_c(export(hand_model(), "c", name="args_export"), tmp_path)
    inputs = hand_inputs(10)
    assert fly_c(lib, inputs[:0], X0)[0] == 2
    assert fly_c(lib, inputs, np.r_[X0[:8], np.nan])[0] == 3
    import ctypes

    lib.gpquad_fly.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p]
    assert lib.gpquad_fly(None, 10, None, None) == 1


def test_python_export_checks_its_arguments(tmp_path):
    module = load_python(export(hand_model(), "python"), tmp_path / "checks_export.py")
    with pytest.raises(ValueError, match="inputs must have shape"):
        module.fly(np.zeros((5, 3)))
    with pytest.raises(ValueError, match="x0 needs 9"):
        module.fly(np.zeros((5, 4)), np.zeros(8))
    with pytest.raises(ValueError, match="input_history must have shape"):
        module.accel(np.zeros(9), np.zeros((module.HISTORY, 4)))


def test_c_prefix_lets_two_models_share_a_program(tmp_path):
    files = export(median_model(), "c", name="median_export", prefix="median")
    assert "median_fly(" in files["median_export.h"] and "gpquad_" not in files["median_export.c"]
    lib = compile_c(files, tmp_path)
    inputs = _inputs("median", 50)
    code, states = fly_c(lib, inputs, X0, prefix="median")
    assert code == 0
    assert_flies_like(states, median_model().fly_states(inputs, X0))


def test_casadi_functions_match_the_python_accel(tmp_path):
    casadi = pytest.importorskip(
        "casadi", reason="casadi is not installed (the [casadi] extra); its export is optional"
    )
    from gpquad.models.exports import casadi_functions

    model = hand_model()
    inputs = hand_inputs(60)
    states = model.fly_states(inputs, X0)
    module = load_python(export(model, "python"), tmp_path / "casadi_ref_export.py")
    functions = casadi_functions(model)
    accel = casadi.Function.deserialize(export(model, "casadi"))
    previous = np.linspace(-1.0, 1.0, 6)
    for k in (0, 10, 25, 40, 59):
        hist = history_rows(inputs, k, module.HISTORY)
        want = module.accel(states[k], hist, previous)
        got = np.array(accel(states[k], hist, previous)).ravel()
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)
        got = np.array(functions["commanded"](states[k], hist)).ravel()
        np.testing.assert_allclose(got, module.commanded(states[k], hist), rtol=1e-12)
    run = tmp_path / "run"
    run.mkdir()
    (run / "model.json").write_text(export(model, "json"))
    assert (
        main(["export", str(run), "--format", "casadi", "--out", str(tmp_path / "m.casadi")]) == 0
    )
    saved = casadi.Function.load(str(tmp_path / "m.casadi"))
    hist = history_rows(inputs, 40, module.HISTORY)
    np.testing.assert_allclose(
        np.array(saved(states[40], hist, previous)).ravel(),
        module.accel(states[40], hist, previous),
        rtol=1e-12,
    )


#: A number with 10 or more significant digits (float noise such as 0.30000000000000004).
_NOISE = re.compile(r"\d*\.?\d{10,}")


@pytest.mark.parametrize("fmt", ["text", "latex", "markdown"])
def test_printed_forms_state_dt_without_float_noise(fmt):
    model = fixture_model("px4_s250_model.json")  # dt 0.03999999999999915 in model.json
    assert model.dt != 0.04
    for m in (model, hand_model()):
        out = export(m, fmt)
        assert ("dt = 0.04 s" if fmt == "text" else r"$\Delta t = 0.04$ s") in out
        assert "delays in samples" in out
        assert not _NOISE.search(out), _NOISE.search(out)
    assert "one explicit step per sample (eq. 2)" in export(hand_model(), fmt)
    rk4 = export(rk4_model(), fmt)
    assert "continuous time, inputs held over each sample (fitted by RK4, 4 step(s)" in rk4
    assert "0.3*u_Y" not in export(hand_model(), "text")  # 0.1 + 0.2 folded into -2.34
    assert "inputs minus their trim (u_P 0.25, u_R -0.05, u_Y 0.1, u_T 0.5)" in export(
        hand_model(), "text"
    )


def test_the_noise_pattern_catches_noise():
    assert _NOISE.search("a_x = 0.30000000000000004*u")
    assert not _NOISE.search("dt = 0.04 s; a_x = 1.2346e+6*u - 0.03*v")


def test_cli_export_writes_and_prints_every_format(tmp_path, capsys):
    run = tmp_path / "run"
    run.mkdir()
    (run / "model.json").write_text(export(hand_model(), "json"))
    assert main(["export", str(run), "--format", "c", "--out", str(tmp_path / "m.c")]) == 0
    assert (tmp_path / "m.c").is_file() and (tmp_path / "m.h").is_file()
    assert '#include "m.h"' in (tmp_path / "m.c").read_text()
    for fmt in FORMATS:
        if fmt == "casadi":
            continue
        capsys.readouterr()
        assert main(["export", str(run), "--format", fmt]) == 0
        assert capsys.readouterr().out.strip()
    assert main(["export", str(run), "--format", "python", "--raw-inputs"]) == 2
    assert "--raw-inputs" in capsys.readouterr().err
    assert main(["export", str(run), "--format", "c", "--out", str(tmp_path / "a b.txt")]) == 2
    assert "--out" in capsys.readouterr().err
