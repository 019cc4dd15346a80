"""Aggregate and print the fidelity of the benchmark's cells (gpquad.benchmark.fidelity).

Per scenario and method: the own-scheme and RK4 x 8 RSE of every state at every horizon
(mean over seeds, min-max), diverged windows (summed over seeds), the per-seed ratio at
FIDELITY_HORIZON (largest over p, q, r) and its worst seed, whether every seed passes
(ratio <= RATIO_LIMIT and no diverged window in either flight), and how many seeds' text
re-flown by the own scheme gives the stored score.
"""

from __future__ import annotations

from gpquad.benchmark.fidelity import (
    FIDELITY_HORIZON,
    FIDELITY_STATES,
    FLOOR_RSE,
    RATIO_LIMIT,
    _shown,
)
from gpquad.benchmark.table import _num, _stats
from gpquad.models.scoring import SCORED_STATES


def _flights(records: list[dict], which: str) -> dict:
    out = {}
    for h in records[0][which]:
        ms = [r[which][h] for r in records]
        out[h] = {
            "windows": ms[0]["windows"],
            "diverged": int(sum(m["diverged"] for m in ms)),
            "rse": {s: _stats([(m["rse"] or {}).get(s) for m in ms]) for s in SCORED_STATES},
            "mean": _stats([m["mean"] for m in ms]),
        }
    return out


def _ratio_value(x) -> float | None:
    if x is None:
        return None
    return float("inf") if x == "inf" else float(x)


def aggregate(records: list[dict]) -> dict:
    """{scenario: {method: {...}}} of fidelity records (gpquad.benchmark.fidelity.update)."""
    grouped: dict = {}
    for rec in records:
        grouped.setdefault(rec["scenario"], {}).setdefault(rec["method"], []).append(rec)
    result: dict = {}
    for scenario, methods in grouped.items():
        result[scenario] = {}
        for method, group in methods.items():
            group = sorted(group, key=lambda r: r["seed"])
            ratios = [_ratio_value(r["ratio"]) for r in group]
            own, rk4 = _flights(group, "own"), _flights(group, "rk4")
            at = group[0].get("ratio_horizon") or FIDELITY_HORIZON
            diverged_any = bool(
                (own.get(at) or {}).get("diverged") or (rk4.get(at) or {}).get("diverged")
            )
            known = [x for x in ratios if x is not None]
            result[scenario][method] = {
                "seeds": [r["seed"] for r in group],
                "ratio_horizon": at,
                "own_scheme": group[0]["own_scheme"],
                "substeps": group[0]["substeps"],
                "own": own,
                "rk4": rk4,
                "ratio_per_seed": ratios,
                "ratio_worst": max(known) if known else None,
                "passes": bool(known)
                and max(known) <= RATIO_LIMIT
                and not diverged_any
                and len(known) == len(ratios),
                "text_matches_stored": int(sum(bool(r["text_matches_stored"]) for r in group)),
            }
    return result


def _scheme(m: dict) -> str:
    s = m["own_scheme"]
    return s["integrator"] + (f" x{s['substeps']}" if s["substeps"] > 1 else "")


def markdown(agg: dict) -> str:
    """One table per scenario: method, own and RK4 x 8 RSE of p, q, r at FIDELITY_HORIZON
    (mean over seeds), the worst seed's ratio, diverged windows of each flight."""
    states = list(FIDELITY_STATES)
    lines = [
        f"RSE at {FIDELITY_HORIZON} (or the longest horizon scored, as the table's head says) "
        "of each cell's printed equations flown by the method's own "
        "scheme and by RK4 with 8 steps per sample (inputs held over the sample), mean over "
        f"seeds; ratio = max(RK4, {FLOOR_RSE:g}) / max(own, {FLOOR_RSE:g}), the largest over "
        f"{', '.join(states)}, of the worst seed (an RSE below {FLOOR_RSE:g} counts as "
        f"{FLOOR_RSE:g}: round-off on both sides gives 1); passes: every seed's ratio <= "
        f"{RATIO_LIMIT:g} and no diverged window in either flight; text = stored: seeds whose "
        "printed text, flown by the own scheme, gives the stored score.",
        "",
    ]
    for scenario, methods in agg.items():
        at = next(iter(methods.values()))["ratio_horizon"]
        head = (
            ["method (own scheme)"]
            + [f"own {s} {at}" for s in states]
            + [f"RK4x8 {s} {at}" for s in states]
            + ["ratio (worst seed)", "diverged own", "diverged RK4x8", "passes", "text = stored"]
        )
        lines += [f"### {scenario}", "", "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        for method, m in methods.items():
            own = m["own"].get(m["ratio_horizon"])
            rk4 = m["rk4"].get(m["ratio_horizon"])
            if not own or not own["windows"]:
                continue
            n = len(m["seeds"])
            cells = [f"{method} ({_scheme(m)})"]
            cells += [_num(own["rse"][s], spread=True) for s in states]
            cells += [_num(rk4["rse"][s], spread=True) for s in states]
            cells += [
                _shown(m["ratio_worst"]),
                f"{own['diverged']}/{own['windows'] * n}",
                f"{rk4['diverged']}/{rk4['windows'] * n}",
                "yes" if m["passes"] else "no",
                f"{m['text_matches_stored']}/{n}",
            ]
            lines.append("| " + " | ".join(cells) + " |")
        lines.append("")
    return "\n".join(lines)
