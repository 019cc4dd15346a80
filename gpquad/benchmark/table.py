"""Aggregate benchmark cells: mean and spread over seeds, Markdown table and JSON.

Per scenario, method and horizon: RSE of u, v, w, p, q, r and their mean (mean over
seeds; spread = min..max over seeds), diverged windows (summed over seeds, of the
windows flown), fit time and peak memory (mean over seeds) and, where the truth is
known, how many seeds recovered each equation's exact structure. The JSON without the
"cost" entries is what `--jobs 1` and `--jobs 2` must reproduce identically.
"""

from __future__ import annotations

import numpy as np

from gpquad.engine.variables import TARGET_NAMES
from gpquad.models.scoring import SCORED_STATES


def _stats(values) -> dict | None:
    vals = [v for v in values if v is not None]
    if not vals:
        return None
    arr = np.array(vals, dtype=float)
    return {
        "mean": float(arr.mean()),
        "min": float(arr.min()),
        "max": float(arr.max()),
        "n": len(vals),
    }


def parameters(cell: dict) -> int | None:
    """A cell's fitted numbers: its n_parameters, summed over the vehicles of a per-vehicle
    scenario; None for cells that did not record it."""
    n = cell.get("n_parameters")
    if isinstance(n, dict):
        return int(sum(n.values())) if n and None not in n.values() else None
    return None if n is None else int(n)


def aggregate(cells: list[dict]) -> dict:
    """{scenario: {method: {"seeds", "horizons": {h: {...}}, "recovery", "cost"}}}."""
    out: dict = {}
    for cell in cells:
        out.setdefault(cell["scenario"], {}).setdefault(cell["method"], []).append(cell)
    result = {}
    for scenario, methods in out.items():
        result[scenario] = {}
        for method, group in methods.items():
            group = sorted(group, key=lambda c: c["seed"])
            horizons = {}
            for h in group[0]["metrics"]:
                ms = [c["metrics"][h] for c in group]
                horizons[h] = {
                    "windows": ms[0]["windows"],
                    "steps": ms[0]["steps"],
                    "diverged": int(sum(m["diverged"] for m in ms)),
                    "rse": {s: _stats([m["rse"].get(s) for m in ms]) for s in SCORED_STATES},
                    "mean": _stats([m["mean"] for m in ms]),
                }
            recovery, exact_per_seed = None, None
            if group[0].get("recovery"):
                recovery = {
                    t: int(sum(bool(c["recovery"].get(t)) for c in group))
                    for t in TARGET_NAMES
                    if t in group[0]["recovery"]
                }
                exact_per_seed = [int(sum(bool(v) for v in c["recovery"].values())) for c in group]
            result[scenario][method] = {
                "seeds": [c["seed"] for c in group],
                "version": group[0].get("version"),
                "horizons": horizons,
                "recovery": recovery,
                "exact_per_seed": exact_per_seed,
                "parameters": _stats([parameters(c) for c in group]),
                "cost": {
                    "fit_time_s": _stats([c["cost"]["fit_time_s"] for c in group]),
                    "cpu_time_s": _stats([c["cost"].get("cpu_time_s") for c in group]),
                    "peak_memory_mb": _stats([c["cost"]["peak_memory_mb"] for c in group]),
                },
            }
    return result


def fit_profile(cell: dict) -> dict[str, float] | None:
    """Where a gpquad cell's fit time went (seconds, summed over a per-vehicle cell's fits):
    "searches" (each equation's search, summed: CPU-like, they run side by side), the
    slowest search, each finishing step's wall time, the wait for the kernels' compilation
    and the finishing work begun during the searches (thread seconds, not in the steps'
    wall times); None for a cell without it."""
    profile = cell.get("fit_profile_s")
    if not profile:
        return None
    fits = [profile] if "search" in profile else list(profile.values())
    out: dict[str, float] = {"searches": 0.0, "slowest search": 0.0}
    for fit in fits:
        out["searches"] += sum(fit["search"].values())
        out["slowest search"] += max(fit["search"].values(), default=0.0)
        for step, seconds in fit["finish"].items():
            out[step] = out.get(step, 0.0) + seconds
        if "compile_wait" in fit:  # cells fitted before it was kept have none
            out["compile wait"] = out.get("compile wait", 0.0) + fit["compile_wait"]
        if fit.get("early_finish"):  # finishing work begun on a core the searches left idle
            out["early finish"] = out.get("early finish", 0.0) + fit["early_finish"]
    return out


def profile_markdown(cells: list[dict]) -> str:
    """Where gpquad's fit time went, per scenario (mean over seeds): fit wall time, the
    searches summed and the slowest, and each finishing step; empty without profiles."""
    rows: dict[str, list[dict]] = {}
    for cell in cells:
        found = fit_profile(cell) if cell["method"] == "gpquad" else None
        if found is not None:
            rows.setdefault(cell["scenario"], []).append(
                {"fit": cell["cost"]["fit_time_s"], **found}
            )
    if not rows:
        return ""
    steps = list(dict.fromkeys(k for group in rows.values() for r in group for k in r))
    lines = [
        "| scenario | " + " | ".join(f"{k} s" for k in steps) + " |",
        "|" + "---|" * (len(steps) + 1),
    ]
    for scenario, group in rows.items():
        means = [_num(_stats([r.get(k) for r in group])) for k in steps]
        lines.append(f"| {scenario} | " + " | ".join(means) + " |")
    return "\n".join(lines) + "\n"


