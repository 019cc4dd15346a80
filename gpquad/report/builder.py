"""`gpquad report DIR`: the figures and tables of a finished sweep.

Reads only the sweep folder (result.json and history.csv of every run, assembly.json,
predictions.npz, models/); assembles the full models first if that was not done.
Writes into DIR/report/:

- prediction.png/.pdf: data, best model and envelope of the full models (paper Fig. 2);
- convergence.png/.pdf: error against generation per equation, across runs;
- median_model.tex/.md: the median full model's equations (paper Table 1), terms
  found in more than ``sweep.shared_fraction`` of an equation's runs in bold;
- metrics.tex/.md: RSE of u, v, w, p, q, r per horizon, diverged windows, model sizes.
"""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

import numpy as np
import sympy as sp

from gpquad.engine.tree.export import to_latex
from gpquad.engine.variables import TARGET_NAMES, TARGET_STATE
from gpquad.errors import GpquadError
from gpquad.models.equations import DiscoveredModel, Equation
from gpquad.models.model_checks import naming
from gpquad.study.assemble import load_sweep_config
from gpquad.study.assemble import reassemble as rebuild_models
from gpquad.study.store import atomic_write_text
from gpquad.study.sweep_folders import RunKey, run_dir

SCORED_STATES = ("u", "v", "w", "p", "q", "r")


# ------------------------------------------------------------------ structures
def _delayed(expr: sp.Expr, eq: Equation) -> sp.Expr:
    """Inputs renamed with their delays (u_T -> u_T(t-5)), so that delays are structure."""
    return expr.xreplace(eq.shown_inputs())


def terms(eq: Equation) -> list[tuple[str, sp.Expr]]:
    """(structure key, term) of each additive term; the key drops the numeric factor."""
    out = []
    for term in sp.Add.make_args(eq.sympy()):
        _, rest = term.as_coeff_Mul()
        key = "1" if rest == 1 else sp.sstr(_delayed(rest, eq))
        out.append((key, term))
    return out


def structure_shares(equations: list[Equation]) -> dict[str, float]:
    """Fraction of the runs whose equation contains each term structure."""
    counts = Counter()
    for eq in equations:
        counts.update({k for k, _ in terms(eq)})
    n = max(len(equations), 1)
    return {k: c / n for k, c in counts.most_common()}


def _short(key: str, width: int = 28) -> str:
    """A structure key for a table cell: long ones are cut."""
    return key if len(key) <= width else key[: width - 3] + "..."


def _equation_latex(eq: Equation, shared: set[str], digits: int = 3) -> str:
    parts = []
    for key, term in terms(eq):
        tex = to_latex(term, eq.delays, eq.leaf_names, digits)
        sign = "-" if tex.startswith("-") else "+"
        body = tex[1:].strip() if sign == "-" else tex
        if key in shared:
            body = rf"\boldsymbol{{{body}}}"
        parts.append((sign, body))
    if not parts:
        return "0"
    first_sign, first = parts[0]
    text = ("-" if first_sign == "-" else "") + first
    for sign, body in parts[1:]:
        text += f" {sign} {body}"
    return text


def median_tables(
    model: DiscoveredModel, runs: dict[str, list[Equation]], fraction: float
) -> tuple[str, str]:
    """(LaTeX, Markdown) of the median model with shared structures in bold."""
    tex_rows, md_rows = [], []
    for t in TARGET_NAMES:
        if t not in model.equations:
            continue
        eq = model.equations[t]
        shares = structure_shares(runs[t])
        shared = {k for k, s in shares.items() if s > fraction}
        body = _equation_latex(eq, shared)
        lhs = eq.latex_lhs()
        tex_rows.append(f"${lhs} = {body}$ & {eq.validation_error:.4g} \\\\")
        top = ", ".join(f"`{_short(k)}` {100 * s:.0f}%" for k, s in list(shares.items())[:4])
        md_rows.append(f"| {t} | ${lhs} = {body}$ | {eq.validation_error:.4g} | {top} |")
    n = {len(v) for v in runs.values()}
    note = (
        f"Bold: term structures (numeric factor aside, delays included) found in more than "
        f"{100 * fraction:.0f}% of the {'/'.join(map(str, sorted(n)))} runs per equation."
    )
    tex = (
        "% " + note + "\n\\begin{tabular}{ll}\n\\hline\nmedian model & validation error \\\\\n"
        "\\hline\n" + "\n".join(tex_rows) + "\n\\hline\n\\end{tabular}\n"
    )
    md = (
        "| target | median model | validation error | most shared structures (runs) |\n"
        "|---|---|---|---|\n" + "\n".join(md_rows) + f"\n\n{note}\n"
    )
    return tex, md


