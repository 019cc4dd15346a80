"""A benchmark cell's peak memory: measured without a thread where the kernel keeps the
peak, so that a fit inside the block can still fork its search workers."""

import sys
import threading

import numpy as np
import pytest

from gpquad.benchmark.cells import PeakRss
from gpquad.study.workers import fork_context

linux = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc is Linux's")
resettable = pytest.mark.skipif(
    not sys.platform.startswith("linux") or not PeakRss.reset(),
    reason="this kernel does not reset the peak (/proc/self/clear_refs)",
)


def _allocate(mb: int) -> float:
    a = np.ones(mb * 1024 * 1024 // 8)
    return float(a.sum())


@resettable
def test_peak_counts_an_allocation_freed_inside_the_block():
    threads = threading.active_count()  # other tests may have left daemon threads
    with PeakRss() as memory:
        before = PeakRss._read("VmRSS:")
        _allocate(200)
        assert threading.active_count() == threads  # no sampling thread
        if threads == 1:
            assert fork_context() is not None
    assert memory.peak_mb >= before + 150


@resettable
def test_peak_is_reset_on_entry():
    _allocate(300)  # a peak before the block, freed
    peak_before = PeakRss._read("VmHWM:")
    with PeakRss() as memory:
        pass
    assert memory.peak_mb < peak_before - 250


@linux
def test_a_thread_samples_where_the_peak_cannot_be_reset(monkeypatch, tmp_path):
    monkeypatch.setattr(PeakRss, "CLEAR", str(tmp_path / "missing" / "clear_refs"))
    threads = threading.active_count()
    with PeakRss() as memory:
        assert threading.active_count() == threads + 1
        before = PeakRss._read("VmRSS:")
        a = np.ones(200 * 1024 * 1024 // 8)
        threading.Event().wait(0.2)  # the thread samples every 50 ms
        del a
    assert threading.active_count() == threads
    assert memory.peak_mb >= before + 150
