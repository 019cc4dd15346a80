"""Measured signals from a ground-truth flight: explicit-generator sensor noise and the body
velocity of the thesis (motion-capture velocity rotated into the body frame).

Noise model (all from one `numpy.random.Generator`, drawn in a fixed order):
accelerometer: constant bias N(0, accel_bias_sd) per axis plus white N(0, accel_noise_sd);
rotor speeds: white N(0, rotor_noise_sd) rad/s; velocity: white N(0, velocity_noise_sd) m/s.
Attitude and body rates are taken as measured (the thesis integrates Betaflight's attitude).
With calibration_s > 0 the accelerometer bias is estimated over the flight's first seconds
(rotorpy flights start with a still hover, where the specific force is -R^T g) and removed, as
Betaflight's calibration does and the thesis assumes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class SensorNoise:
    accel_noise_sd: float = 0.0
    accel_bias_sd: float = 0.0
    rotor_noise_sd: float = 0.0
    velocity_noise_sd: float = 0.0
    calibration_s: float = 0.0  # accelerometer bias removed using the first seconds (hover)


def rotations(quat_xyzw: np.ndarray) -> np.ndarray:
    """Body-to-world rotation matrices (N, 3, 3) from quaternions (x, y, z, w)."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_quat(quat_xyzw).as_matrix()


def measure(flight: dict, noise: SensorNoise, rng: np.random.Generator) -> dict:
    """Arrays of a flight as sensors see them: force (accelerometer), rotor, vel_body, plus the
    true ones (t, pos, vel, rot, omega, force_true, rotor_true)."""
    n = len(flight["t"])
    rot = rotations(flight["quat"])
    bias = rng.normal(0.0, noise.accel_bias_sd, 3) if noise.accel_bias_sd > 0 else np.zeros(3)
    acc_white = (
        rng.normal(0.0, noise.accel_noise_sd, (n, 3))
        if noise.accel_noise_sd > 0
        else np.zeros((n, 3))
    )
    rotor_white = (
        rng.normal(0.0, noise.rotor_noise_sd, flight["rotor"].shape)
        if noise.rotor_noise_sd > 0
        else 0.0
    )
    vel_white = (
        rng.normal(0.0, noise.velocity_noise_sd, (n, 3)) if noise.velocity_noise_sd > 0 else 0.0
    )
    vel_meas = flight["vel"] + vel_white
    force = flight["force"] + bias + acc_white
    if noise.calibration_s > 0:
        still = flight["t"] - flight["t"][0] < noise.calibration_s
        expected = -np.einsum("nji,j->ni", rot[still], np.array([0.0, 0.0, -9.81]))
        force = force - np.mean(force[still] - expected, axis=0)
    return {
        "t": flight["t"],
        "pos": flight["pos"],
        "vel": flight["vel"],
        "rot": rot,
        "omega": flight["omega"],
        "force_true": flight["force"],
        "rotor_true": flight["rotor"],
        "force": force,
        "rotor": flight["rotor"] + rotor_white,
        "vel_body": np.einsum("nji,nj->ni", rot, vel_meas),
        "accel_bias": bias,
    }
