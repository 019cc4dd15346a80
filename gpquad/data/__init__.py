"""Flight data: the Flight record, generic file reading, and the dataset the engine uses.

The names below are resolved on first use (PEP 562), so that importing one of the package's
modules (a command's option table, say) does not import pandas and every reader."""

_NAMES = {
    "Dataset": "gpquad.data.dataset",
    "build_dataset": "gpquad.data.dataset",
    "Flight": "gpquad.data.flight",
    "read_flight_file": "gpquad.data.flight",
}

__all__ = ["Flight", "read_flight_file", "Dataset", "build_dataset"]


def __getattr__(name: str):
    if name not in _NAMES:
        raise AttributeError(f"module 'gpquad.data' has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(_NAMES[name]), name)
    globals()[name] = value
    return value
