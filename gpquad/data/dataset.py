"""The dataset the engine identifies from: flights concatenated into FlightArrays.

Accelerations are the integrator's discrete inverse (gpquad.engine.kernels.integrator),
computed per flight so that no difference spans two flights. Each flight is
split by time: the first part trains, the last `validation_fraction` validates.
Test windows never span two flights or the train/validation boundary.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from gpquad.data.flight import Flight
from gpquad.engine.kernels.flight_arrays import FlightArrays
from gpquad.engine.kernels.integrator import body_accelerations, rk4_body_accelerations
from gpquad.engine.kernels.quaternion import body_rotations, euler_array
from gpquad.errors import GpquadError

#: Relative tolerance on the sample period shared by all flights.
DT_MATCH = 1e-3


@dataclass
class Dataset:
    """Concatenated flights and their index ranges (start inclusive, stop exclusive)."""

    arrays: FlightArrays
    input_names: tuple[str, ...]
    segments: list[tuple[int, int]]
    train: list[tuple[int, int]]
    validation: list[tuple[int, int]]
    names: list[str]
    trim: dict[str, float]
    #: Per flight: source, segment times, which signals are measured, pipeline steps.
    flight_info: list[dict] = field(default_factory=list)
    #: The integration check's table when one was run before identification.
    integration_check: dict | None = None
    #: FlightArrays per RK4 substep count (scheme_arrays), made once.
    _rk4_arrays: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    @property
    def dt(self) -> float:
        return self.arrays.dt

    @property
    def n_samples(self) -> int:
        return self.arrays.states.shape[0]

    def summary(self) -> dict:
        return {
            "flights": self.names,
            "samples": self.n_samples,
            "dt_s": self.dt,
            "train_samples": int(sum(b - a for a, b in self.train)),
            "validation_samples": int(sum(b - a for a, b in self.validation)),
            "trim": self.trim,
            "flight_info": self.flight_info,
            "integration_check": self.integration_check,
        }

    def scheme_arrays(self, integrator: str, substeps: int = 1) -> FlightArrays:
        """The arrays a kernel flies by `integrator`: for "rk4" the accelerations are those
        that carry the data from sample to sample under RK4 with `substeps` steps
        (gpquad.engine.kernels.integrator.rk4_body_accelerations), so that the targets a
        tree does not model follow the data as exactly as under eq. 2."""
        if integrator == "euler":
            return self.arrays
        substeps = int(substeps)
        if substeps not in self._rk4_arrays:
            acc = np.zeros_like(self.arrays.acc)
            for a, b in self.segments:
                if b - a > 1:
                    acc[a : b - 1] = rk4_body_accelerations(
                        self.arrays.states[a:b, 3:6],
                        self.arrays.states[a:b, 6:9],
                        self.dt,
                        substeps,
                    )
            self._rk4_arrays[substeps] = self.arrays._replace(acc=acc)
        return self._rk4_arrays[substeps]

    def unmeasured(self, state: str) -> list[str]:
        """Flights whose log does not measure `state` (phi, theta, psi, u, v, w, p, q, r)."""
        return [
            info["name"]
            for info in self.flight_info
            if not info.get("measured", {}).get(state, "measured").startswith("measured")
        ]


def flight_arrays(flight: Flight) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(states (N, 9), acc (N, 6), rot (N, 9)) of one flight; last acc row is 0."""
    dt = flight.dt
    quat = np.ascontiguousarray(flight.quat, dtype=float)
    vel = np.ascontiguousarray(flight.vel, dtype=float)
    rates = np.ascontiguousarray(flight.rates, dtype=float)
    states = np.hstack([euler_array(quat), vel, rates])
    acc = np.zeros((len(flight), 6))
    acc[:-1] = body_accelerations(vel, rates, dt)
    return states, acc, body_rotations(rates, dt)


def _trim(flights: list[Flight], mode: str, given: dict, input_names) -> dict[str, float]:
    if mode == "none":
        return {name: 0.0 for name in input_names}
    if mode == "mean":
        stacked = np.vstack([f.inputs for f in flights])
        return {name: float(stacked[:, i].mean()) for i, name in enumerate(input_names)}
    missing = [n for n in input_names if n not in given]
    if missing:
        raise GpquadError(
            f"data.trim = 'given' but no value for {missing}", field="data.trim_values"
        )
    return {name: float(given[name]) for name in input_names}


def build_dataset(
    flights: list[Flight],
    *,
    validation_fraction: float,
    trim: str = "none",
    trim_values: dict | None = None,
    held_out: list[bool] | None = None,
) -> Dataset:
    """Concatenate flights, compute accelerations and rotations, split train/validation.

    held_out: per flight, True = validation whole, False = training whole; None = the last
    `validation_fraction` of every flight validates.
    """
    if not flights:
        raise GpquadError("no flight data", field="data.files")
    input_names = flights[0].input_names
    dt = flights[0].dt
    for f in flights[1:]:
        if f.input_names != input_names:
            raise GpquadError(f"inputs {f.input_names} differ from {input_names}", source=f.name)
        if abs(f.dt - dt) > DT_MATCH * dt:
            raise GpquadError(
                f"sample period {f.dt:.5g} s differs from {dt:.5g} s; resample to one rate",
                source=f.name,
                field="t",
            )
    trim_map = _trim(flights, trim, trim_values or {}, input_names)
    offsets = np.array([trim_map[n] for n in input_names])
    parts = [flight_arrays(f) for f in flights]
    arrays = FlightArrays(
        quat=np.ascontiguousarray(np.vstack([f.quat for f in flights])),
        states=np.ascontiguousarray(np.vstack([p[0] for p in parts])),
        acc=np.ascontiguousarray(np.vstack([p[1] for p in parts])),
        inputs=np.ascontiguousarray(np.vstack([f.inputs for f in flights]) - offsets),
        rot=np.ascontiguousarray(np.vstack([p[2] for p in parts])),
        dt=float(dt),
    )
    segments, train, validation = [], [], []
    start = 0
    for k, f in enumerate(flights):
        stop = start + len(f)
        segments.append((start, stop))
        cut = stop - int(round(validation_fraction * len(f)))
        if held_out is not None:
            cut = start if held_out[k] else stop
        train.append((start, cut))
        if cut < stop:
            validation.append((cut, stop))
        start = stop
    return Dataset(
        arrays=arrays,
        input_names=tuple(input_names),
        segments=segments,
        train=train,
        validation=validation,
        names=[f.name for f in flights],
        trim=trim_map,
        flight_info=[_info(f) for f in flights],
    )


#: Flight.meta entries worth recording with a run (the rest are arrays).
_INFO_KEYS = (
    "source",
    "log",
    "segment",
    "t_start_s",
    "t_stop_s",
    "measured",
    "pipeline",
    "equations",
    "input_level",
)


def _info(flight: Flight) -> dict:
    info = {"name": flight.name, "samples": len(flight)}
    info.update({k: flight.meta[k] for k in _INFO_KEYS if k in flight.meta})
    return info
