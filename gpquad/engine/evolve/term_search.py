"""Greedy term insertion on the best climber (an optional memetic step, not in the paper).

The hill climbers rarely build a small bilinear coupling such as 0.9 q r in p_dot: the
mutant that adds it must also get its coefficient right to be accepted. Here every
candidate `model + c x_i` and `model + c x_i x_j` (x over the states and inputs) is
screened by the error after one Gauss-Newton step through the integrator from c = 0 (all
of them from one shared flight, gpquad.engine.evolve.term_screen), the SCREEN_KEEP best
have all their constants re-fitted (Levenberg-Marquardt through the integrator, or the
configured fit), and the best one replaces the model when it lowers the error by more than
`min_gain` (relative). Final selection (BIC) removes what the data do not
support.
"""

from __future__ import annotations

import numpy as np

from gpquad.engine.evolve.evaluator import Evaluator
from gpquad.engine.evolve.term_screen import screen_steps
from gpquad.engine.kernels.tree_eval import eval_on_samples
from gpquad.engine.tree.encoding import Tree, shallow_sum, subtree_end, tree_depth
from gpquad.engine.tree.operators import ADD, CONST, MUL, SUB, VAR_BASE
from gpquad.engine.tree.polynomial import expand, monomial_terms

#: Term candidates fitted in full: those with the lowest error after their screening step
#: (docs/decisions/2026-11-26-term-screen.md).
SCREEN_KEEP = 16


def additive_terms(codes, values, start: int = 0, sign: float = 1.0) -> list:
    """The terms of the top-level sum of a prefix tree: [(sign, codes, values)], SUB's right
    side with the opposite sign."""
    code = int(codes[start])
    if code in (ADD, SUB):
        left_end = subtree_end(codes, start + 1)
        right_sign = sign if code == ADD else -sign
        return additive_terms(codes, values, start + 1, sign) + additive_terms(
            codes, values, left_end, right_sign
        )
    end = subtree_end(codes, start)
    return [(sign, list(codes[start:end]), list(values[start:end]))]


def gain_slot(codes) -> int | None:
    """Index of a term's own gain: the term itself if a constant, else the constant child of
    a top-level product; None if it has none."""
    if codes[0] == CONST:
        return 0
    if codes[0] == MUL:
        if codes[1] == CONST:
            return 1
        if codes[-1] == CONST and subtree_end(codes, 1) == len(codes) - 1:
            return len(codes) - 1
    return None


def model_terms(model: Tree) -> list[list[tuple[int, float]]]:
    """The model's additive terms as prefix (code, value) lists, each with its own gain: its
    monomials when it multiplies out (gpquad.engine.tree.polynomial), else its top-level
    terms (gained_terms). A climber such as (c1 u_T + c2 w) * (1 + c3 u_R^2) is then four
    terms, not one, and term insertion can exchange one of them for a missing phi^2."""
    poly = expand(model.codes, model.values)
    return monomial_terms(poly) if poly is not None else gained_terms(model)


def with_term_coefficients(model: Tree) -> Tree:
    """The model as a shallow sum of c_k * term_k, one constant per additive term of
    model_terms (a gained term's c_k starts at its sign; a term that is a constant or
    already constant * subtree keeps its form). A coupling written p*r, whose gain the truth
    has as 0.9, gets one."""
    prefix = shallow_sum(model_terms(model))
    return Tree.from_lists([c for c, _ in prefix], [v for _, v in prefix], model.delays)


def signed_terms(model: Tree) -> list[tuple]:
    """The top-level terms as sorted (sign, codes, values) tuples: two trees that only order
    their terms differently have the same."""
    return sorted(
        (sign, tuple(codes), tuple(values))
        for sign, codes, values in additive_terms(model.codes, model.values)
    )


def gained_terms(model: Tree) -> list[list[tuple[int, float]]]:
    """The model's additive terms as prefix (code, value) lists, each with its own gain."""
    terms = []
    for sign, codes, values in additive_terms(model.codes, model.values):
        gain = gain_slot(codes)
        if gain is not None:  # a constant, or constant * subtree: scale that constant
            values = list(values)
            values[gain] *= sign
            terms.append(list(zip(codes, values, strict=True)))
        else:
            terms.append([(MUL, 0.0), (CONST, sign)] + list(zip(codes, values, strict=True)))
    return terms


