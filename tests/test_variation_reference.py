"""The fast variation code draws and builds exactly what the plain reference code below does
(the reference is the straightforward form of each operator: same Generator, same seed =>
the same trees, draw for draw)."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from gpquad.engine.tree.encoding import Tree, node_depth, subtree_end, tree_degree
from gpquad.engine.tree.operators import ADD, CONST, N_OPERATORS, SUB, VAR_BASE
from gpquad.engine.tree.random_stream import RandomStream
from gpquad.engine.tree.variation import (
    DEGREE_TRIES,
    VariationParams,
    macro_mutation,
    micro_mutation,
    mutate,
    mutate_population,
    random_subtree,
    random_tree,
)

BLOCK = 4096


class ReferenceStream:
    """Scalars served from blocks of BLOCK draws, each block drawn when the last is used up."""

    def __init__(self, rng):
        self.rng, self.uniform_block, self.u, self.normal_block, self.n = rng, [], 0, [], 0

    def random(self):
        if self.u == len(self.uniform_block):
            self.uniform_block, self.u = self.rng.random(BLOCK).tolist(), 0
        self.u += 1
        return self.uniform_block[self.u - 1]

    def below(self, n):
        return min(int(self.random() * n), n - 1)

    def uniform(self, low, high):
        return low + (high - low) * self.random()

    def normal(self, sigma):
        if self.n == len(self.normal_block):
            self.normal_block, self.n = self.rng.standard_normal(BLOCK).tolist(), 0
        self.n += 1
        return sigma * self.normal_block[self.n - 1]


def reference_node_depths(codes):
    depths, open_slots = [], []
    for i, c in enumerate(codes):
        d = open_slots.pop() if i else 0
        depths.append(d)
        if c < N_OPERATORS:
            open_slots.extend((d + 1, d + 1))
    return depths


def reference_degree(codes):
    stack = []
    for c in reversed(list(codes)):
        c = int(c)
        if c == CONST:
            stack.append(0)
        elif c >= VAR_BASE:
            stack.append(1)
        else:
            a, b = stack.pop(), stack.pop()
            stack.append(max(a, b) if c in (ADD, SUB) else a + b)
    return stack[0]


def reference_leaf(rng, p):
    if rng.random() < p.p_constant_leaf:
        return CONST, rng.uniform(p.const_low, p.const_high)
    if p.variables is None:
        return VAR_BASE + rng.below(p.n_variables), 0.0
    return VAR_BASE + p.variables[rng.below(len(p.variables))], 0.0


def reference_subtree(rng, p, max_depth):
    codes, values = [], []

    def grow(depth_left):
        if depth_left == 0 or rng.random() < p.p_leaf:
            c, v = reference_leaf(rng, p)
            codes.append(c)
            values.append(v)
            return
        codes.append(rng.below(N_OPERATORS))
        values.append(0.0)
        grow(depth_left - 1)
        grow(depth_left - 1)

    grow(max_depth)
    return codes, values


def reference_macro(rng, codes, values, p):
    i = rng.below(len(codes))
    depth = reference_node_depths(codes)[i]
    end = subtree_end(codes, i)
    if depth < p.max_depth and rng.random() >= p.p_leaf:
        new_op = rng.below(N_OPERATORS)
        if codes[i] < N_OPERATORS:
            return codes[:i] + [new_op] + codes[i + 1 :], values[:i] + [0.0] + values[i + 1 :]
        lc, lv = reference_subtree(rng, p, p.max_depth - depth - 1)
        rc, rv = reference_subtree(rng, p, p.max_depth - depth - 1)
        return codes[:i] + [new_op] + lc + rc + codes[end:], values[:i] + [0.0] + lv + rv + values[
            end:
        ]
    c, v = reference_leaf(rng, p)
    return codes[:i] + [c] + codes[end:], values[:i] + [v] + values[end:]


def reference_micro(rng, codes, values, p):
    i = rng.below(len(codes))
    depth = reference_node_depths(codes)[i]
    end = subtree_end(codes, i)
    new_c, new_v = reference_subtree(rng, p, p.max_depth - depth)
    return codes[:i] + new_c + codes[end:], values[:i] + new_v + values[end:]


def reference_mutate(rng, tree, p):
    parent_codes, parent_values = tree.codes.tolist(), tree.values.tolist()
    for _ in range(DEGREE_TRIES):
        mutation = reference_macro if rng.random() < 0.5 else reference_micro
        codes, values = mutation(rng, parent_codes, parent_values, p)
        if p.max_degree <= 0 or reference_degree(codes) <= p.max_degree:
            break
    else:
        codes, values = parent_codes, parent_values
    if rng.random() < p.p_const_perturb:
        slots = [i for i, c in enumerate(codes) if c == CONST]
        if slots:
            values = list(values)
            values[slots[rng.below(len(slots))]] += rng.normal(p.const_sigma)
    delays = tree.delays.tolist()
    for j in range(p.n_inputs):
        if rng.random() < p.p_delay:
            delays[j] = rng.below(p.max_delay + 1)
    return Tree.from_lists(codes, values, delays)


def params_for(draw_settings) -> VariationParams:
    max_depth, max_degree, variables, p_leaf = draw_settings
    return VariationParams(
        n_variables=13,
        n_inputs=4,
        variables=variables,
        max_depth=max_depth,
        max_degree=max_degree,
        p_leaf=p_leaf,
    )


settings_strategy = st.tuples(
    st.integers(1, 6),
    st.sampled_from([0, 1, 2, 3]),
    st.sampled_from([None, (0, 3, 9, 10, 11, 12), (4,)]),
    st.sampled_from([0.3, 0.5, 0.7]),
)


def same_tree(a: Tree, b: Tree) -> bool:
    return (
        a.codes.tolist() == b.codes.tolist()
        and a.values.tolist() == b.values.tolist()
        and a.delays.tolist() == b.delays.tolist()
    )


@settings(max_examples=60)
@given(st.integers(0, 2**32 - 1), settings_strategy)
def test_node_depth_and_degree_match_the_reference(seed, draw_settings):
    p = params_for(draw_settings)
    codes, _ = reference_subtree(ReferenceStream(np.random.default_rng(seed)), p, p.max_depth)
    depths = reference_node_depths(codes)
    assert [node_depth(codes, i) for i in range(len(codes))] == depths
    assert tree_degree(codes) == reference_degree(codes)
    assert tree_degree(np.asarray(codes)) == reference_degree(codes)


@settings(max_examples=30)
@given(st.integers(0, 2**32 - 1), st.lists(st.integers(0, 4), min_size=1, max_size=300))
def test_stream_matches_the_reference_and_leaves_the_generator_alike(seed, ops):
    fast_rng, ref_rng = np.random.default_rng(seed), np.random.default_rng(seed)
    fast, ref = RandomStream(fast_rng), ReferenceStream(ref_rng)
    for op in ops * 40:  # past a block boundary
        if op == 0:
            assert fast.random() == ref.random()
        elif op == 1:
            assert fast.below(7) == ref.below(7)
        elif op == 2:
            assert fast.normal(0.3) == ref.normal(0.3)
        elif op == 3:
            assert fast.uniform(-5.0, 5.0) == ref.uniform(-5.0, 5.0)
        else:  # the Generator's own draws in between (the test phase's)
            assert fast_rng.integers(100) == ref_rng.integers(100)
    assert fast_rng.bit_generator.state == ref_rng.bit_generator.state


@settings(max_examples=40)
@given(st.integers(0, 2**32 - 1), settings_strategy)
def test_subtrees_and_mutations_match_the_reference(seed, draw_settings):
    p = params_for(draw_settings)
    fast, ref = (
        RandomStream(np.random.default_rng(seed)),
        ReferenceStream(np.random.default_rng(seed)),
    )
    assert random_subtree(fast, p, p.max_depth) == reference_subtree(ref, p, p.max_depth)
    tree = random_tree(np.random.default_rng(seed + 1), p)
    codes, values = tree.codes.tolist(), tree.values.tolist()
    for _ in range(20):
        assert macro_mutation(fast, codes, values, p) == reference_macro(ref, codes, values, p)
        assert micro_mutation(fast, codes, values, p) == reference_micro(ref, codes, values, p)
    assert (codes, values) == (tree.codes.tolist(), tree.values.tolist())  # parent untouched
    for _ in range(60):
        child, ref_child = mutate(fast, tree, p), reference_mutate(ref, tree, p)
        assert same_tree(child, ref_child)
        assert child.codes.dtype == ref_child.codes.dtype == np.int64
        assert child.delays.dtype == ref_child.delays.dtype == np.int64
        tree = child
    assert fast.random() == ref.random()


def _packed(trees: list[Tree], width: int):
    """Evaluator.pack's rows of `trees`, `width` wide."""
    codes = np.zeros((len(trees), width), dtype=np.int64)
    values = np.zeros((len(trees), width))
    for i, t in enumerate(trees):
        codes[i, : t.size], values[i, : t.size] = t.codes, t.values
    sizes = np.array([t.size for t in trees], dtype=np.int64)
    return codes, values, sizes, np.array([t.delays for t in trees], dtype=np.int64)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), settings_strategy, st.booleans())
