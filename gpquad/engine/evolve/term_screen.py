"""The candidates of term insertion (gpquad.engine.evolve.term_search): which terms it
offers, as variable tuples, and the prefix of a new term at gain 0.

Every insertion is fitted through the integrator. Two screens that fitted only the 16
ranked best were measured and not adopted (docs/decisions/2026-11-26-search-speed.md): a
one-step least-squares fit and a Gauss-Newton prediction of the integrated drop both made
betaflight-gecko's equations worse on held-out flights.
"""

from __future__ import annotations

from gpquad.engine.tree.operators import CONST, MUL, VAR_BASE

#: An insertion: its new terms, each a tuple of the variables it multiplies.
Insertion = tuple[tuple[int, ...], ...]


def insertions(variables: list[int], taps: dict[int, int]) -> list[Insertion]:
    """Every term insertion of term_candidates, in its order: x_i, x_i x_j (no taps), the
    pairs x_i + x_j (no taps), and two taps of one input."""
    plain = [v for v in variables if v not in taps]
    out: list[Insertion] = [((i,),) for i in variables]
    out += [((i, j),) for k, i in enumerate(plain) for j in plain[k:]]
    out += [((i,), (j,)) for k, i in enumerate(plain) for j in plain[k + 1 :]]
    out += [
        ((i,), (j,))
        for k, i in enumerate(variables)
        for j in variables[k + 1 :]
        if j in taps and taps[j] == taps.get(i, i)
    ]
    return out


def zero_term(variables: tuple[int, ...]) -> list[tuple[int, float]]:
    """Prefix of 0 * x_i (* x_j)."""
    if len(variables) == 1:
        return [(MUL, 0.0), (CONST, 0.0), (VAR_BASE + variables[0], 0.0)]
    return [
        (MUL, 0.0),
        (CONST, 0.0),
        (MUL, 0.0),
        (VAR_BASE + variables[0], 0.0),
        (VAR_BASE + variables[1], 0.0),
    ]
