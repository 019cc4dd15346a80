"""Paired comparison: gpquad on exactly the test windows a diverging peer flew.

A peer that diverges on some windows is scored over the others only (`evaluate.score`), so
its RSE and gpquad's, over every window, describe different flights: on rotorpy-angle
SINDy flies the hummingbird's windows and diverges on every crazyflie window. For each
scenario, peer and horizon where the peer diverged, this scores gpquad's seeds on the
windows the peer flew. Per state, RSE = SSE / D with the same data denominator D for both
methods on the same windows, so gpquad's RSE there is the peer's RSE x SSE_gpquad /
SSE_peer, from the cells' per-window squared errors (`evaluate.window_sse`). gpquad seed s
pairs with the peer's seed s (or its one deterministic seed 0). Cells made before
per-window errors were recorded are left out.
"""

from __future__ import annotations

import numpy as np

from gpquad.models.scoring import SCORED_STATES


def _pair(ours: dict | None, theirs: dict | None) -> tuple[float, float, int] | None:
    """(gpquad mean RSE, peer mean RSE, windows) on the windows the peer flew; None when
    the peer diverged nowhere or everywhere, or a cell has no per-window errors. gpquad's
    RSE is inf if it diverged on one of those windows."""
    if not ours or not theirs or not theirs.get("diverged"):
        return None
    a, b = ours.get("window_sse"), theirs.get("window_sse")
    if a is None or b is None or len(a) != len(b):
        return None
    flown = [k for k, row in enumerate(b) if row is not None]
    if not flown:
        return None
    states = [i for i, s in enumerate(SCORED_STATES) if theirs["rse"].get(s) is not None]
    peer_rse = np.array([theirs["rse"][SCORED_STATES[i]] for i in states])
    if any(a[k] is None for k in flown):
        return float("inf"), float(peer_rse.mean()), len(flown)
    ours_sse = np.array([[a[k][i] for i in states] for k in flown]).sum(axis=0)
    peer_sse = np.array([[b[k][i] for i in states] for k in flown]).sum(axis=0)
    ratio = ours_sse / np.maximum(peer_sse, 1e-300)
    return float((peer_rse * ratio).mean()), float(peer_rse.mean()), len(flown)


def paired(cells: list[dict]) -> list[dict]:
    """[{scenario, peer, horizon, windows, flown, peer_rse, gpquad_rse: {mean, min, max, n}}]."""
    by: dict = {}
    for cell in cells:
        by.setdefault((cell["scenario"], cell["method"]), {})[cell["seed"]] = cell
    rows = []
    for (scenario, method), peer_cells in by.items():
        ours = by.get((scenario, "gpquad"))
        if method == "gpquad" or not ours:
            continue
        for h in next(iter(peer_cells.values()))["metrics"]:
            got = []
            for seed, cell in sorted(ours.items()):
                peer = peer_cells.get(seed, peer_cells.get(0))
                pair = peer and _pair(cell["metrics"].get(h), peer["metrics"].get(h))
                if pair:
                    got.append(pair)
            if got:
                ours_rse = np.array([g[0] for g in got])
                rows.append(
                    {
                        "scenario": scenario,
                        "peer": method,
                        "horizon": h,
                        "windows": ours[min(ours)]["metrics"][h]["windows"],
                        "flown": [g[2] for g in got],
                        "peer_rse": float(np.mean([g[1] for g in got])),
                        "gpquad_rse": {
                            "mean": float(ours_rse.mean()),
                            "min": float(ours_rse.min()),
                            "max": float(ours_rse.max()),
                            "n": len(got),
                        },
                    }
                )
    return rows


def paired_markdown(rows: list[dict]) -> str:
    """The rows as a Markdown table (empty string when no peer diverged)."""
    if not rows:
        return ""
    lines = [
        "| scenario | peer | horizon | windows the peer flew | peer mean RSE there "
        "| gpquad mean RSE there (min-max over seeds) |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        g = r["gpquad_rse"]
        spread = f" ({g['min']:.3g}-{g['max']:.3g})" if g["n"] > 1 and g["max"] > g["min"] else ""
        flown = sorted(set(r["flown"]))
        lines.append(
            f"| {r['scenario']} | {r['peer']} | {r['horizon']} | "
            f"{'/'.join(map(str, flown))} of {r['windows']} | {r['peer_rse']:.3g} | "
            f"{g['mean']:.3g}{spread} |"
        )
    return "\n".join(lines) + "\n"
