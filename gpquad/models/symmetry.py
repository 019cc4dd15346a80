"""Left-right parity of the equations: terms a symmetric vehicle cannot have.

Under the left-right mirror of gpquad.data.mirror, phi, psi, v, p, r and the mirrored
inputs (`vehicle.mirror_inputs`, the roll and yaw commands) change sign, and so do a_y,
p_dot and r_dot; everything else keeps it. A left-right symmetric vehicle's a_x, a_z and
q_dot are therefore even functions of the odd variables, and its a_y, p_dot and r_dot odd
ones: a term of the wrong parity, such as 3.72 r in a_z (a heave that depends on the
direction of a yaw turn), is a term such a vehicle cannot have. It may still be real (a
payload off to one side, a constant offset of a trim that is not the vehicle's neutral),
or it may be fitted to the side of the flights the log happened to fly. `gpquad run`
lists every equation whose wrong-parity part has an RMS on the training samples of at
least PARITY_SHARE of the target's, with that share and its terms, and model.json keeps
the list (`mirror_parity`).
"""

from __future__ import annotations

import numpy as np
import sympy as sp

from gpquad.data.mirror import ODD_STATES, ODD_TARGETS
from gpquad.engine.taps import base_input
from gpquad.engine.tree.arithmetic import parse_in_symbols
from gpquad.engine.tree.export import round_constants
from gpquad.models.analysis import term_series

#: Smallest RMS share (of the target's RMS on the training samples) of a listed term.
PARITY_SHARE = 0.05


def term_parity(term: str, flipped) -> int:
    """+1 for a term the mirror leaves alone, -1 for one it negates ("1" is even)."""
    sign = 1
    for factor in sp.Mul.make_args(parse_in_symbols(term, None)):
        base, exponent = factor.as_base_exp()
        if not isinstance(base, sp.Symbol):
            continue
        name = str(base)
        odd = name in ODD_STATES or base_input(name) in flipped
        if odd and int(exponent) % 2:
            sign = -sign
    return sign


def wrong_parity(target: str, term: str, flipped) -> bool:
    """Whether `term` (a monomial's text) has the parity a symmetric vehicle's `target`
    cannot have."""
    return term_parity(term, flipped) != (-1 if target in ODD_TARGETS else 1)


def mirror_odd_terms(model, dataset, flipped, share: float = PARITY_SHARE) -> dict:
    """{target: {"share", "terms"}} for each equation whose wrong-parity part (the sum of its
    terms of the wrong parity for a left-right symmetric vehicle, trim-subtracted inputs, as
    the mirror flips them about their trims) has an RMS of at least `share` of the target's
    on the training samples. Summed, not term by term: 3.72 r - 4.06 u_Y(t-5) in a rate-mode
    a_z is two large terms whose difference, the yaw tracking error, is small. "terms" lists
    them as {term, coefficient}."""
    flipped = frozenset(flipped)
    out = {}
    for target, equation in model.equations.items():
        terms, target_rms = term_series(equation, dataset, raw=False)
        wrong = [(t, c, v) for t, c, v in terms if wrong_parity(target, t, flipped)]
        if not wrong or not target_rms > 0:
            continue
        part = np.sum([v for _, _, v in wrong], axis=0)
        part_share = float(np.sqrt(np.mean(part**2))) / target_rms
        if part_share >= share:
            shown = equation.shown_inputs()
            expr = sum(c * parse_in_symbols(t, None) for t, c, _ in wrong)
            out[target] = {
                "share": part_share,
                "terms": [{"term": t, "coefficient": c} for t, c, _ in wrong],
                "text": str(round_constants(expr, 3).xreplace(shown)),
            }
    return out


def parity_summary(found: dict, flipped) -> str:
    """One line for the user."""
    head = f"left-right parity ({', '.join(flipped)} flipped)"
    if not found:
        return (
            f"{head}: no equation has a part of the wrong parity above "
            f"{100 * PARITY_SHARE:.0f} % of its target's RMS"
        )
    parts = [
        f"{target} {100 * entry['share']:.0f} % ({entry['text']})"
        for target, entry in found.items()
    ]
    return (
        f"{head}: parts a left-right symmetric vehicle cannot have (RMS share of the "
        f"target's): {'; '.join(parts)}"
    )
