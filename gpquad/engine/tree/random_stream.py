"""Cheap scalar random draws for the variation operators.

numpy's Generator costs ~1-5 us per scalar call, which dominated mutation time.
RandomStream draws blocks from an explicit Generator and hands out scalars, so the
sequence is fully determined by the Generator's state (no global randomness).
"""

from __future__ import annotations

import numpy as np

BLOCK = 4096


class RandomStream:
    """Scalar uniform/normal/integer draws served from blocks of a numpy Generator."""

    __slots__ = ("_rng", "_uniform", "_u", "_normal", "_n")

    def __init__(self, rng: np.random.Generator):
        self._rng = rng
        self._uniform: list[float] = []
        self._u = 0
        self._normal: list[float] = []
        self._n = 0

    def random(self) -> float:
        """U[0, 1)."""
        if self._u == len(self._uniform):
            self._uniform = self._rng.random(BLOCK).tolist()
            self._u = 0
        value = self._uniform[self._u]
        self._u += 1
        return value

    def below(self, n: int) -> int:
        """Uniform integer in 0..n-1."""
        return min(int(self.random() * n), n - 1)

    def uniform(self, low: float, high: float) -> float:
        return low + (high - low) * self.random()

    def normal(self, sigma: float) -> float:
        """N(0, sigma^2)."""
        if self._n == len(self._normal):
            self._normal = self._rng.standard_normal(BLOCK).tolist()
            self._n = 0
        value = self._normal[self._n]
        self._n += 1
        return sigma * value


def as_stream(rng) -> RandomStream:
    """Wrap a Generator (a RandomStream passes through)."""
    return rng if isinstance(rng, RandomStream) else RandomStream(rng)