def regain_candidates(model: Tree, max_depth: int) -> list[Tree]:
    """The model with new gains and no new term: c * model (c starts at 1: a structure
    found without its gain, such as u_Y - r for a rate loop 16 (u_Y - r), gets one), and one
    gain per additive term (p*r written without its 0.9 gets a coefficient)."""
    out = []
    scaled = [MUL, CONST] + model.codes.tolist()
    if tree_depth(scaled) <= max_depth:
        out.append(Tree.from_lists(scaled, [0.0, 1.0] + model.values.tolist(), model.delays))
    per_term = with_term_coefficients(model)
    if tree_depth(per_term.codes) <= max_depth and signed_terms(per_term) != signed_terms(model):
        out.append(per_term)
    return out


def term_candidates(
    model: Tree, variables, max_depth: int, contributions=None, taps: dict[int, int] | None = None
) -> list[Tree]:
    """The trees of insertion_candidates (its notes)."""
    return [
        tree for tree, _ in insertion_candidates(model, variables, max_depth, contributions, taps)
    ]


def insertion_candidates(
    model: Tree, variables, max_depth: int, contributions=None, taps: dict[int, int] | None = None
) -> list[tuple[Tree, list | None]]:
    """model + 0 x_i, model + 0 x_i x_j and model + 0 x_i + 0 x_j for every allowed variable
    (an int n: the first n) and pair, within max_depth. A model too deep
    to take a new term makes room: with `contributions` (one per additive term of
    model_terms(model)), its least contributing terms are dropped until the new one fits,
    so that a substitute can be exchanged for the right term.

    taps: the extra taps of the inputs (gpquad.engine.taps), variable -> its input's
    variable. A tap enters alone (c u_R(t-k)) or beside another tap of its input (a
    difference of two delays), never in a product or beside another variable: with 8
    states and 4 inputs at 4 taps that is 192 candidates instead of 600 (one tap: 156).

    Each candidate comes as (tree, new): `new` is the list of the added terms when the tree
    is shallow_sum(model_terms(model) + new), the model's own terms kept, else None."""
    variables = list(range(variables)) if isinstance(variables, int) else list(variables)
    taps = taps or {}
    plain = [v for v in variables if v not in taps]

    def term(*names):
        if len(names) == 1:
            return [(MUL, 0.0), (CONST, 0.0), (VAR_BASE + names[0], 0.0)]
        return [
            (MUL, 0.0),
            (CONST, 0.0),
            (MUL, 0.0),
            (VAR_BASE + names[0], 0.0),
            (VAR_BASE + names[1], 0.0),
        ]

    additions = [[term(i)] for i in variables]
    additions += [[term(i, j)] for k, i in enumerate(plain) for j in plain[k:]]
    # Two terms at once, c1 x_i + c2 x_j: a stiff loop k (u - x) - c x improves the error only
    # with both of its terms, so one-term insertion alone never finds it.
    additions += [[term(i), term(j)] for k, i in enumerate(plain) for j in plain[k + 1 :]]
    additions += [
        [term(i), term(j)]
        for k, i in enumerate(variables)
        for j in variables[k + 1 :]
        if j in taps and taps[j] == taps.get(i, i)
    ]
    out = []
    base = model_terms(model)
    head = [(ADD, 0.0)] + list(zip(model.codes.tolist(), model.values.tolist(), strict=True))
    order = (
        np.argsort(contributions, kind="stable")
        if contributions is not None
        else np.zeros(0, dtype=np.int64)
    )
    for new in additions:
        prefix = shallow_sum(base + new)
        kept_all = True
        dropped = 0
        while tree_depth([c for c, _ in prefix]) > max_depth and dropped < len(order) - 1:
            dropped += 1  # exchange the least contributing terms for the new ones
            keep = sorted(order[dropped:].tolist())
            prefix = shallow_sum([base[k] for k in keep] + new)
            kept_all = False
        if tree_depth([c for c, _ in prefix]) > max_depth:  # the model as it is, plus the terms
            prefix = head + (new[0] if len(new) == 1 else [(ADD, 0.0)] + new[0] + new[1])
            kept_all = False
        codes = [c for c, _ in prefix]
        if tree_depth(codes) <= max_depth:
            tree = Tree.from_lists(codes, [v for _, v in prefix], model.delays)
            out.append((tree, new if kept_all else None))
    return out