def phase_markdown(cells: list[dict]) -> str:
    """The gpquad searches' phases per scenario (gpquad.engine.evolve.coevolution.PHASES;
    seconds summed over a fit's searches, mean over seeds); empty for cells fitted before
    the phases were kept."""
    from gpquad.engine.evolve.coevolution import PHASES, summed_phases

    rows: dict[str, list[dict]] = {}
    for cell in cells:
        profile = cell.get("fit_profile_s") if cell["method"] == "gpquad" else None
        if not profile:
            continue
        fits = [profile] if "search" in profile else list(profile.values())
        if not all(fit.get("phases") for fit in fits):
            continue
        searches = {f"{k} {t}": s for k, fit in enumerate(fits) for t, s in fit["phases"].items()}
        rows.setdefault(cell["scenario"], []).append(summed_phases(searches))
    if not rows:
        return ""
    lines = [
        "| scenario | " + " | ".join(f"{p} s" for p in PHASES) + " |",
        "|" + "---|" * (len(PHASES) + 1),
    ]
    for scenario, group in rows.items():
        means = [_num(_stats([r[p] for r in group])) for p in PHASES]
        lines.append(f"| {scenario} | " + " | ".join(means) + " |")
    return "\n".join(lines) + "\n"


def _num(stats, spread: bool = False) -> str:
    if stats is None:
        return "-"
    text = f"{stats['mean']:.3g}"
    if spread and stats["n"] > 1 and stats["max"] > stats["min"]:
        text += f" ({stats['min']:.3g}-{stats['max']:.3g})"
    return text


def summary_markdown(agg: dict) -> str:
    """One compact table of every scenario: mean RSE per horizon (mean over seeds, min-max),
    diverged windows, exact equations per seed (where the truth is known), fitted numbers
    (summed over the six equations and, per-vehicle scenarios, the vehicles) and fit time."""
    horizons = sorted(
        {h for ms in agg.values() for m in ms.values() for h in m["horizons"]},
        key=lambda h: float(h.rstrip("s")),
    )
    head = (
        ["scenario", "method"]
        + [f"mean RSE {h}" for h in horizons]
        + ["exact equations", "parameters", "fit s"]
    )
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for scenario, methods in agg.items():
        for method, m in methods.items():
            cells = [scenario, method]
            for h in horizons:
                hm = m["horizons"].get(h)
                if not hm or not hm["windows"]:
                    cells.append("")
                    continue
                text = _num(hm["mean"], spread=True)
                if hm["diverged"]:
                    text += f" ({hm['diverged']}/{hm['windows'] * len(m['seeds'])} div.)"
                cells.append(text)
            rec = "-"
            if m["recovery"]:
                n = len(m["seeds"])
                per_seed = m.get("exact_per_seed")
                rec = (
                    ", ".join(f"{k}/6" for k in per_seed)
                    if per_seed
                    else f"{sum(m['recovery'].values())}/{6 * n}"
                )
            cells += [rec, _num(m.get("parameters"), spread=True), _num(m["cost"]["fit_time_s"])]
            lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def markdown(agg: dict) -> str:
    """One table per scenario: rows method x horizon."""
    head = (
        ["method", "horizon"]
        + [f"RSE {s}" for s in SCORED_STATES]
        + ["mean RSE (min-max over seeds)", "diverged", "fit s", "peak MB", "recovered"]
    )
    lines = []
    for scenario, methods in agg.items():
        lines += [f"### {scenario}", "", "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        for method, m in methods.items():
            rec = "-"
            if m["recovery"]:
                n = len(m["seeds"])
                rec = " ".join(f"{t}:{k}/{n}" for t, k in m["recovery"].items())
            for h, hm in m["horizons"].items():
                if not hm["windows"]:
                    continue
                cells = [method, h] + [_num(hm["rse"][s]) for s in SCORED_STATES]
                cells += [
                    _num(hm["mean"], spread=True),
                    f"{hm['diverged']}/{hm['windows'] * len(m['seeds'])}",
                    _num(m["cost"]["fit_time_s"]),
                    _num(m["cost"]["peak_memory_mb"]),
                    rec,
                ]
                lines.append("| " + " | ".join(cells) + " |")
        lines.append("")
    return "\n".join(lines)


def comparable(agg: dict) -> dict:
    """The aggregate without timings and memory (identical for any --jobs)."""
    return {
        s: {m: {k: v for k, v in d.items() if k != "cost"} for m, d in ms.items()}
        for s, ms in agg.items()
    }
