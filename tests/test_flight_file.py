"""The generic flight file: validation errors, frames, and round trips."""

import dataclasses

import numpy as np
import pandas as pd
import pytest

from gpquad.data.dataset import build_dataset
from gpquad.data.flight import (
    enu_flu_quat,
    flip_body,
    flip_world,
    read_flight_file,
    write_flight_file,
)
from gpquad.engine.kernels.integrator import world_to_body
from gpquad.engine.kernels.quaternion import rotation_matrix
from gpquad.errors import GpquadError

INPUTS = ("u_P", "u_R", "u_Y", "u_T")


@pytest.fixture()
def flight_csv(tmp_path, short_flight):
    return write_flight_file(short_flight, tmp_path / "flight.csv")


def test_csv_and_parquet_round_trip(tmp_path, short_flight, flight_csv):
    back = read_flight_file(flight_csv, INPUTS)
    assert np.abs(back.vel - short_flight.vel).max() < 1e-12
    assert np.abs(back.quat - short_flight.quat).max() < 1e-12
    pq = write_flight_file(short_flight, tmp_path / "flight.parquet")
    assert np.array_equal(read_flight_file(pq, INPUTS).inputs, short_flight.inputs)


def _broken(tmp_path, flight_csv, edit):
    df = pd.read_csv(flight_csv)
    edit(df)
    path = tmp_path / "broken.csv"
    df.to_csv(path, index=False)
    return path


@pytest.mark.parametrize(
    "edit, field, message",
    [
        (lambda df: df.pop("u_T"), "u_T", "missing column"),
        (lambda df: df.loc.__setitem__((5, "p"), np.nan), "p", "NaN"),
        (lambda df: df.loc.__setitem__((10, "t"), df.loc[9, "t"]), "t", "not increasing"),
        (lambda df: df.loc.__setitem__((slice(None), "t"), df["t"] ** 1.2), "t", "not uniform"),
        (lambda df: df.loc.__setitem__((slice(None), "q"), np.degrees(df["q"]) * 10), "q", "deg/s"),
        (lambda df: [df.pop(c) for c in ("u", "v", "w")], "u", "velocity"),
        (lambda df: df.loc.__setitem__((slice(None), "qw"), 3.0), "qw", "norm"),
    ],
)
def test_bad_files_name_file_and_field(tmp_path, flight_csv, edit, field, message):
    path = _broken(tmp_path, flight_csv, edit)
    with pytest.raises(GpquadError, match=message) as info:
        read_flight_file(path, INPUTS)
    text = str(info.value)
    assert str(path) in text and f"field '{field}'" in text and "\n" not in text


def test_unknown_type_and_corrupt_file(tmp_path):
    odd = tmp_path / "flight.xyz"
    odd.write_text("hello")
    with pytest.raises(GpquadError, match="unknown file type"):
        read_flight_file(odd, INPUTS)
    bad = tmp_path / "flight.parquet"
    bad.write_bytes(b"PAR1 this is not parquet")
    with pytest.raises(GpquadError, match="cannot read"):
        read_flight_file(bad, INPUTS)


def test_world_velocity_is_rotated_into_body(tmp_path, short_flight):
    df = short_flight.to_frame()
    world = np.array([rot(q) @ v for q, v in zip(short_flight.quat, short_flight.vel)])
    df = df.drop(columns=["u", "v", "w"]).assign(vx=world[:, 0], vy=world[:, 1], vz=world[:, 2])
    path = tmp_path / "world.csv"
    df.to_csv(path, index=False)
    assert np.abs(read_flight_file(path, INPUTS).vel - short_flight.vel).max() < 1e-9


def rot(q):
    mat = np.empty((3, 3))
    rotation_matrix(*q, mat)
    return mat


def test_enu_flu_conversion_round_trip_and_physics(short_flight):
    q = short_flight.quat
    q_enu = enu_flu_quat(q)
    back = enu_flu_quat(q_enu)
    assert np.abs(np.abs(np.sum(back * q, axis=1)) - 1).max() < 1e-12  # same rotations
    # A world vector seen from the body is the same physical vector in both conventions.
    world_ned = np.tile([1.0, 2.0, 3.0], (len(q), 1))
    body_frd = world_to_body(q, world_ned)
    body_flu = world_to_body(np.ascontiguousarray(q_enu), flip_world(world_ned))
    assert np.abs(flip_body(body_flu) - body_frd).max() < 1e-12


def test_enu_file_gives_the_same_dataset(tmp_path, short_flight):
    df = short_flight.to_frame()
    q_enu = enu_flu_quat(short_flight.quat)
    df[["qw", "qx", "qy", "qz"]] = q_enu
    df[["u", "v", "w"]] = flip_body(short_flight.vel)
    df[["p", "q", "r"]] = flip_body(short_flight.rates)
    df[["x", "y", "z"]] = flip_world(short_flight.pos)
    path = tmp_path / "enu.csv"
    df.to_csv(path, index=False, float_format="%.17g")
    ned = read_flight_file(path, INPUTS, frame="ENU/FLU")
    a = build_dataset([short_flight], validation_fraction=0.1).arrays
    b = build_dataset([ned], validation_fraction=0.1).arrays
    assert np.abs(a.states - b.states).max() < 1e-9
    assert np.abs(a.acc - b.acc).max() < 1e-6


def test_two_flights_with_different_rates_are_refused(short_flight):
    other = dataclasses.replace(short_flight, t=short_flight.t * 2)
    with pytest.raises(GpquadError, match="sample period"):
        build_dataset([short_flight, other], validation_fraction=0.1)
