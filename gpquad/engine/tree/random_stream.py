"""Cheap scalar random draws for the variation operators.

numpy's Generator costs ~1-5 us per scalar call, which dominated mutation time.
RandomStream draws blocks from an explicit Generator and hands out scalars, so the
sequence is fully determined by the Generator's state (no global randomness).
A block is drawn only when the previous one is used up and a value is asked for, so the
Generator's own draws between them (the test phase's) see the same state.

The blocks are arrays with a position (`uniforms`, `u_pos`; `normals`, `n_pos`), so that a
kernel can read the same sequence (gpquad.engine.tree.mutation_kernel) and hand the
positions back; `refill_uniforms` and `refill_normals` draw the next block behind what is
left of the current one.
"""

from __future__ import annotations

import numpy as np

BLOCK = 4096
_EMPTY = np.empty(0)


class RandomStream:
    """Scalar uniform/normal/integer draws served from blocks of a numpy Generator."""

    __slots__ = ("_rng", "uniforms", "u_pos", "_u_list", "normals", "n_pos", "_n_list")

    def __init__(self, rng: np.random.Generator):
        self._rng = rng
        self.uniforms, self._u_list, self.u_pos = _EMPTY, [], 0
        self.normals, self._n_list, self.n_pos = _EMPTY, [], 0

    def refill_uniforms(self) -> None:
        """The uniform block becomes what is left of it followed by a new block."""
        rest = self.uniforms[self.u_pos :]
        self.uniforms = np.concatenate([rest, self._rng.random(BLOCK)])
        self._u_list, self.u_pos = self.uniforms.tolist(), 0

    def refill_normals(self) -> None:
        """The normal block becomes what is left of it followed by a new block."""
        rest = self.normals[self.n_pos :]
        self.normals = np.concatenate([rest, self._rng.standard_normal(BLOCK)])
        self._n_list, self.n_pos = self.normals.tolist(), 0

    def random(self) -> float:
        """U[0, 1)."""
        i = self.u_pos
        if i >= len(self._u_list):
            self.refill_uniforms()
            i = 0
        self.u_pos = i + 1
        return self._u_list[i]

    def below(self, n: int) -> int:
        """Uniform integer in 0..n-1."""
        return min(int(self.random() * n), n - 1)

    def uniform(self, low: float, high: float) -> float:
        return low + (high - low) * self.random()

    def normal(self, sigma: float) -> float:
        """N(0, sigma^2)."""
        i = self.n_pos
        if i >= len(self._n_list):
            self.refill_normals()
            i = 0
        self.n_pos = i + 1
        return sigma * self._n_list[i]


def as_stream(rng) -> RandomStream:
    """Wrap a Generator (a RandomStream passes through)."""
    return rng if isinstance(rng, RandomStream) else RandomStream(rng)
