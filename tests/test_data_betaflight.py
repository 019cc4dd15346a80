"""Betaflight blackbox reader on the bundled MIT/Apache fixture and the real logs."""

import dataclasses
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from gpquad.data.betaflight import read_betaflight, read_betaflight_logs, read_frames
from gpquad.data.integration_check import integration_check
from gpquad.errors import GpquadError
from gpquad.study.config import DataConfig

FIXTURE = Path(__file__).parent / "fixtures" / "btfl_001_cut.bbl"
SHARED = Path(__file__).resolve().parents[2] / "shared" / "data" / "betaflight"
needs_shared = pytest.mark.skipif(
    not SHARED.is_dir(), reason="../shared/data/betaflight is not present"
)
DATA = DataConfig(format="betaflight", segment="none", min_segment_s=2.0)


def _read_logs(path, data):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        tables, skipped = read_betaflight_logs(path, data)
    return tables, skipped, [str(w.message) for w in caught]


def test_fixture_frames_units_and_headers():
    df, headers, stop = read_frames(FIXTURE, 1)
    assert stop is None and len(df) == 98
    assert headers["Firmware revision"].startswith("Betaflight 4.2")
    assert np.all(np.diff(df["time"].to_numpy()) > 0)
    tables, skipped, warned = _read_logs(FIXTURE, DATA)
    log2 = tables[-1]
    # deg/s -> rad/s, FLU -> FRD: a resting craft's accelerometer reads -1 g on z (FRD)
    acc = log2.table[["ax", "ay", "az"]].to_numpy()
    assert np.median(np.linalg.norm(acc, axis=1)) == pytest.approx(9.81, rel=0.05)
    assert np.median(acc[:, 2]) < -8.5  # z points down: gravity's reaction is along -z
    assert np.abs(log2.table[["p", "q", "r"]].to_numpy()).max() < 1.0
    assert log2.table["throttle"].between(0.0, 1.0).all()
    assert any("header Firmware revision" in n for n in log2.notes)
    assert log2.measured["u"].startswith("not measured")


def test_truncated_log_keeps_decoded_frames_with_a_warning():
    tables, skipped, warned = _read_logs(FIXTURE, DATA)
    assert [t.name for t in tables] == ["btfl_001_cut.log1", "btfl_001_cut.log2"]
    assert any("truncated or corrupt" in w and "log 2 of 2" in w for w in warned)
    t = tables[1].table["t"].to_numpy()
    assert t[-1] - t[0] == pytest.approx(10.8, abs=0.1)


def test_fixture_flight_and_check():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        flights = read_betaflight(FIXTURE, DATA)
    assert [f.name for f in flights] == ["btfl_001_cut.log2#0"]
    (f,) = flights
    assert f.dt == pytest.approx(0.04) and len(f) == 220
    check = integration_check(flights, 750, 0.05)
    assert check.passed and check.row("w").status == "not measured"
    assert check.row("p").status == "pass"


def test_bench_log_has_no_flight_by_throttle():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(GpquadError) as err:
            read_betaflight(FIXTURE, dataclasses.replace(DATA, segment="auto"))
    msg = str(err.value)  # names the file, the field and the longest log's reason
    assert "\n" not in msg and msg.startswith(f"{FIXTURE}, field 'data.segment'")
    assert "no usable flight" in msg and "(log 2 of 2)" in msg and "0.0 s in flight" in msg


def test_log_index_selects_one_log_and_bad_index_is_an_error():
    tables, _, _ = _read_logs(FIXTURE, dataclasses.replace(DATA, log_index=1))
    assert [t.name for t in tables] == ["btfl_001_cut.log1"]
    with pytest.raises(GpquadError, match="log 5 does not exist"):
        _read_logs(FIXTURE, dataclasses.replace(DATA, log_index=5))


def test_not_a_blackbox_file(tmp_path):
    bad = tmp_path / "x.bbl"
    bad.write_bytes(b"\x00" * 1000)
    with pytest.raises(GpquadError) as err:
        read_betaflight(bad, DATA)
    assert str(bad) in str(err.value) and "\n" not in str(err.value)
    with pytest.raises(GpquadError, match="file not found"):
        read_betaflight(tmp_path / "missing.bbl", DATA)


