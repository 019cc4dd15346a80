"""A linear output-error model as one starting climber (an optional memetic step, not in
the paper).

The paper's climbers start from random trees. On a stiff closed loop (an attitude loop
q_dot = k (u_P - theta) - c q with k ~ 500) they settle in a wrong basin, such as
-12 q - 44 u_P(t-4), whose integrated error is four times that of the loop. Here one climber
starts instead from the linear model in every allowed variable, c0 + sum c_i x_i, with its
constants fitted through the integrator (Levenberg-Marquardt, with the growing horizon of
`fit_horizons` when set), cut to the `max_terms` terms that contribute most
(|c_i| x SD of x_i) so that it leaves room under the depth limit for product terms, and
re-fitted. Evolution, term insertion and the final BIC selection then add the nonlinear
terms and remove what the data do not support. No random draw is made, so runs stay reproducible.
"""

from __future__ import annotations

import numpy as np

from gpquad.engine.tree.encoding import Tree, shallow_sum, tree_depth
from gpquad.engine.tree.operators import CONST, MUL, VAR_BASE


def linear_tree(variables, coefficients, constant: float, delays) -> Tree:
    """constant + sum coefficients[k] * x_variables[k] as a shallow sum (shallow_sum)."""
    terms = [
        [(MUL, 0.0), (CONST, float(c)), (VAR_BASE + int(v), 0.0)]
        for v, c in zip(variables, coefficients, strict=True)
    ]
    prefix = shallow_sum(terms + [[(CONST, float(constant))]])
    return Tree.from_lists([c for c, _ in prefix], [v for _, v in prefix], delays)


def coefficients_of(tree: Tree, variables) -> tuple[np.ndarray, float]:
    """(c_i in the order of `variables`, constant) of a tree made by linear_tree (its
    shallow sum holds the terms in another order)."""
    codes, values = tree.codes, tree.values
    gains = {
        int(codes[k + 2]) - VAR_BASE: float(values[k + 1])
        for k in range(len(codes) - 2)
        if codes[k] == MUL and codes[k + 1] == CONST and codes[k + 2] >= VAR_BASE
    }
    constant = sum(
        float(values[k])
        for k in range(len(codes))
        if codes[k] == CONST and (k == 0 or codes[k - 1] != MUL)
    )
    return np.array([gains.get(int(v), 0.0) for v in variables]), constant


def variable_scales(arrays, variables, ranges) -> np.ndarray:
    """SD of each variable (states, then inputs) over the samples of `ranges`."""
    rows = np.concatenate([np.arange(a, b) for a, b in ranges])
    table = np.hstack([arrays.states, arrays.inputs])[rows]
    return table[:, list(variables)].std(axis=0)


#: Terms the seed keeps: 7 linear terms and a constant fill under half of a depth-5 shallow
#: sum, which leaves room for four product terms such as c q r that term insertion adds.
MAX_TERMS = 7


def linear_seed(
    variables,
    delays: np.ndarray,
    scales: np.ndarray,
    fit,
    starts,
    n_steps: int,
    max_depth: int,
    max_terms: int = MAX_TERMS,
) -> Tree | None:
    """The fitted linear climber, or None when no fit is finite.

    delays: the input delays of the seed (zeros; tap k of an input at k, gpquad.engine.taps).
    fit(tree, error, starts, n_steps) -> (tree, error) fits all constants (accepting any
    finite result when error is inf).
    """
    variables = list(variables)
    delays = np.asarray(delays, dtype=np.int64)
    full, error = fit(
        linear_tree(variables, np.zeros(len(variables)), 0.0, delays), np.inf, starts, n_steps
    )
    if not np.isfinite(error):
        return None
    coefs, constant = coefficients_of(full, variables)
    order = np.argsort(-np.abs(coefs) * scales, kind="stable")
    keep = min(len(variables), max_terms)
    while (
        keep > 1
        and tree_depth(linear_tree(variables[:keep], coefs[:keep], 0.0, delays).codes) > max_depth
    ):
        keep -= 1
    if keep == len(variables):
        return full
    chosen = sorted(order[:keep].tolist())
    cut = linear_tree([variables[k] for k in chosen], coefs[chosen], constant, delays)
    cut, cut_error = fit(cut, np.inf, starts, n_steps)
    return cut if np.isfinite(cut_error) else None
