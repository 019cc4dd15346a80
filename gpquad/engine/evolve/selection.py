"""Choosing the final equation by an information criterion (not in the paper).

A fixed prune tolerance on the error scale removes terms whose share is small but real
(a gyroscopic q*r in p_dot). Here every decision compares the Bayesian information
criterion of the integrated target state,

    BIC = n log(MSE) + k log(n),

with n the number of window-steps scored and k the tree's size (one symbol per node, so
a term costs its nodes). Below the resolution the smallest terms are first tried gone
together (SMALL_TERM_SHARES), then terms are removed one by one while BIC does not grow
(training windows, constants re-fitted by least squares, which is exactly what minimises
MSE), and the final equation is the candidate (pruned best, then every climber of the
size/error front) with the lowest BIC on the validation windows.
"""

from __future__ import annotations

import itertools
import math

import numpy as np

from gpquad.engine.evolve.evaluator import Evaluator
from gpquad.engine.evolve.term_search import with_term_coefficients, without_small_terms
from gpquad.engine.threads import thread_map
from gpquad.engine.tree.encoding import Tree
from gpquad.engine.tree.polynomial import polynomial_form
from gpquad.engine.tree.variation import fold_constants, subtrees_as_constants

#: MSE floor of the criterion (an exact model on noise-free data scores ~1e-20).
MSE_FLOOR = 1e-18
#: The criterion's resolution: integrated-state errors below this share of the state's
#: standard deviation (RSE) count as zero, so that on noise-free data a term that lowers an
#: error already below it (a compensation of the scheme's discretisation) does not pay.
RSE_RESOLUTION = 1e-3
#: Before term-by-term pruning of a model already below the resolution (its MSE under the
#: floor), the smallest terms summing to these shares of its RMS value are tried gone at
#: once (first share first): the terms that only compensate a scheme go in one fit.
SMALL_TERM_SHARES = (1e-2, 1e-3)


def bic(mse: float, n: int, k: int, floor: float = MSE_FLOOR) -> float:
    """n log(max(MSE, floor)) + k log(n); inf for a non-finite MSE."""
    if not np.isfinite(mse) or n < 1:
        return math.inf
    return n * math.log(max(mse, floor)) + k * math.log(n)


def mse_floor(ev_mse: Evaluator, starts, n_steps: int) -> float:
    """The MSE below which the criterion does not look: (RSE_RESOLUTION x the standard
    deviation of the integrated target state over the windows' samples)^2, at least
    MSE_FLOOR."""
    if len(starts) == 0:
        return MSE_FLOOR
    samples = (np.asarray(starts)[:, None] + np.arange(1, n_steps + 1)[None, :]).ravel()
    states = ev_mse.arrays.states
    samples = samples[samples < len(states)]
    spread = float(np.std(states[samples, 3 + ev_mse.target])) if len(samples) else 0.0
    return max(MSE_FLOOR, (RSE_RESOLUTION * spread) ** 2)


def mse_of(ev_mse: Evaluator, tree: Tree, starts, n_steps: int) -> float:
    """Mean squared integrated-state error of `tree` on the windows (ev_mse.squared)."""
    if len(starts) == 0:
        return math.nan
    return float(ev_mse.window_errors([tree], starts, n_steps=n_steps).mean())


def prune_by_bic(
    ev_mse: Evaluator,
    model: Tree,
    starts,
    n_steps: int,
    constant_of,
    fit,
    regain_fit=None,
    threads=lambda: 1,
) -> Tree:
    """Replace subtrees by constants (largest first, constants re-fitted by
    fit(tree, mse, starts, n_steps) -> (tree, mse)) while the training BIC does not grow.
    The candidates are fitted threads() at a time side by side (asked before each batch;
    the same result for any number)."""
    n = len(starts) * n_steps
    floor = mse_floor(ev_mse, starts, n_steps)
    model = fold_constants(model)
    model, err = fit(model, mse_of(ev_mse, model, starts, n_steps), starts, n_steps)
    score = bic(err, n, model.size, floor)
    # One gain per additive term first: a coupling written p*r (truth 0.9 p r) next to a
    # substitute term gets its coefficient, and the substitute's can fall to zero and go.
    per_term = with_term_coefficients(model)
    if model.size < per_term.size <= ev_mse.capacity:  # within the depth limit's node count
        per_term, per_err = (regain_fit or fit)(
            per_term, mse_of(ev_mse, per_term, starts, n_steps), starts, n_steps
        )
        if bic(per_err, n, per_term.size, floor) < score:
            model, err, score = per_term, per_err, bic(per_err, n, per_term.size, floor)
    tried = []
    # only below the resolution: on noisy data small terms go one by one, as they always did
    for share in SMALL_TERM_SHARES if err < floor else ():
        samples = (np.asarray(starts)[:, None] + np.arange(n_steps)[None, :]).ravel()
        smaller = without_small_terms(model, ev_mse.arrays, samples, share)
        if smaller is None or smaller.codes.tolist() in tried:
            continue
        tried.append(smaller.codes.tolist())
        smaller, small_err = fit(smaller, mse_of(ev_mse, smaller, starts, n_steps), starts, n_steps)
        if bic(small_err, n, smaller.size, floor) <= score:
            model, score = smaller, bic(small_err, n, smaller.size, floor)
            break

    def fitted_one(candidate: Tree) -> tuple[Tree, float]:
        return fit(candidate, mse_of(ev_mse, candidate, starts, n_steps), starts, n_steps)

    return pruned_subtrees(
        model, score, lambda t, e: bic(e, n, t.size, floor), constant_of, fitted_one, threads
    )


