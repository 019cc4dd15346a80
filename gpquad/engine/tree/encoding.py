"""Flat prefix trees: the Tree record and structural helpers.

A tree is a prefix list of integer codes (gpquad.engine.tree.operators) with a
parallel list of constant values (used only where the code is CONST) and one
delay per control input. Depth counts edges: a single leaf has depth 0, so a
depth-5 tree has at most 63 nodes.
"""

import heapq
from dataclasses import dataclass

import numpy as np

from gpquad.engine.tree.operators import ADD, CONST, N_OPERATORS, SUB, VAR_BASE

#: The deepest tree a configuration may ask for (evolution.max_depth).
MAX_TREE_DEPTH = 8


def max_nodes(max_depth: int) -> int:
    """Node capacity of a full binary tree of the given depth."""
    return 2 ** (max_depth + 1) - 1


@dataclass(frozen=True)
class Tree:
    """One model: prefix codes (int64), constants (float64) and input delays (int64, samples)."""

    codes: np.ndarray
    values: np.ndarray
    delays: np.ndarray

    @property
    def size(self) -> int:
        return int(len(self.codes))

    @property
    def depth(self) -> int:
        return tree_depth(self.codes)

    @classmethod
    def from_lists(cls, codes, values, delays) -> "Tree":
        return cls(
            np.asarray(codes, dtype=np.int64),
            np.asarray(values, dtype=np.float64),
            np.asarray(delays, dtype=np.int64),
        )

    def padded(self, capacity: int):
        """(codes, values) padded to `capacity` for the kernels' 2-D population arrays."""
        codes = np.full(capacity, CONST, dtype=np.int64)
        values = np.zeros(capacity)
        codes[: self.size] = self.codes
        values[: self.size] = self.values
        return codes, values

    def used_inputs(self) -> set[int]:
        """Indices of the inputs that appear in the tree."""
        return {int(c) - VAR_BASE - 9 for c in self.codes if c >= VAR_BASE + 9}


def stack_rows(trees: dict[int, "Tree"], n_rows: int, min_slots: int = 0):
    """One tree per row for the kernels that take a tree per target: (codes, values, sizes,
    delays) of shapes (n_rows, M), (n_rows, M), (n_rows,), (n_rows, K). A row without a tree
    is the constant 0; delays are zero-padded to the widest tree (every input tap) or
    min_slots."""
    capacity = max([t.size for t in trees.values()] + [1])
    slots = max([min_slots] + [len(t.delays) for t in trees.values()])
    codes = np.full((n_rows, capacity), CONST, dtype=np.int64)
    values = np.zeros((n_rows, capacity))
    sizes = np.ones(n_rows, dtype=np.int64)
    delays = np.zeros((n_rows, slots), dtype=np.int64)
    for k, tree in trees.items():
        codes[k, : tree.size] = tree.codes
        values[k, : tree.size] = tree.values
        sizes[k] = tree.size
        delays[k, : len(tree.delays)] = tree.delays
    return codes, values, sizes, delays


def subtree_end(codes, start: int) -> int:
    """Index one past the subtree rooted at `start` (numba compiles it too)."""
    need = 1
    i = start
    while need:
        need += 1 if codes[i] < N_OPERATORS else -1
        i += 1
    return i


def node_depths(codes) -> list[int]:
    """Depth of every node of a prefix tree."""
    depths = []
    open_slots: list[int] = []  # depths of children still to be read
    for i, c in enumerate(codes):
        d = open_slots.pop() if i else 0
        depths.append(d)
        if c < N_OPERATORS:
            open_slots.extend((d + 1, d + 1))
    return depths


def node_depth(codes, index: int) -> int:
    """Depth of node `index` of a prefix tree, reading only the nodes before it (numba
    compiles it too)."""
    depth = 0
    right_children: list[int] = []  # depths of the right children still to be read
    for k in range(index):
        if codes[k] < N_OPERATORS:
            depth += 1
            right_children.append(depth)
        else:
            depth = right_children.pop()
    return depth


def tree_depth(codes) -> int:
    """Largest node depth."""
    return max(node_depths(codes))


def tree_degree(codes) -> int:
    """Polynomial degree of a prefix tree: a variable 1, a constant 0, + and - the larger of
    their children's, * and / the sum (a quotient counts its denominator's variables, so
    1 / x is degree 1: an upper bound that keeps the rule one of counting). Plain enough for
    numba to compile as it is (gpquad.engine.tree.mutation_kernel)."""
    stack = []
    for k in range(len(codes) - 1, -1, -1):
        c = codes[k]
        if c >= VAR_BASE:
            stack.append(1)
        elif c == CONST:
            stack.append(0)
        else:
            a = stack.pop()
            b = stack.pop()
            stack.append((a if a > b else b) if c == ADD or c == SUB else a + b)
    return stack[0]


def is_valid(codes) -> bool:
    """True when `codes` is exactly one complete prefix tree."""
    need = 1
    for c in codes:
        if need == 0:
            return False
        need += (2 if c < N_OPERATORS else 0) - 1
    return need == 0


def shallow_sum(
    terms: list[list[tuple[int, float]]], operator: int = ADD
) -> list[tuple[int, float]]:
    """Prefix (code, value) list of the sum of `terms` as the tree of ADD nodes of least
    depth: the two shallowest subtrees are joined first (ties: the earlier first), so that a
    product term (3 levels) sits higher than a constant (1 level). Under max_depth 5 that holds
    8 products, or 16 linear terms, or 4 products and 8 linear terms, where a balanced sum of
    n terms puts every term at depth ceil(log2 n) and holds 8 terms of any kind.
    operator=MUL makes a product the same way."""
    if not terms:
        raise ValueError("a sum needs at least one term")
    heap = [(tree_depth([c for c, _ in t]), k, t) for k, t in enumerate(terms)]
    heapq.heapify(heap)
    order = len(terms)
    while len(heap) > 1:
        depth_a, _, a = heapq.heappop(heap)
        depth_b, _, b = heapq.heappop(heap)
        heapq.heappush(heap, (max(depth_a, depth_b) + 1, order, [(operator, 0.0)] + a + b))
        order += 1
    return heap[0][2]
