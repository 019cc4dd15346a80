"""Variation operators of the paper (section 2.2), with explicit randomness.

Every function takes a numpy Generator or a RandomStream built on one; nothing
here draws from global state.
Trees are handled as Python lists while they change and as Tree records otherwise.
"""

from dataclasses import dataclass

import numpy as np

from gpquad.engine.taps import initial_delays
from gpquad.engine.tree import mutation_kernel as mk
from gpquad.engine.tree.encoding import Tree, max_nodes, node_depth, subtree_end, tree_degree
from gpquad.engine.tree.operators import CONST, DIV_EPS, N_OPERATORS, VAR_BASE
from gpquad.engine.tree.random_stream import RandomStream, as_stream


@dataclass(frozen=True)
class VariationParams:
    """Mutation settings; defaults are the paper's."""

    n_variables: int  # leaves that are variables: 9 states + inputs
    n_inputs: int
    #: Variable indices a new leaf may take (None: all). States a log does not measure are
    #: left out, so that no equation is fitted to a log's placeholder values.
    variables: tuple[int, ...] | None = None
    max_depth: int = 5
    p_leaf: float = 0.7
    p_constant_leaf: float = 0.25
    const_low: float = -5.0
    const_high: float = 5.0
    const_sigma: float = 0.1**0.5  # variance 0.1
    p_const_perturb: float = 0.5
    p_delay: float = 0.1
    max_delay: int = 5
    #: Taps per input (gpquad.engine.taps): n_inputs counts every tap of every input.
    taps: int = 1
    #: Highest polynomial degree of a tree (encoding.tree_degree); 0 = no limit (the paper).
    max_degree: int = 0

    def allows(self, codes) -> bool:
        """True when a structure is within the degree limit."""
        return self.max_degree <= 0 or tree_degree(codes) <= self.max_degree


#: Draws of a structural mutation (or a new tree) before the degree limit gives up and the
#: parent's structure is kept.
DEGREE_TRIES = 20


def random_leaf(rng: RandomStream, params: VariationParams):
    """(code, value) of a new leaf: a U(low, high) constant or a uniform variable."""
    if rng.random() < params.p_constant_leaf:
        return CONST, rng.uniform(params.const_low, params.const_high)
    if params.variables is None:
        return VAR_BASE + rng.below(params.n_variables), 0.0
    return VAR_BASE + params.variables[rng.below(len(params.variables))], 0.0


def random_subtree(rng, params: VariationParams, max_depth: int):
    """Grow a random subtree of depth <= max_depth; each node is a leaf with p = p_leaf.
    Nodes are drawn in prefix order (a node, then its left subtree, then its right)."""
    rng = as_stream(rng)
    random = rng.random
    p_leaf = params.p_leaf
    p_constant = params.p_constant_leaf
    low = params.const_low
    span = params.const_high - params.const_low
    variables = params.variables
    n_leaves = params.n_variables if variables is None else len(variables)
    codes: list[int] = []
    values: list[float] = []
    depths_left = [max_depth]  # the nodes still to draw, the next one last
    while depths_left:
        depth_left = depths_left.pop()
        if depth_left == 0 or random() < p_leaf:
            if random() < p_constant:
                codes.append(CONST)
                values.append(low + span * random())
                continue
            k = min(int(random() * n_leaves), n_leaves - 1)
            codes.append(VAR_BASE + (k if variables is None else variables[k]))
        else:
            codes.append(min(int(random() * N_OPERATORS), N_OPERATORS - 1))
            depths_left += (depth_left - 1, depth_left - 1)
        values.append(0.0)
    return codes, values


