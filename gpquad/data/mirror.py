"""A dataset's left-right mirror image: the same flights as a mirror-symmetric vehicle
would fly them reflected in its body x-z plane.

A multirotor is (nearly) symmetric left-right: reflected in the body x-z plane it is the
same vehicle (a propeller that spins clockwise on the right reflects into one that spins
counter-clockwise on the right and clockwise on the left, as built). The reflection
M = diag(1, -1, 1) of body and world frames maps

    velocity (u, v, w)        -> (u, -v, w)
    rates (p, q, r)           -> (-p, q, -r)       (a pseudo-vector: det(M) M omega)
    attitude (phi, theta, psi) -> (-phi, theta, -psi), quaternion (w, x, y, z) -> (w, -x, y, -z)
    accelerations             -> a_y, p_dot, r_dot change sign
    inputs                    -> the roll and yaw commands change sign (`flipped`)

and a model of such a vehicle must fly the mirrored flights as it flies the recorded ones.
gpquad.models.stability uses this as a test the recorded flights cannot give: an equation
such as a_z = 12.9 r w - 3.6 w (fitted to a px4-s250 log) damps w only
while r < 0.28 rad/s; the recorded flights turn right too rarely to show it, the mirrored
ones turn right as often as the recorded ones turn left.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from gpquad.engine.kernels.flight_arrays import FlightArrays
from gpquad.engine.variables import STATE_NAMES, TARGET_NAMES

#: States and accelerations that change sign in the mirror (gpquad.models.symmetry's
#: parities come from these too).
ODD_STATES = frozenset({"phi", "psi", "v", "p", "r"})
ODD_TARGETS = frozenset({"a_y", "p_dot", "r_dot"})
QUAT_SIGNS = np.array([1.0, -1.0, 1.0, -1.0])
STATE_SIGNS = np.array([-1.0 if n in ODD_STATES else 1.0 for n in STATE_NAMES])
ACC_SIGNS = np.array([-1.0 if n in ODD_TARGETS else 1.0 for n in TARGET_NAMES])
#: M R M for a row-major 3x3 rotation: the entries with exactly one y index change sign.
ROT_SIGNS = np.array([1.0, -1.0, 1.0, -1.0, 1.0, -1.0, 1.0, -1.0, 1.0])


def mirror_arrays(arrays: FlightArrays, input_names, flipped) -> FlightArrays:
    """The kernel arrays of the mirrored flights; the inputs named in `flipped` change sign
    (they are trim-subtracted, so each flips about its trim)."""
    signs = np.array([-1.0 if n in flipped else 1.0 for n in input_names])
    return FlightArrays(
        quat=np.ascontiguousarray(arrays.quat * QUAT_SIGNS),
        states=np.ascontiguousarray(arrays.states * STATE_SIGNS),
        acc=np.ascontiguousarray(arrays.acc * ACC_SIGNS),
        inputs=np.ascontiguousarray(arrays.inputs * signs),
        rot=np.ascontiguousarray(arrays.rot * ROT_SIGNS),
        dt=arrays.dt,
    )


def mirror_dataset(dataset, flipped):
    """The dataset with its flights mirrored (same ranges, names and trim)."""
    return dataclasses.replace(
        dataset, arrays=mirror_arrays(dataset.arrays, dataset.input_names, tuple(flipped))
    )
