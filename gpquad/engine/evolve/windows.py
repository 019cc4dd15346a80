"""Window start positions: which data windows a test may pick, and fixed tilings.

A window of n_steps starting at s reads states s..s+n_steps, accelerations
s..s+n_steps-1 and inputs back to s - max_delay, all inside one range.
Tests live in a virtual space 0..n_valid-1 that enumerates every valid start,
so that mutation by an offset can never produce a window spanning two flights.
"""

from __future__ import annotations

import numpy as np

from gpquad.errors import GpquadError


class WindowSpace:
    """Valid window starts of a list of index ranges [start, stop)."""

    def __init__(self, ranges, n_steps: int, max_delay: int):
        lows, counts = [], []
        for a, b in ranges:
            count = (b - 1 - n_steps) - (a + max_delay) + 1
            if count > 0:
                lows.append(a + max_delay)
                counts.append(count)
        if not counts:
            longest = max((b - a for a, b in ranges), default=0)
            raise GpquadError(
                f"no training range fits a window of {n_steps} steps plus "
                f"{max_delay} delay samples (longest range: {longest} samples); "
                "lower evolution.window_s or give longer flights",
                field="evolution.window_s",
            )
        self.lows = np.array(lows, dtype=np.int64)
        self.cum = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        self.size = int(self.cum[-1])
        self.n_steps = n_steps

    def starts(self, positions) -> np.ndarray:
        """Data indices of virtual positions."""
        positions = np.asarray(positions, dtype=np.int64)
        which = np.searchsorted(self.cum, positions, side="right") - 1
        return self.lows[which] + positions - self.cum[which]

    def random(self, rng: np.random.Generator, n: int) -> np.ndarray:
        return rng.integers(0, self.size, size=n).astype(np.int64)

    def mutate(self, rng: np.random.Generator, positions, offset_max: int) -> np.ndarray:
        """Add a uniform integer offset in [-offset_max, offset_max], clipped to the space."""
        offsets = rng.integers(-offset_max, offset_max + 1, size=len(positions))
        return np.clip(np.asarray(positions) + offsets, 0, self.size - 1).astype(np.int64)


def tile(ranges, n_steps: int, max_delay: int) -> tuple[np.ndarray, int]:
    """Non-overlapping windows covering the ranges: (starts, steps).

    The step count is n_steps, or shorter when no range fits a full window.
    """
    usable = [b - 1 - (a + max_delay) for a, b in ranges]
    if not usable or max(usable) < 1:
        return np.zeros(0, dtype=np.int64), 0
    steps = min(n_steps, max(usable))
    starts = []
    for a, b in ranges:
        s = a + max_delay
        while s + steps <= b - 1:
            starts.append(s)
            s += steps
    return np.array(starts, dtype=np.int64), steps


def spread(starts: np.ndarray, n: int) -> np.ndarray:
    """At most n of `starts`, evenly spaced over them (deterministic), so that a fit on
    short windows costs a bounded number of steps whatever the flight's length."""
    starts = np.asarray(starts, dtype=np.int64)
    if n >= len(starts):
        return starts
    pick = np.unique(np.linspace(0, len(starts) - 1, max(n, 1)).round().astype(np.int64))
    return starts[pick]