# --------------------------------------------------------------------- metrics
def _fmt(x) -> str:
    if x is None or (isinstance(x, float) and not np.isfinite(x)):
        return "--"
    return f"{x:.3g}"


def metrics_rows(assembly: dict) -> list[dict]:
    """One row per (horizon, model group): RSE per state and diverged windows."""
    rows = []
    fulls = assembly["full_models"]
    median = fulls[assembly["median_index"]]
    for h in assembly["best"]["metrics"]:
        for label, group in (
            ("best", [assembly["best"]]),
            ("median", [median]),
            (f"all {len(fulls)} full models", fulls),
        ):
            ms = [g["metrics"][h] for g in group]
            windows = ms[0]["windows"]
            row = {
                "horizon": h,
                "model": label,
                "windows": windows * len(ms),
                "diverged": sum(m["diverged"] for m in ms),
            }
            for s in SCORED_STATES:
                vals = np.array([m["rse"].get(s, np.nan) for m in ms], dtype=float)
                vals = vals[np.isfinite(vals)]
                if len(group) == 1:
                    row[s] = _fmt(vals[0]) if vals.size else "--"
                else:
                    row[s] = (
                        f"{np.median(vals):.3g} [{vals.min():.3g}, {vals.max():.3g}]"
                        if vals.size
                        else "--"
                    )
            rows.append(row)
    return rows


def size_rows(assembly: dict) -> list[dict]:
    fulls = assembly["full_models"]
    median = fulls[assembly["median_index"]]
    targets = list(assembly["best"]["sizes"])
    rows = []
    for t in targets:
        sizes = np.array([f["sizes"][t] for f in fulls])
        runs = np.array([r["size"] for r in assembly["runs_errors"][t]])
        val = np.array([r["validation_error"] for r in assembly["runs_errors"][t]])
        rows.append(
            {
                "target": t,
                "best": assembly["best"]["sizes"][t],
                "median": median["sizes"][t],
                "full": f"{sizes.mean():.1f} [{sizes.min()}, {sizes.max()}]",
                "runs": f"{np.median(runs):.0f} [{runs.min()}, {runs.max()}]",
                "val": f"{np.nanmedian(val):.3g} [{np.nanmin(val):.3g}, {np.nanmax(val):.3g}]",
            }
        )
    return rows


def metrics_tables(assembly: dict) -> tuple[str, str]:
    """(LaTeX, Markdown) metrics tables."""
    rows = metrics_rows(assembly)
    noise = assembly.get("input_noise_fraction", 0)
    missing = [TARGET_STATE[t] for t in TARGET_NAMES if t not in assembly["best"]["sizes"]]
    head = ["horizon", "model", *SCORED_STATES, "diverged / windows"]
    md = [
        f"RSE of the integrated states on validation windows (input noise SD = "
        f"{100 * noise:.0f}% of max input; for groups: median [min, max]). "
        "Diverged windows are left out of the RSE."
        + (
            f" Not identified in this sweep (flown with the data's accelerations): "
            f"{', '.join(missing)}."
            if missing
            else ""
        ),
        "",
        "| " + " | ".join(head) + " |",
        "|" + "---|" * len(head),
    ]
    tex = [
        "\\begin{tabular}{ll" + "r" * (len(SCORED_STATES) + 1) + "}",
        "\\hline",
        " & ".join(head) + " \\\\",
        "\\hline",
    ]
    for r in rows:
        cells = [
            r["horizon"],
            r["model"],
            *[r[s] for s in SCORED_STATES],
            f"{r['diverged']} / {r['windows']}",
        ]
        md.append("| " + " | ".join(cells) + " |")
        tex.append(" & ".join(c.replace("%", "\\%") for c in cells) + " \\\\")
    tex += ["\\hline", "\\end{tabular}", ""]
    sizes = size_rows(assembly)
    md += [
        "",
        "Model sizes (tree nodes) and run validation errors (median [min, max]).",
        "",
        "| target | best | median model | full models | all runs | run validation error |",
        "|---|---|---|---|---|---|",
    ]
    tex += [
        "\\begin{tabular}{lrrlll}",
        "\\hline",
        "target & best & median & full models & all runs & run validation error \\\\",
        "\\hline",
    ]
    for r in sizes:
        cells = [
            r["target"].replace("_", "\\_"),
            str(r["best"]),
            str(r["median"]),
            r["full"],
            r["runs"],
            r["val"],
        ]
        md.append("| " + " | ".join([r["target"]] + cells[1:]) + " |")
        tex.append(" & ".join(cells) + " \\\\")
    tex += ["\\hline", "\\end{tabular}", ""]
    return "\n".join(tex), "\n".join(md) + "\n"


