"""Optional dependencies: one table of which extra provides which package, and the one-line
error a user gets on reaching a feature without it."""

from __future__ import annotations

import importlib

from gpquad.errors import GpquadError

#: Importable module -> (pip package, extra of gpquad that installs it).
EXTRAS = {
    "orangebox": ("orangebox", "betaflight"),
    "pyarrow": ("pyarrow", "parquet"),
    "statsmodels": ("statsmodels", "physics"),
    "rotorpy": ("rotorpy", "rotorpy"),
    "dask": ("dask[distributed]", "dask"),
    "cma": ("cma", "control"),
    "control": ("control", "control"),
    "pysindy": ("pysindy", "peers"),
    "pyoperon": ("pyoperon", "peers"),
    "casadi": ("casadi", "casadi"),
    "pymavlink": ("pymavlink", "ardupilot"),
}


def require(module: str, feature: str):
    """`module` imported, or a GpquadError naming the extra that installs it."""
    try:
        return importlib.import_module(module)
    except ImportError:
        top = module.split(".")[0]
        package, extra = EXTRAS.get(top, (top, None))
        how = f"pip install 'gpquad[{extra}]'" if extra else f"pip install {package}"
        raise GpquadError(
            f"{feature} needs the optional package '{package}'; install it with: {how}",
            field=extra or package,
        ) from None