@needs_shared
def test_multi_log_file_with_damaged_logs():
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        flights = read_betaflight(SHARED / "btfl_all.bbl", DataConfig())
    warned = [str(w.message) for w in caught]
    assert len(warned) >= 30  # 44 logs, most of them damaged: each skipped with a warning
    assert any("cannot be decoded" in w for w in warned)
    assert len(flights) >= 3
    assert integration_check(flights, 750, 0.05).passed


@needs_shared
@pytest.mark.parametrize("name", ["btfl_002.bbl", "LOG00037.BFL", "gimbal_ghost/btfl_002.bbl"])
def test_real_logs_load(name):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        flights = read_betaflight(SHARED / name, DataConfig())
    assert flights and all(np.isfinite(f.rates).all() for f in flights)
    assert all(f.dt == pytest.approx(0.04) for f in flights)


@pytest.mark.parametrize(
    "edit, field, words",
    [
        (lambda df: df.drop(columns=["gyroADC[1]"]), "gyroADC[1]", "missing field"),
        (lambda df: df.assign(**{"gyroADC[0]": df["gyroADC[0]"] * 100.0}), "gyroADC[0]", "deg/s"),
    ],
)
def test_bad_fields_are_one_line_errors_naming_the_field(edit, field, words):
    """A log without a gyro axis, or a gyro far beyond any rate a craft can reach."""
    from gpquad.data.betaflight import _log_table

    df, headers, _ = read_frames(FIXTURE, 2)
    df = df.assign(**{"gyroADC[0]": np.linspace(-300.0, 300.0, len(df))})  # |peak| 300 deg/s
    with pytest.raises(GpquadError) as err:
        _log_table(edit(df), headers, DATA, "fixture.bbl (log 2 of 2)", "x")
    msg = str(err.value)
    assert "\n" not in msg and words in msg
    assert msg.startswith("fixture.bbl (log 2 of 2), field '" + field + "'")


def test_garbage_piece_overlapping_the_clock_is_dropped(monkeypatch):
    """Damaged bytes can decode into frames whose clock re-runs a stretch of the log: the
    shorter of two pieces that overlap in time is dropped with a warning; without that check
    both would be flown as separate flights."""
    import gpquad.data.betaflight as bf

    df, headers, _ = read_frames(FIXTURE, 2)
    t = df["time"].to_numpy()
    garbage = df.iloc[100:1600].copy()  # 3 s of frames
    garbage["time"] = t[100:1600] - t[100] + t[len(t) // 2]  # the clock runs again mid-log
    damaged = pd.concat([df, garbage], ignore_index=True)
    monkeypatch.setattr(bf, "read_frames", lambda path, index: (damaged, headers, None))
    tables, skipped, warned = _read_logs(FIXTURE, dataclasses.replace(DATA, log_index=2))
    assert len(tables) == 1 and len(tables[0].table) > 0
    assert any("overlaps a longer piece" in w and "piece 1" in w for w in warned)
    assert bf._overlapping([(0, 10), (10, 14)], np.r_[np.arange(10.0), 2.0, 3.0, 4.0, 5.0]) == [1]
    assert bf._overlapping([(0, 10), (10, 14)], np.arange(14.0)) == []


@needs_shared
def test_rate_set_points_are_in_the_gyros_frame():
    """At the rates level u_R, u_P, u_Y are the set-points of p, q, r in FRD: each follows
    its own rate (correlation > 0.8 on a real flight). Left in Betaflight's FLU axes, as
    before this test, u_P and u_Y correlated with q and r at about -0.9."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        flights = read_betaflight(SHARED / "btfl_002.bbl", DataConfig())
    for f in flights:
        names = list(f.input_names)
        for rate, name in enumerate(("u_R", "u_P", "u_Y")):
            assert np.corrcoef(f.inputs[:, names.index(name)], f.rates[:, rate])[0, 1] > 0.8