# ---------------------------------------------------------------------- report
def make_report(folder, reassemble: bool = False, formats=("png", "pdf")) -> list[Path]:
    """Write every figure and table of a sweep folder; returns the paths written."""
    from gpquad.report import plotting

    folder = Path(folder)
    if not (folder / "sweep.json").exists():
        if (folder / "model.json").exists() and (folder / "history.csv").exists():
            return make_run_report(folder, formats)
        raise GpquadError(
            "not a sweep folder (no sweep.json) nor a run folder (no model.json); "
            "give the --out of a sweep or a run",
            source=str(folder),
        )
    with naming(folder / "sweep.json"):
        info = json.loads((folder / "sweep.json").read_text())
        int(info["runs"])
    if reassemble or not (folder / "assembly.json").exists():
        rebuild_models(folder)
    cfg = load_sweep_config(folder)
    with naming(folder / "assembly.json"):
        assembly = json.loads((folder / "assembly.json").read_text())
        if not isinstance(assembly, dict):
            raise ValueError("not an object")
    median = DiscoveredModel.load(folder / "models" / "median")
    out = folder / "report"
    written: list[Path] = []
    runs: dict[str, list[Equation]] = {}
    histories: dict[str, list[Path]] = {}
    for t in median.equations:
        runs[t], histories[t] = [], []
        for k in range(int(info["runs"])):
            d = run_dir(folder, RunKey(t, k))
            with naming(d / "result.json"):
                res = json.loads((d / "result.json").read_text())
                runs[t].append(
                    Equation.from_dict(t, res["equation"], median.input_names, median.trim)
                )
            histories[t].append(d / "history.csv")
    if (folder / "predictions.npz").exists():
        written += plotting.prediction_figure(
            folder / "predictions.npz", out / "prediction", formats
        )
    written += plotting.convergence_figure(
        histories, out / "convergence", cfg.evolution.metric, formats
    )
    tex, md = median_tables(median, runs, cfg.sweep.shared_fraction)
    written += [
        atomic_write_text(out / "median_model.tex", tex),
        atomic_write_text(out / "median_model.md", md),
    ]
    tex, md = metrics_tables(assembly)
    written += [
        atomic_write_text(out / "metrics.tex", tex),
        atomic_write_text(out / "metrics.md", md),
    ]
    return written


def convergence_report(folder, targets, metric: str, formats=("png", "pdf")) -> list[Path]:
    """The convergence figure of a `gpquad run` folder (FOLDER/report/convergence): best
    suite error against generation for each of `targets`, from its history.csv, complete
    once the searches are (so it may be drawn while the model is finished)."""
    from gpquad.report import plotting

    folder = Path(folder)
    return plotting.convergence_figure(
        {t: [folder / "history.csv"] for t in targets},
        folder / "report" / "convergence",
        metric,
        formats,
    )


def make_run_report(
    folder, formats=("png", "pdf"), window_s: float = 7.0, dataset=None
) -> list[Path]:
    """Figures of one `gpquad run` folder, written into FOLDER/report/; `dataset`: the run's
    data when the caller has it loaded (else it is loaded from the folder's config).

    prediction: the run's equations flown over the first validation window of `window_s`
    (states without an equation use the data's accelerations); convergence: best suite
    error against generation for each equation (`convergence_report`).
    """
    import io

    from gpquad.data.io import load_dataset
    from gpquad.engine.evolve.windows import tile
    from gpquad.engine.variables import STATE_NAMES
    from gpquad.report import plotting
    from gpquad.study.config import load_folder_config
    from gpquad.study.store import atomic_write_bytes

    folder = Path(folder)
    cfg = load_folder_config(folder)
    model = DiscoveredModel.load(folder)
    out = folder / "report"
    written = convergence_report(folder, list(model.equations), cfg.evolution.metric, formats)
    dataset = load_dataset(cfg) if dataset is None else dataset
    steps_wanted = max(1, int(round(window_s / dataset.dt)))
    starts, steps = tile(dataset.validation, steps_wanted, cfg.evolution.max_delay)
    if len(starts):
        start = starts[:1]
        pred = model.simulate(dataset, start, steps)[0]
        data = np.stack([dataset.arrays.states[s : s + steps + 1] for s in start])[0]
        buf = io.BytesIO()
        np.savez(
            buf,
            t=np.arange(steps + 1) * dataset.dt,
            data=data,
            best=pred,
            full=np.zeros((0, steps + 1, 9)),
            start=start,
            dt=dataset.dt,
            state_names=np.array(STATE_NAMES),
            targets=np.array(sorted(model.equations)),
            unmeasured=np.array([s for s in STATE_NAMES if dataset.unmeasured(s)], dtype=str),
        )
        atomic_write_bytes(out / "predictions.npz", buf.getvalue())
        written += plotting.prediction_figure(
            out / "predictions.npz", out / "prediction", formats, best_label="discovered equations"
        )
    return written
