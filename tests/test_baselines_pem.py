"""PEM baseline: recovery, bounds and perpendicular-axis constraints, open vs closed loop."""

import dataclasses
import math

import numpy as np
import pytest

from gpquad.baselines import pem
from gpquad.baselines import pem_sim as ps
from gpquad.baselines.geometry import Geometry, drag_factor, inertia, initial_guess, lift_factor
from gpquad.baselines.pem_config import (
    PARAMS,
    TRUE_PARAMS,
    PemConfig,
    PemSection,
    PemSimConfig,
    load_pem_config,
)
from gpquad.errors import GpquadError


def config(train_s=30.0, **pem_kw):
    return PemConfig(
        simulator=PemSimConfig(train_s=train_s, unseen_s=(10.0,)), pem=PemSection(**pem_kw)
    )


def theta0_of(cfg):
    v = cfg.vehicle
    return ps.theta_array(initial_guess(cfg.geometry, v.arm_length, v.mass, v.gravity))


def with_truth(cfg, **changes):
    truth = {**TRUE_PARAMS, **changes}
    return dataclasses.replace(cfg, simulator=dataclasses.replace(cfg.simulator, true_params=truth))


def test_noise_free_recovery_within_5_percent():
    cfg = config()
    rec = ps.simulate(cfg, cfg.simulator.train_s, 0)
    theta0 = theta0_of(cfg)
    truth = ps.theta_array(TRUE_PARAMS)
    assert np.abs(theta0 / truth - 1).max() > 0.4  # the analytic guess is far off (d, J_r)
    f = pem.fit(cfg, rec, rec.outputs(), theta0)
    assert np.abs(f.theta / truth - 1).max() < 0.05
    assert f.e_refined < 1e-3 * f.e_initial
    # E of the truth on its own noise-free data is zero
    assert pem.error(truth, cfg, rec, rec.outputs(), pem.weights(rec.outputs())) < 1e-20


def test_perpendicular_axis_constraints_hold_when_truth_violates_them():
    # I_zz > I_xx + I_yy violates eq. (20); with the constraints the fit must stay feasible.
    base = with_truth(config(train_s=20.0), I_zz=0.04)
    rec = ps.simulate(base, 20.0, 0)
    theta0 = theta0_of(base)
    A = pem.perpendicular_axis_matrix(theta0)
    constrained = pem.fit(base, rec, rec.outputs(), theta0)
    i = constrained.theta
    assert i[2] <= (i[0] + i[1]) * (1 + 1e-6)
    assert (A @ (i / theta0)).min() >= -1e-6
    assert constrained.e_refined > 1e-8  # the truth is out of reach
    free = pem.fit(
        dataclasses.replace(base, pem=PemSection(constraints=False)), rec, rec.outputs(), theta0
    )
    assert abs(free.theta[2] / 0.04 - 1) < 0.05
    assert free.theta[2] > free.theta[0] + free.theta[1]


def test_bounds_are_respected():
    cfg = with_truth(config(train_s=20.0, bound_factor=1.5), d=3.679e-7)
    rec = ps.simulate(cfg, 20.0, 0)
    theta0 = theta0_of(cfg)
    f = pem.fit(cfg, rec, rec.outputs(), theta0)
    x = f.theta / theta0
    assert x.min() >= 1 / 1.5 - 1e-9 and x.max() <= 1.5 + 1e-9
    d = PARAMS.index("d")
    assert x[d] == pytest.approx(1.5, rel=1e-6)  # true d is 3.2 x the guess: stuck at the bound


def test_perpendicular_axis_matrix():
    theta0 = np.array([1.0, 2.0, 4.0, 1, 1, 1])
    A = pem.perpendicular_axis_matrix(theta0)
    ok = np.array([1.0, 1.0, 0.7, 1, 1, 1])  # I = (1, 2, 2.8): all three hold
    bad = np.array([1.0, 1.0, 1.0, 1, 1, 1])  # I_zz = 4 > 1 + 2
    assert (A @ ok).min() >= 0 and (A @ bad)[2] == pytest.approx(1 + 2 - 4)


def test_open_loop_fails_within_two_seconds_closed_loop_holds():
    cfg = config(train_s=30.0)
    rec = ps.simulate(cfg, 30.0, 3)
    d = pem.divergence_times(ps.theta_array(TRUE_PARAMS), cfg, rec, 5.0, 0.2)
    assert np.median(d["open"]) < 2.0
    assert np.all(d["closed"] == 5.0)


def test_geometry_formulas():
    g = Geometry()
    assert lift_factor(g, 1.5, 9.8) == pytest.approx(1.5 * 9.8 / (4 * 405.0**2))
    be = dataclasses.replace(g, lift_method="blade_element")
    bracket = 0.30 / 6 - 0.15 / 8 - 0.05 / 4
    assert lift_factor(be, 1.5, 9.8) == pytest.approx(
        2 * math.pi * 1.225 * 2 * 0.025 * 0.127**3 * bracket
    )
    assert drag_factor(g) == pytest.approx(
        2 * math.pi * 1.225 * 2 * 0.025 * 0.127**4 * (0.01 / (16 * math.pi) + 0.05 * bracket)
    )
    tips = dataclasses.replace(
        g,
        rod_mass=0.0,
        box_mass=0.0,
        motor_radius=0.0,
        motor_height=0.0,
        prop_mass=0.0,
        rotor_mass=0.0,
    )
    ixx, iyy, izz, jr = inertia(tips, 0.2)
    assert (ixx, iyy, izz, jr) == pytest.approx(
        (2 * 0.1 * 0.04, 2 * 0.1 * 0.04, 4 * 0.1 * 0.04, 0.0)
    )
    ixx, iyy, izz, _ = inertia(g, 0.2178)
    assert izz <= ixx + iyy  # a flat vehicle satisfies eq. (20)


def test_pem_config_is_strict(tmp_path):
    path = tmp_path / "pem.toml"
    path.write_text("[pem]\nmethod = 'Nelder-Mead'\n")
    with pytest.raises(GpquadError, match=r"pem\.method"):
        load_pem_config(path)
    path.write_text("[geometry]\nchord = 'wide'\n")
    with pytest.raises(GpquadError, match=r"pem.toml.*geometry\.chord.*expected float"):
        load_pem_config(path)
    path.write_text("[vehicle]\nwingspan = 1.0\n")
    with pytest.raises(GpquadError, match=r"vehicle\.wingspan.*unknown key"):
        load_pem_config(path)
