"""gpquad: coevolutionary genetic programming for multirotor dynamics.

One symbolic equation is discovered for each body-frame acceleration (a_x, a_y, a_z,
p_dot, q_dot, r_dot) of a vehicle by flying candidate equations through a body-frame
quaternion integrator over data windows, while test windows co-evolve.

    >>> import gpquad
    >>> model = gpquad.fit(df, seed=1)          # doctest: +SKIP
    >>> print(model)                            # doctest: +SKIP
    >>> model.score(other_flight_df)            # doctest: +SKIP

See `fit`, `read_log`, `load` and `Model`.
"""

from gpquad._version import __version__
from gpquad.api import fit, load, read_log, reference_flight
from gpquad.errors import GpquadError
from gpquad.model import EquationForms, Model
from gpquad.study.config import Config, load_config

__all__ = [
    "Config",
    "EquationForms",
    "GpquadError",
    "Model",
    "__version__",
    "fit",
    "load",
    "load_config",
    "read_log",
    "reference_flight",
]
