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

from __future__ import annotations

from typing import TYPE_CHECKING

from gpquad._machine import pin

pin()  # before numpy loads: the same BLAS kernels on Linux x86-64 machines (gpquad._machine)

from gpquad._lazy import lazy_attributes  # noqa: E402
from gpquad._version import __version__  # noqa: E402
from gpquad.errors import GpquadError  # noqa: E402

if TYPE_CHECKING:
    from gpquad.api import fit, load, read_log, reference_flight
    from gpquad.model import EquationForms, Model
    from gpquad.study.config import Config, load_config

#: Where each public name lives: imported on first use, so that the command line and the
#: worker processes do not pay for what they never touch (pandas, sympy, the readers).
_HOMES = {
    "fit": "gpquad.api",
    "load": "gpquad.api",
    "read_log": "gpquad.api",
    "reference_flight": "gpquad.api",
    "EquationForms": "gpquad.model",
    "Model": "gpquad.model",
    "Config": "gpquad.study.config",
    "load_config": "gpquad.study.config",
}

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

__getattr__ = lazy_attributes(__name__, _HOMES)


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