def pruned_subtrees(model: Tree, score: float, score_of, constant_of, fit, threads) -> Tree:
    """`model` (its score `score`) with subtrees replaced by constants while
    score_of(tree, error) does not grow: in passes over subtrees_as_constants, the first
    candidate whose fit(candidate) -> (tree, error) scores no higher is taken. One fit per
    structure (a leaf folded into its term's gain repeats the term as a constant). The
    candidates are fitted threads() at a time side by side and judged in order, so the
    result and the fits kept are those of one by one."""
    fitted: dict[tuple, tuple[Tree, float]] = {}
    changed = True
    while changed and model.size > 1:
        changed = False
        candidates = subtrees_as_constants(model, constant_of)
        while not changed and (batch := list(itertools.islice(candidates, max(1, threads())))):
            keys = [tuple(c.codes.tolist()) for c in batch]
            new: dict[tuple, Tree] = {}  # the first candidate of each structure
            for key, candidate in zip(keys, batch, strict=True):
                if key not in fitted:
                    new.setdefault(key, candidate)
            made = dict(zip(new, thread_map(fit, list(new.values()), len(batch))))
            for key in keys:  # the fits after the one taken are not kept
                if key not in fitted:
                    fitted[key] = made[key]
                candidate, cand_err = fitted[key]
                cand_score = score_of(candidate, cand_err)
                if cand_score <= score:
                    model, score, changed = candidate, cand_score, True
                    break
    return model


def fitted_rivals(
    ev_mse: Evaluator, fit, chosen: Tree, rivals, starts, chosen_from, n_steps, workers: int = 1
) -> list[Tree]:
    """The `rivals` that could beat `chosen` on the windows `chosen_from`, each with its
    constants fitted by fit(tree, mse, starts, n_steps) on the windows `starts`; the others
    are left out unfitted. A tree of k nodes scores at least n log(floor) + k log(n)
    whatever its constants; one whose bound is not below `chosen`'s BIC cannot be chosen
    before it (select_by_bic keeps the first on ties). The fits run in up to `workers`
    threads."""
    n = len(chosen_from) * n_steps
    floor = mse_floor(ev_mse, chosen_from, n_steps)
    to_beat = bic(mse_of(ev_mse, chosen, chosen_from, n_steps), n, chosen.size, floor)
    return thread_map(
        lambda t: fit(t, mse_of(ev_mse, t, starts, n_steps), starts, n_steps)[0],
        [t for t in rivals if bic(floor, n, t.size, floor) < to_beat],
        workers,
    )


def fewest_nodes(tree: Tree) -> Tree:
    """The tree, or the same function multiplied out (gpquad.engine.tree.polynomial) when
    that takes fewer nodes: BIC counts a tree's nodes, so a linear equation grown as a deep
    tree would lose to a smaller rival of the same error that its printed form beats."""
    prefix = polynomial_form(tree.codes, tree.values)
    if prefix is None or len(prefix) >= tree.size:
        return tree
    return Tree.from_lists([c for c, _ in prefix], [v for _, v in prefix], tree.delays)


def select_by_bic(
    ev_mse: Evaluator, candidates: list[Tree], starts, n_steps: int
) -> tuple[Tree, list[float]]:
    """The candidate with the lowest BIC on the windows (first one on ties), and all BICs;
    each candidate is scored (and returned) with its fewest nodes (`fewest_nodes`)."""
    candidates = [fewest_nodes(t) for t in candidates]
    n = len(starts) * n_steps
    floor = mse_floor(ev_mse, starts, n_steps)
    scores = [bic(mse_of(ev_mse, t, starts, n_steps), n, t.size, floor) for t in candidates]
    return candidates[int(np.argmin(scores))], scores