def improve_terms(
    ev: Evaluator,
    model: Tree,
    error: float,
    suite,
    fit,
    n_variables: int,
    max_depth: int,
    min_gain: float,
    regain_fit=None,
    taps: dict[int, int] | None = None,
    allows=None,
) -> tuple[Tree, float]:
    """Best of the regain candidates and the single-term insertions (constants fitted by
    fit(tree, error, starts, n_steps); of the insertions only the SCREEN_KEEP with the
    lowest error after one Gauss-Newton step (gpquad.engine.evolve.term_screen), in their
    order of term_candidates);
    kept if its error < (1 - min_gain) * error. regain_fit (default fit) fits the
    candidates of regain_candidates: a gain that starts at 1 for a loop whose gain is 17
    sits in another basin of the long-window error, which a growing horizon leaves.
    allows(codes) -> bool filters the insertions (the degree limit)."""
    regain = regain_candidates(model, max_depth)
    offered = [
        (t, new)
        for t, new in insertion_candidates(
            model, n_variables, max_depth, term_contributions(ev, model, suite), taps
        )
        if allows is None or allows(t.codes)
    ]
    insertions = [t for t, _ in offered]
    if len(insertions) > SCREEN_KEEP:
        steps = screen_steps(ev, model, model_terms(model), offered, suite)
        stepped = {k: step for k, step in enumerate(steps) if step is not None}
        errors = np.full(len(insertions), np.inf)
        if stepped:
            errors[list(stepped)] = ev.mean_errors(list(stepped.values()), suite)
        errors[~np.isfinite(errors)] = np.inf
        kept = np.sort(np.argsort(errors, kind="stable")[:SCREEN_KEEP])
        insertions = [insertions[k] for k in kept]
    candidates = regain + insertions
    if not candidates:
        return model, error
    errors = ev.mean_errors(candidates, suite)
    best, best_error = model, error * (1.0 - min_gain)
    for k, (tree, err) in enumerate(zip(candidates, errors, strict=True)):
        use = regain_fit if (regain_fit is not None and k < len(regain)) else fit
        fitted, fitted_error = use(tree, float(err), suite, ev.n_steps)
        if fitted_error < best_error:
            best, best_error = fitted, fitted_error
    if best is model:
        return model, error
    return best, float(best_error)


def _term_values(model: Tree, terms, arrays, samples) -> list[np.ndarray]:
    """Each term's (prefix (code, value) list) values at `samples`."""
    out = []
    for term in terms:
        tree = Tree.from_lists([c for c, _ in term], [v for _, v in term], model.delays)
        codes, values, delays = tree.codes, tree.values, tree.delays
        out.append(
            eval_on_samples(codes, values, tree.size, delays, arrays.states, arrays.inputs, samples)
        )
    return out


def _rms(values: np.ndarray) -> float:
    return float(np.sqrt(np.mean(values**2))) if np.all(np.isfinite(values)) else np.inf


def term_contributions(ev: Evaluator, model: Tree, suite) -> np.ndarray:
    """RMS value of each additive term of model_terms(model) over the suite's samples."""
    samples = np.ascontiguousarray(
        (np.asarray(suite)[:, None] + np.arange(ev.n_steps)[None, :]).ravel(), dtype=np.int64
    )
    return np.array([_rms(v) for v in _term_values(model, model_terms(model), ev.arrays, samples)])


def without_small_terms(model: Tree, arrays, samples, share: float) -> Tree | None:
    """The model as a sum of its terms (model_terms) without its smallest ones, those whose
    RMS values at `samples` sum to at most `share` of the model's RMS value (by the triangle
    inequality they move it by no more); None when no term or every term would go."""
    samples = np.ascontiguousarray(samples, dtype=np.int64)
    terms = model_terms(model)
    if len(terms) < 2:
        return None
    values = _term_values(model, terms, arrays, samples)
    budget = share * _rms(np.sum(values, axis=0))
    if not np.isfinite(budget):
        return None
    sizes = [_rms(v) for v in values]
    kept = list(range(len(terms)))
    moved = 0.0
    for k in sorted(kept, key=lambda k: sizes[k]):
        if moved + sizes[k] > budget or len(kept) == 1:
            break
        kept.remove(k)
        moved += sizes[k]
    if len(kept) == len(terms):
        return None
    prefix = shallow_sum([terms[k] for k in kept])
    return Tree.from_lists([c for c, _ in prefix], [v for _, v in prefix], model.delays)


def best_index(errors: np.ndarray) -> int:
    """Index of the lowest finite error (0 if none is finite)."""
    finite = np.where(np.isfinite(errors), errors, np.inf)
    return int(np.argmin(finite))