def test_the_population_kernel_mutates_as_the_reference(seed, draw_settings, deep):
    """mutate_population (the model phase's kernel) gives variation.mutate's mutants tree
    after tree to the bit and leaves the stream and its Generator where the reference
    leaves them, past block boundaries and with parents deeper than max_depth (a term
    insertion's), whose subtrees can outgrow a row and go to the reference."""
    p = params_for(draw_settings)
    rng = np.random.default_rng(seed + 1)
    trees = [random_tree(rng, p) for _ in range(6)]
    # best + c x, three times: deeper than max_depth allows (below such a node a subtree
    # grows without a depth limit, which only p_leaf > 1/2 ends, as the defaults' 0.7)
    if deep and p.p_leaf > 0.5:
        for _ in range(3):
            trees = [
                Tree.from_lists([ADD, *t.codes, CONST], [0.0, *t.values, 1.5], t.delays)
                for t in trees
            ]
    fast_rng, ref_rng = np.random.default_rng(seed), np.random.default_rng(seed)
    fast, ref = RandomStream(fast_rng), RandomStream(ref_rng)
    for generation in range(150):  # 900 mutations: past the 4096-draw blocks
        width = max(t.size for t in trees) + (generation % 3)  # rows as narrow as can be
        codes, values, sizes, delays = mutate_population(fast, _packed(trees, width), p)
        children = [mutate(ref, t, p) for t in trees]
        for i, child in enumerate(children):
            n = int(sizes[i])
            assert n == child.size
            assert codes[i, :n].tolist() == child.codes.tolist()
            assert values[i, :n].tolist() == child.values.tolist()
            assert delays[i].tolist() == child.delays.tolist()
            assert not codes[i, n:].any() and not values[i, n:].any()  # padded as pack pads
        trees = [c if (generation + i) % 2 else t for i, (t, c) in enumerate(zip(trees, children))]
    assert fast.random() == ref.random() and fast.normal(1.0) == ref.normal(1.0)
    assert fast_rng.bit_generator.state == ref_rng.bit_generator.state
