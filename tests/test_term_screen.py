"""The candidates of term insertion, as variable tuples."""

from gpquad.engine.evolve.term_screen import insertions, zero_term
from gpquad.engine.evolve.term_search import term_candidates
from gpquad.engine.tree.encoding import Tree
from gpquad.engine.tree.operators import ADD, CONST, MUL, VAR_BASE
from gpquad.engine.variables import N_STATE


def test_insertions_are_the_term_candidates_in_order():
    taps = {N_STATE + 4 + j: N_STATE + j for j in range(4)}
    every = insertions(list(range(17)), taps)
    assert len(every) == len(set(every))
    assert len(insertions(list(range(13)), {})) == 13 + 91 + 78
    model = Tree.from_lists([MUL, CONST, VAR_BASE + 6], [0.0, 2.0, 0.0], [0, 0, 0, 0])  # 2 p
    trees = term_candidates(model, 13, 5)
    for insertion, tree in zip(insertions(list(range(13)), {}), trees, strict=True):
        added = [c for term in insertion for c, _ in zero_term(term)]
        expected = [MUL, CONST, VAR_BASE + 6] + added + [ADD] * len(insertion)
        assert sorted(tree.codes.tolist()) == sorted(expected)
