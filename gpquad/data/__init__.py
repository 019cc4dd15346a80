"""Flight data: the Flight record, generic file reading, and the dataset the engine uses.

The names below are resolved on first use (PEP 562), so that importing one of the package's
modules (a command's option table, say) does not import pandas and every reader."""

from gpquad._lazy import lazy_attributes

_NAMES = {
    "Dataset": "gpquad.data.dataset",
    "build_dataset": "gpquad.data.dataset",
    "Flight": "gpquad.data.flight",
    "read_flight_file": "gpquad.data.flight",
}

__all__ = ["Flight", "read_flight_file", "Dataset", "build_dataset"]

__getattr__ = lazy_attributes(__name__, _NAMES)
