"""The term search's screen: one Gauss-Newton step per candidate from c = 0, the candidates
that keep every term of the model taken from one shared flight.

A candidate model' + c1 t1 (+ c2 t2), model' the model as the sum of its terms
(term_search.model_terms), flies at c = 0 the trajectory of model' itself. Its Jacobian
there is model''s own columns beside one column per new constant: the sensitivity of the
flight to c_k, driven by t_k's values along that trajectory (the derivatives of the terms
by the states are multiplied by c = 0). So one sensitivity flight of
model' + sum_k c_k t_k over every distinct new term, all c_k = 0, gives every such
candidate's residuals and Jacobian: the numbers of the candidate's own flight up to
round-off (the additions come in another order). Each candidate's step then solves the
normal equations of its columns, from the Gram matrix of the whole flight's Jacobian (a
new term the model already has moves one of the two equal columns' constants); a candidate
whose columns are nearly dependent otherwise takes gradient_fit.step_from's pivoted QR.
The model's own constants that the residuals cannot tell apart are held fixed in every
candidate. A candidate that drops a term of the model to make room under the depth limit
flies alone.
"""

from __future__ import annotations

import numpy as np

from gpquad.engine.evolve.evaluator import Evaluator
from gpquad.engine.evolve.gradient_fit import (
    GRAM_FULL_RANK,
    gauss_newton_step,
    identifiable,
    residuals_and_jacobian,
    step_from,
)
from gpquad.engine.tree.encoding import Tree, shallow_sum
from gpquad.engine.tree.operators import CONST

#: |cosine| between two Jacobian columns above which they are the same column up to
#: round-off (a new term that the model already has).
SAME_COLUMN = 1.0 - 1e-15


def _tagged(term, label) -> list:
    """The prefix (code, value) list of a term with each value tagged (label, position,
    value), so that where its constants land in a sum can be read back."""
    return [(code, (label, k, value)) for k, (code, value) in enumerate(term)]


def _value(tag) -> float:
    """The value under a tag of _tagged (the sum's own nodes carry theirs untagged)."""
    return tag[2] if isinstance(tag, tuple) else tag


def _constant_tags(prefix) -> list:
    """The tag (label, position) of each constant of a tagged prefix list, in order."""
    return [tag[:2] for code, tag in prefix if code == CONST]


def screen_steps(
    ev: Evaluator, model: Tree, terms: list, candidates: list[tuple[Tree, list | None]], starts
) -> list[Tree | None]:
    """Each candidate after one Gauss-Newton step (gradient_fit.gauss_newton_step) on the
    windows `starts`, None where that gives none. candidates: (tree, new) as
    term_search.insertion_candidates makes them from `model`, whose terms
    (term_search.model_terms) are `terms`: a tree with `new` is shallow_sum(terms + new)."""
    steps: list[Tree | None] = [None] * len(candidates)
    shared = [k for k, (_, new) in enumerate(candidates) if new is not None]
    for k, (tree, new) in enumerate(candidates):
        if new is None:
            steps[k] = gauss_newton_step(ev, tree, starts, ev.n_steps)
    if not shared:
        return steps
    base = [_tagged(term, ("model", i)) for i, term in enumerate(terms)]
    added: dict[tuple, list] = {}
    for k in shared:
        for term in candidates[k][1]:
            added.setdefault(tuple(term), _tagged(term, ("new", tuple(term))))
    prefix = shallow_sum(base + list(added.values()))
    flown = Tree.from_lists(
        [code for code, _ in prefix], [_value(tag) for _, tag in prefix], model.delays
    )
    column = {tag: j for j, tag in enumerate(_constant_tags(prefix))}
    res, jac, diverged = residuals_and_jacobian(ev, flown, starts, ev.n_steps)
    if diverged:  # every candidate flies this trajectory at c = 0
        return steps
    gram, moment = jac.T @ jac, jac.T @ res
    # the model's constants the residuals cannot tell apart stay fixed, as step_from would
    # hold them in every candidate
    own = [tag for tag in column if tag[0][0] == "model"]
    held = set(own) - {own[i] for i in _free(jac, [column[tag] for tag in own])}
    for k in shared:
        tree, new = candidates[k]
        tags = _constant_tags(shallow_sum(base + [added[tuple(term)] for term in new]))
        cols = [column[tag] for tag in tags]
        free = [j for j, tag in enumerate(tags) if tag not in held]
        steps[k] = normal_step(tree, gram[np.ix_(cols, cols)], moment[cols], free)
        if steps[k] is None:
            steps[k] = step_from(tree, res, jac[:, cols])
    return steps


def _free(jac: np.ndarray, cols: list[int]) -> np.ndarray:
    """Positions in `cols` of the columns gradient_fit.identifiable keeps."""
    if not cols or not np.all(np.isfinite(jac[:, cols])):
        return np.arange(len(cols))
    return identifiable(jac[:, cols])


def normal_step(tree: Tree, gram: np.ndarray, moment: np.ndarray, free) -> Tree | None:
    """`tree` after the Gauss-Newton step in its constants `free` (positions in the prefix
    order of its constants) from its Jacobian's Gram matrix J^T J and J^T r (the normal
    equations, on unit columns). Of two columns equal up to round-off (SAME_COLUMN) the
    first one's constant moves. None unless the columns left are identifiable with room to
    spare (the condition of gradient_fit.identifiable's shortcut), where
    gradient_fit.step_from (pivoted QR) decides instead."""
    gram, moment = gram[np.ix_(free, free)], moment[free]
    if not (np.all(np.isfinite(gram)) and np.all(np.isfinite(moment))):
        return None
    norms = np.sqrt(np.diag(gram))
    if not np.all(norms > 0):
        return None
    unit = gram / np.outer(norms, norms)
    # a new term the model already has: its column is one of the model's, and only one of
    # the two moves (which one does not change the stepped equation)
    kept: list[int] = []
    for j in range(len(free)):
        if all(abs(unit[i, j]) < SAME_COLUMN for i in kept):
            kept.append(j)
    unit, moment, norms = unit[np.ix_(kept, kept)], moment[kept], norms[kept]
    eigen = np.linalg.eigvalsh(unit)
    if not eigen[0] > GRAM_FULL_RANK * eigen[-1]:
        return None
    h = -np.linalg.solve(unit, moment / norms) / norms
    values = tree.values.copy()
    values[np.flatnonzero(tree.codes == CONST)[np.asarray(free)[kept]]] += h
    return Tree(tree.codes, values, tree.delays)
