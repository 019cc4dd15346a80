"""The flat arrays that every kernel reads for one dataset (all flights concatenated)."""

from typing import NamedTuple

import numpy as np


class FlightArrays(NamedTuple):
    """Kernel view of a dataset; row i is sample i, flights concatenated.

    quat   : (N, 4)  body-to-world unit quaternion (w, x, y, z)
    states : (N, 9)  [phi, theta, psi, u, v, w, p, q, r], rad, m/s, rad/s
    acc    : (N, 6)  [a_x, a_y, a_z, p_dot, q_dot, r_dot] taking sample i to i+1
                     (the last row of each flight is 0 and never used)
    inputs : (N, n_inputs) trim-subtracted control inputs
    rot    : (N, 9)  R_{b_i}^{b_{i+1}} of the data rates, row-major
    dt     : float   sample period, s
    """

    quat: np.ndarray
    states: np.ndarray
    acc: np.ndarray
    inputs: np.ndarray
    rot: np.ndarray
    dt: float
