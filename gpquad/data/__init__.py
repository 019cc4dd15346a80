"""Flight data: the Flight record, generic file reading, and the dataset the engine uses."""

from gpquad.data.dataset import Dataset, build_dataset
from gpquad.data.flight import Flight, read_flight_file

__all__ = ["Flight", "read_flight_file", "Dataset", "build_dataset"]
