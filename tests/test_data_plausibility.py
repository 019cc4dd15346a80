"""Checks that can fail: a generic file with time in microseconds, a quaternion stored
x, y, z, w, rates of the wrong sign, no motion, or a mis-scaled gyro is refused with one line
naming the file and field; the same file unbroken passes. Each check is fed its bad case."""

import dataclasses

import numpy as np
import pandas as pd
import pytest

from gpquad.cli.commands import main
from gpquad.data.flight import read_flight_file, write_flight_file
from gpquad.data.integration_check import integration_check
from gpquad.errors import GpquadError

INPUTS = ("u_P", "u_R", "u_Y", "u_T")


@pytest.fixture()
def flight_csv(tmp_path, short_flight):
    return write_flight_file(short_flight, tmp_path / "flight.csv")


def broken(tmp_path, flight_csv, edit):
    df = pd.read_csv(flight_csv)
    edit(df)
    path = tmp_path / "broken.csv"
    df.to_csv(path, index=False)
    return path


def xyzw(df):
    q = df[["qw", "qx", "qy", "qz"]].to_numpy()
    df[["qw", "qx", "qy", "qz"]] = q[:, [1, 2, 3, 0]]


def micro(df):
    df["t"] = df["t"] * 1e6


def flip_qr(df):
    df["q"] = -df["q"]
    df["r"] = -df["r"]


def still(df):
    for c in ("p", "q", "r", "u", "v", "w"):
        df[c] = 0.0
    for c in ("qw", "qx", "qy", "qz"):
        df[c] = df[c].iloc[0]


def frozen_inputs(df):
    for c in INPUTS:
        df[c] = 0.1


@pytest.mark.parametrize(
    "edit,field,words",
    [
        (xyzw, "qw", "x, y, z, w"),
        (micro, "t", "microseconds"),
        (flip_qr, "q", "opposite sign"),
        (still, "p", "does not move"),
        (frozen_inputs, "u_P", "never change"),
    ],
)
def test_bad_generic_files_are_refused(tmp_path, flight_csv, edit, field, words):
    path = broken(tmp_path, flight_csv, edit)
    with pytest.raises(GpquadError) as err:
        read_flight_file(path, INPUTS)
    msg = str(err.value)
    assert "\n" not in msg and str(path) in msg and f"field '{field}'" in msg and words in msg


def test_the_unbroken_file_passes(flight_csv):
    read_flight_file(flight_csv, INPUTS)


@pytest.mark.parametrize("edit", [xyzw, micro, flip_qr, still])
def test_data_check_fails_on_them(tmp_path, flight_csv, edit, capsys):
    path = broken(tmp_path, flight_csv, edit)
    assert main(["data", "check", str(path), "--plot", str(tmp_path / "c.png")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("gpquad: error:")


def test_integration_check_judges_attitude_of_a_generic_file(short_flight):
    """A gyro 30 % too large follows the quaternion (correlation 1) but the attitude it
    integrates does not: roll and pitch fail the check, which passes on the true rates."""
    good = integration_check([short_flight], 750)
    assert good.passed and good.row("phi").status == "pass" and good.row("phi").rse < 1e-6
    scaled = dataclasses.replace(short_flight, rates=short_flight.rates * 1.3, meta={})
    bad = integration_check([scaled], 750)
    assert not bad.passed
    assert bad.row("phi").status == "FAIL" and bad.row("theta").status == "FAIL"
    assert np.isfinite(bad.row("phi").rse) and bad.row("phi").rse > 0.05
