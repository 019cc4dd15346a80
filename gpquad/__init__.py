"""gpquad: coevolutionary genetic programming for multirotor dynamics.

One symbolic equation is discovered for each body-frame acceleration
(a_x, a_y, a_z, p_dot, q_dot, r_dot) of a vehicle by integrating candidate
models forward over data windows (Numba kernels) and co-evolving the windows.
"""

__version__ = "0.1.0"

from gpquad.errors import GpquadError

__all__ = ["GpquadError", "__version__"]
