"""compile_program / run_program (the euler fitness kernel's tree evaluation) give the bits of
the stack interpreter eval_lanes, on random trees with every operator and protected
divisions by (near) zero."""

import numpy as np

from gpquad.engine.kernels.tree_eval import (
    STACK_ROWS,
    compile_program,
    eval_lanes,
    run_program,
)
from gpquad.engine.numba_config import python_callable
from gpquad.engine.tree.variation import VariationParams, random_tree

eval_lanes = python_callable(eval_lanes)
compile_program = python_callable(compile_program)
run_program = python_callable(run_program)


def test_program_equals_stack_interpreter():
    rng = np.random.default_rng(4)
    params = VariationParams(n_variables=13, n_inputs=4, max_depth=6)
    n = 37
    for _ in range(300):
        tree = random_tree(rng, params)
        features = rng.standard_normal((13, n))
        features[:, :5] = 0.0  # division by zero: protected
        features[:, 5:9] *= 1e-7
        stack, want = np.empty((STACK_ROWS, n)), np.empty(n)
        eval_lanes(tree.codes, tree.values, tree.size, features, stack, want, n)
        regs = np.zeros((13 + tree.size, n))
        regs[:13] = features
        prog = np.empty((tree.size, 4), dtype=np.int64)
        n_ops, root = compile_program(tree.codes, tree.values, tree.size, 13, regs, prog)
        run_program(prog, n_ops, regs, n)
        assert np.array_equal(regs[root].view(np.int64), want.view(np.int64))