def random_tree(rng, params: VariationParams) -> Tree:
    """A new model: a random tree whose root is an operator when depth allows; delays 0
    (tap k of an input at delay k, gpquad.engine.taps.initial_delays)."""
    rng = as_stream(rng)
    delays = initial_delays(params.n_inputs // params.taps, params.taps, params.max_delay)
    while True:
        codes, values = random_subtree(rng, params, params.max_depth)
        if (len(codes) > 1 or params.max_depth == 0) and params.allows(codes):
            return Tree.from_lists(codes, values, delays)


def _spliced(items: list, start: int, end: int, new: list) -> list:
    """A copy of `items` with items[start:end] replaced by `new`."""
    out = items.copy()
    out[start:end] = new
    return out


def macro_mutation(rng, codes, values, params: VariationParams):
    """Replace one node by a new one, dropping or growing children as needed."""
    rng = as_stream(rng)
    i = rng.below(len(codes))
    depth = node_depth(codes, i)
    was_op = codes[i] < N_OPERATORS
    if depth < params.max_depth and rng.random() >= params.p_leaf:
        new_op = rng.below(N_OPERATORS)
        if was_op:
            new_codes = codes.copy()
            new_codes[i] = new_op
            new_values = values.copy()
            new_values[i] = 0.0
            return new_codes, new_values
        left_c, left_v = random_subtree(rng, params, params.max_depth - depth - 1)
        right_c, right_v = random_subtree(rng, params, params.max_depth - depth - 1)
        return (
            _spliced(codes, i, i + 1, [new_op, *left_c, *right_c]),
            _spliced(values, i, i + 1, [0.0, *left_v, *right_v]),
        )
    end = subtree_end(codes, i)
    c, v = random_leaf(rng, params)
    return _spliced(codes, i, end, [c]), _spliced(values, i, end, [v])


def micro_mutation(rng, codes, values, params: VariationParams):
    """Replace the subtree at one node by a newly grown subtree."""
    rng = as_stream(rng)
    i = rng.below(len(codes))
    depth = node_depth(codes, i)
    end = subtree_end(codes, i)
    new_c, new_v = random_subtree(rng, params, params.max_depth - depth)
    return _spliced(codes, i, end, new_c), _spliced(values, i, end, new_v)


def perturb_constant(rng, codes, values, sigma: float) -> list[float]:
    """Add N(0, sigma^2) to one randomly chosen constant (if there is one)."""
    slots = [i for i, c in enumerate(codes) if c == CONST]
    if not slots:
        return values
    rng = as_stream(rng)
    values = list(values)
    values[slots[rng.below(len(slots))]] += rng.normal(sigma)
    return values


def mutate(rng, tree: Tree, params: VariationParams) -> Tree:
    """The paper's mutation: macro or micro (p = 0.5 each), then constant and delay mutation.
    With params.max_degree, a structure above it is drawn again (DEGREE_TRIES times)."""
    rng = as_stream(rng)
    random = rng.random
    parent_codes = tree.codes.tolist()
    parent_values = tree.values.tolist()
    max_degree = params.max_degree
    for _ in range(DEGREE_TRIES):  # one draw unless the degree limit refuses it
        if random() < 0.5:
            codes, values = macro_mutation(rng, parent_codes, parent_values, params)
        else:
            codes, values = micro_mutation(rng, parent_codes, parent_values, params)
        if max_degree <= 0 or tree_degree(codes) <= max_degree:
            break
    else:
        codes, values = parent_codes, parent_values
    if random() < params.p_const_perturb:
        values = perturb_constant(rng, codes, values, params.const_sigma)
    delays = tree.delays  # shared with the parent unless a delay changes
    p_delay = params.p_delay
    for j in range(params.n_inputs):
        if random() < p_delay:
            if delays is tree.delays:
                delays = delays.tolist()
            delays[j] = rng.below(params.max_delay + 1)
    return Tree.from_lists(codes, values, delays)


def kernel_params(params: VariationParams):
    """(params_f, params_i, variables) of `params` for mutation_kernel.mutate_rows."""
    params_f = np.array(
        [
            params.p_leaf,
            params.p_constant_leaf,
            params.const_low,
            params.const_high,
            params.const_sigma,
            params.p_const_perturb,
            params.p_delay,
        ]
    )
    params_i = np.array(
        [
            params.max_depth,
            params.n_inputs,
            params.max_delay,
            params.max_degree,
            DEGREE_TRIES if params.max_degree > 0 else 1,
        ],
        dtype=np.int64,
    )
    variables = (
        np.arange(params.n_variables, dtype=np.int64)
        if params.variables is None
        else np.asarray(params.variables, dtype=np.int64)
    )
    return params_f, params_i, variables


def mutate_population(stream: RandomStream, packed, params: VariationParams, kernel_args=None):
    """`mutate` of every row of `packed` (codes, values, sizes, delays, as Evaluator.pack
    packs them) by gpquad.engine.tree.mutation_kernel, drawing from `stream` as `mutate`
    would tree after tree; returns the mutants packed likewise (the same bits).
    kernel_args: kernel_params(params), when the caller keeps them."""
    codes, values, sizes, delays = packed
    params_f, params_i, variables = kernel_params(params) if kernel_args is None else kernel_args
    n_rows = codes.shape[0]
    width = codes.shape[1] + max_nodes(max(params.max_depth, 0))
    out = (
        np.zeros((n_rows, width), dtype=np.int64),
        np.zeros((n_rows, width)),
        np.zeros(n_rows, dtype=np.int64),
        np.empty_like(delays),
    )
    pos = np.zeros(3, dtype=np.int64)
    row = 0
    while row < n_rows:
        pos[0], pos[1], pos[2] = stream.u_pos, stream.n_pos, mk.DONE
        row = mk.mutate_rows(
            codes,
            values,
            sizes,
            delays,
            row,
            stream.uniforms,
            stream.normals,
            pos,
            params_f,
            params_i,
            variables,
            *out,
        )
        stream.u_pos, stream.n_pos = int(pos[0]), int(pos[1])
        if pos[2] == mk.NEED_UNIFORM:
            stream.refill_uniforms()
        elif pos[2] == mk.NEED_NORMAL:
            stream.refill_normals()
        elif pos[2] == mk.OVERFLOW:  # the reference mutates this row; the rows widen to fit it
            n = int(sizes[row])
            parent = Tree(codes[row, :n], values[row, :n], delays[row])
            child = mutate(stream, parent, params)
            if child.size > out[0].shape[1]:
                grow = child.size - out[0].shape[1]
                out = (
                    np.pad(out[0], ((0, 0), (0, grow))),
                    np.pad(out[1], ((0, 0), (0, grow))),
                    out[2],
                    out[3],
                )
            out[0][row], out[1][row] = 0, 0.0  # what the stopped kernel wrote
            out[0][row, : child.size] = child.codes
            out[1][row, : child.size] = child.values
            out[2][row] = child.size
            out[3][row] = child.delays
            row += 1
    return out


def constant_mutation(rng, tree: Tree, params: VariationParams) -> Tree:
    """Gaussian perturbation of one constant only (re-convergence after simplification)."""
    values = perturb_constant(rng, tree.codes.tolist(), tree.values.tolist(), params.const_sigma)
    return Tree.from_lists(tree.codes, values, tree.delays)


def replace_with_constant(rng, tree: Tree, constant_of) -> Tree:
    """Bloat simplification: replace a random subtree by one constant.

    constant_of(start, end) gives the constant for the subtree codes[start:end]
    (for instance its mean value on the data).
    """
    codes = tree.codes.tolist()
    values = tree.values.tolist()
    i = as_stream(rng).below(len(codes))
    end = subtree_end(codes, i)
    value = float(constant_of(i, end))
    return Tree.from_lists(
        codes[:i] + [CONST] + codes[end:], values[:i] + [value] + values[end:], tree.delays
    )


def _apply(code: int, a: float, b: float) -> float:
    if code == 0:
        return a + b
    if code == 1:
        return a - b
    if code == 2:
        return a * b
    return 1.0 if abs(b) < DIV_EPS else a / b


def fold_constants(tree: Tree) -> Tree:
    """Exact simplification: an operator whose two children are constants becomes a constant.

    Uses the kernel's protected division, so the tree's values are unchanged.
    """
    codes = tree.codes.tolist()
    values = tree.values.tolist()
    changed = True
    while changed:
        changed = False
        for i in range(len(codes) - 2):
            if codes[i] < N_OPERATORS and codes[i + 1] == CONST and codes[i + 2] == CONST:
                v = _apply(codes[i], values[i + 1], values[i + 2])
                if not np.isfinite(v):
                    continue
                codes[i : i + 3] = [CONST]
                values[i : i + 3] = [v]
                changed = True
                break
    return Tree.from_lists(codes, values, tree.delays)


__all__ = [
    "VariationParams",
    "random_tree",
    "random_subtree",
    "mutate",
    "mutate_population",
    "constant_mutation",
    "macro_mutation",
    "micro_mutation",
    "replace_with_constant",
    "fold_constants",
]


def subtrees_as_constants(model: Tree, constant_of):
    """Yield `model` with one non-constant subtree replaced by constant_of(model, start, end),
    largest subtree first (the candidates of every pruning pass), each constant-folded."""
    codes = model.codes.tolist()
    values = model.values.tolist()
    spans = sorted(
        ((subtree_end(codes, i) - i, i) for i in range(1, len(codes)) if codes[i] != CONST),
        reverse=True,
    )
    for _, i in spans:
        end = subtree_end(codes, i)
        yield fold_constants(
            Tree.from_lists(
                codes[:i] + [CONST] + codes[end:],
                values[:i] + [constant_of(model, i, end)] + values[end:],
                model.delays,
            )
        )
