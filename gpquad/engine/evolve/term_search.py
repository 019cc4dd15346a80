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
from gpquad.engine.tree.encoding import Tree, tree_depth
from gpquad.engine.tree.operators import ADD, CONST, MUL, VAR_BASE


def term_candidates(model: Tree, variables, max_depth: int) -> list[Tree]:
    """1 * model, and model + 0 x_i, model + 0 x_i x_j and model + 0 x_i + 0 x_j for every
    allowed variable (an int n: the first n) and pair, within max_depth."""
    variables = list(range(variables)) if isinstance(variables, int) else list(variables)
    terms = [[(MUL, 0.0), (CONST, 0.0), (VAR_BASE + i, 0.0)] for i in variables]
    terms += [[(MUL, 0.0), (CONST, 0.0), (MUL, 0.0), (VAR_BASE + i, 0.0), (VAR_BASE + j, 0.0)]
              for k, i in enumerate(variables) for j in variables[k:]]
    # Two terms at once, c1 x_i + c2 x_j: a stiff loop k (u - x) - c x improves the error only
    # with both of its terms, so one-term insertion alone never finds it.
    terms += [[(ADD, 0.0), (MUL, 0.0), (CONST, 0.0), (VAR_BASE + i, 0.0), (MUL, 0.0),
               (CONST, 0.0), (VAR_BASE + j, 0.0)]
              for k, i in enumerate(variables) for j in variables[k + 1:]]
    head_codes = [ADD] + model.codes.tolist()
    head_values = [0.0] + model.values.tolist()
    out = []
    # The whole model scaled, c * model (c starts at 1): a structure found without its gain,
    # such as u_Y - r for a rate loop 16 (u_Y - r), gets one.
    scaled = [MUL, CONST] + model.codes.tolist()
    if tree_depth(scaled) <= max_depth:
        out.append(Tree.from_lists(scaled, [0.0, 1.0] + model.values.tolist(), model.delays))
    for term in terms:
        codes = head_codes + [c for c, _ in term]
        if tree_depth(codes) <= max_depth:
            out.append(Tree.from_lists(codes, head_values + [v for _, v in term], model.delays))
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
