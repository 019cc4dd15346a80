"""Greedy term insertion on the best climber (an optional memetic step, not in the paper).

The hill climbers rarely build a small bilinear coupling such as 0.9 q r in p_dot: the
mutant that adds it must also get its coefficient right to be accepted. Here every
candidate `model + c x_i` and `model + c x_i x_j` (x over the states and inputs) has all
its constants re-fitted (Levenberg-Marquardt through the integrator, or the configured
fit), and the best one replaces the model when it lowers the error by more than
`min_gain` (relative). Final selection (BIC) removes what the data do not support.
"""

from __future__ import annotations

import numpy as np

from gpquad.engine.evolve.evaluator import Evaluator
from gpquad.engine.evolve.linear_seed import balanced_sum
from gpquad.engine.tree.encoding import Tree, subtree_end, tree_depth
from gpquad.engine.tree.operators import ADD, CONST, MUL, SUB, VAR_BASE


def additive_terms(codes, values, start: int = 0, sign: float = 1.0) -> list:
    """The terms of the top-level sum of a prefix tree: [(sign, codes, values)], SUB's right
    side with the opposite sign."""
    code = int(codes[start])
    if code in (ADD, SUB):
        left_end = subtree_end(codes, start + 1)
        right_sign = sign if code == ADD else -sign
        return (additive_terms(codes, values, start + 1, sign)
                + additive_terms(codes, values, left_end, right_sign))
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


def with_term_coefficients(model: Tree) -> Tree:
    """The model as a balanced sum of c_k * term_k, one constant per additive term (c_k
    starts at the term's sign; a term that is a constant or already constant * subtree keeps
    its form). A coupling written p*r, whose gain the truth has as 0.9, gets one."""
    prefix = balanced_sum(gained_terms(model))
    return Tree.from_lists([c for c, _ in prefix], [v for _, v in prefix], model.delays)


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


def term_candidates(model: Tree, variables, max_depth: int) -> list[Tree]:
    """1 * model, and model + 0 x_i, model + 0 x_i x_j and model + 0 x_i + 0 x_j for every
    allowed variable (an int n: the first n) and pair, within max_depth."""
    variables = list(range(variables)) if isinstance(variables, int) else list(variables)

    def term(*names):
        if len(names) == 1:
            return [(MUL, 0.0), (CONST, 0.0), (VAR_BASE + names[0], 0.0)]
        return [(MUL, 0.0), (CONST, 0.0), (MUL, 0.0), (VAR_BASE + names[0], 0.0),
                (VAR_BASE + names[1], 0.0)]

    additions = [[term(i)] for i in variables]
    additions += [[term(i, j)] for k, i in enumerate(variables) for j in variables[k:]]
    # Two terms at once, c1 x_i + c2 x_j: a stiff loop k (u - x) - c x improves the error only
    # with both of its terms, so one-term insertion alone never finds it.
    additions += [[term(i), term(j)] for k, i in enumerate(variables) for j in variables[k + 1:]]
    out = []
    # The whole model scaled, c * model (c starts at 1): a structure found without its gain,
    # such as u_Y - r for a rate loop 16 (u_Y - r), gets one.
    scaled = [MUL, CONST] + model.codes.tolist()
    if tree_depth(scaled) <= max_depth:
        out.append(Tree.from_lists(scaled, [0.0, 1.0] + model.values.tolist(), model.delays))
    # Every candidate is a balanced sum of the model's terms, each with its own gain, and the
    # new terms: p*r written without its 0.9 gets a coefficient, and a substitute term
    # (q*u_Y standing in for a missing q*r) can go to zero when the right term comes in.
    base = gained_terms(model)
    per_term = with_term_coefficients(model)
    if tree_depth(per_term.codes) <= max_depth and per_term.size > model.size:
        out.append(per_term)
    head = [(ADD, 0.0)] + list(zip(model.codes.tolist(), model.values.tolist(), strict=True))
    for new in additions:
        prefix = balanced_sum(base + new)
        if tree_depth([c for c, _ in prefix]) > max_depth:  # the model as it is, plus the terms
            prefix = head + (new[0] if len(new) == 1 else [(ADD, 0.0)] + new[0] + new[1])
        codes = [c for c, _ in prefix]
        if tree_depth(codes) <= max_depth:
            out.append(Tree.from_lists(codes, [v for _, v in prefix], model.delays))
    return out


def improve_terms(ev: Evaluator, model: Tree, error: float, suite, fit, n_variables: int,
                  max_depth: int, min_gain: float) -> tuple[Tree, float]:
    """Best single-term insertion (constants fitted by fit(tree, error, starts, n_steps));
    kept if its error < (1 - min_gain) * error."""
    candidates = term_candidates(model, n_variables, max_depth)
    if not candidates:
        return model, error
    errors = ev.mean_errors(candidates, suite)
    best, best_error = model, error * (1.0 - min_gain)
    for tree, err in zip(candidates, errors, strict=True):
        fitted, fitted_error = fit(tree, float(err), suite, ev.n_steps)
        if fitted_error < best_error:
            best, best_error = fitted, fitted_error
    if best is model:
        return model, error
    return best, float(best_error)


def best_index(errors: np.ndarray) -> int:
    """Index of the lowest finite error (0 if none is finite)."""
    finite = np.where(np.isfinite(errors), errors, np.inf)
    return int(np.argmin(finite))
