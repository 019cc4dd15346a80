"""Property: for random equations (taps, delays, lags, trim, divisions) and either scheme
(euler, or RK4 with 1-3 substeps), the python and C exports fly as
DiscoveredModel.fly_states."""

from __future__ import annotations

import itertools

import numpy as np
from export_models import INPUTS, assert_flies_like, compile_c, equation, fly_c, load_python
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from gpquad.engine.variables import STATE_NAMES, TARGET_NAMES
from gpquad.models.equations import DiscoveredModel
from gpquad.models.exports import export

N_SLOTS = 2 * len(INPUTS)
EXAMPLES = itertools.count()  # two taps per input

leaf = st.one_of(
    st.floats(-3.0, 3.0, allow_nan=False).map(float),
    st.sampled_from(STATE_NAMES),
    st.tuples(st.just("in"), st.integers(0, N_SLOTS - 1)),
)
trees = st.recursive(leaf, lambda sub: st.tuples(st.sampled_from("+-*/"), sub, sub), max_leaves=12)


@st.composite
def models(draw):
    delays = draw(st.lists(st.integers(0, 5), min_size=N_SLOTS, max_size=N_SLOTS))
    trim = dict(
        zip(
            INPUTS,
            draw(st.lists(st.sampled_from([0.0, 0.1, -0.25, 0.5]), min_size=4, max_size=4)),
            strict=True,
        )
    )
    targets = draw(st.lists(st.sampled_from(TARGET_NAMES), min_size=1, max_size=6, unique=True))
    eqs = {
        t: equation(t, draw(trees), delays, trim, lag=draw(st.sampled_from([0.0, 0.03, 0.2])))
        for t in targets
    }
    integrator, substeps = draw(st.sampled_from([("euler", 1), ("rk4", 1), ("rk4", 2), ("rk4", 3)]))
    return DiscoveredModel(eqs, INPUTS, trim, 0.04, 1, {}, integrator=integrator, substeps=substeps)


@settings(
    max_examples=40,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
@given(model=models(), seed=st.integers(0, 2**16))
def test_python_and_c_exports_fly_random_models_as_fly_states(model, seed, tmp_path):
    rng = np.random.default_rng(seed)
    inputs = rng.normal(0.0, 0.3, size=(40, len(INPUTS)))
    x0 = rng.normal(0.0, 0.2, size=9)
    reference = model.fly_states(inputs, x0)
    assume(np.all(np.isfinite(reference)) and np.abs(reference).max() < 1e4)
    # a new name per example: dlopen gives an already-loaded library's path the old library
    name = f"prop_{model.integrator}{model.substeps}_{next(EXAMPLES)}"
    module = load_python(export(model, "python"), tmp_path / f"{name}.py")
    assert_flies_like(module.fly(inputs, x0), reference)
    lib = compile_c(export(model, "c", name=name), tmp_path)
    code, states = fly_c(lib, inputs, x0)
    assert code == 0
    assert_flies_like(states, reference)
