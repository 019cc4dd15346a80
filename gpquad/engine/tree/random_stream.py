"""Cheap scalar random draws for the variation operators.

numpy's Generator costs ~1-5 us per scalar call, which dominated mutation time.
RandomStream draws blocks from an explicit Generator and hands out scalars, so the
sequence is fully determined by the Generator's state (no global randomness).
A block is drawn only when the previous one is used up and a value is asked for, so the
Generator's own draws between them (the test phase's) see the same state.
"""

from __future__ import annotations

from itertools import chain

import numpy as np

BLOCK = 4096


def _blocks(draw):
    """Endless lists of BLOCK values, each drawn when it is asked for."""
    while True:
        yield draw(BLOCK).tolist()


class RandomStream:
    """Scalar uniform/normal/integer draws served from blocks of a numpy Generator.

    `random()` is the bound __next__ of an iterator over the blocks: a C call, no Python frame.
    """

    __slots__ = ("_rng", "random", "_normal")

    def __init__(self, rng: np.random.Generator):
        self._rng = rng
        #: U[0, 1)
        self.random = chain.from_iterable(_blocks(rng.random)).__next__
        self._normal = chain.from_iterable(_blocks(rng.standard_normal)).__next__

    def below(self, n: int) -> int:
        """Uniform integer in 0..n-1."""
        return min(int(self.random() * n), n - 1)

    def uniform(self, low: float, high: float) -> float:
        return low + (high - low) * self.random()

    def normal(self, sigma: float) -> float:
        """N(0, sigma^2)."""
        return sigma * self._normal()


def as_stream(rng) -> RandomStream:
    """Wrap a Generator (a RandomStream passes through)."""
    return rng if isinstance(rng, RandomStream) else RandomStream(rng)
