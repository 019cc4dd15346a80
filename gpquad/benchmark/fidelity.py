"""Fidelity: how a cell's printed equations fly in continuous time (RK4, 8 steps per sample).

Every method prints continuous-time equations (gpquad's `p_dot = ...`, a peer's regression in
the lagged features), and a reader flies them in their own fine integrator, inputs held over
each sample. A cell's equations are re-read from its stored text (`equations`: gpquad's lines
in the model's trim-subtracted inputs, a peer's expression in the features of
`gpquad.benchmark.peers`) and flown over the same test windows twice:

- "own": by the method's own scheme: gpquad's finished model's integrator and steps per
  sample (the cell's `scheme`; a stiff loop raises them, gpquad.models.stiffness), else
  `evolution.integrator` / `substeps` of the cell's settings (eq. 2, one step per sample,
  when the cell records none); a peer's
  one-step map (its accelerations are forward differences, eq. 2's inverse);
- "rk4": by RK4 with FIDELITY_SUBSTEPS steps per sample (gpquad.engine.kernels.step).

Both are scored by `gpquad.benchmark.evaluate.score` (RSE over the windows that did not
diverge, diverged windows counted). Flying both from the same text isolates the scheme: the
cell's stored score (its full-precision model) is compared with the text's own-scheme score
only as a check (`text_matches_stored`).

The ratio of a state is max(RSE_rk4, FLOOR_RSE) / max(RSE_own, FLOOR_RSE): an RSE below
FLOOR_RSE (an error RMS below 0.1 % of the state's spread) counts as FLOOR_RSE, so two
numbers at round-off (1e-30 on an exact-truth scenario) give 1, not a ratio of round-off
noise. A cell's ratio is the largest over p, q, r at FIDELITY_HORIZON (or the longest horizon
flown, when a benchmark is scored at shorter ones); all-diverged is inf.

Nothing is refitted: `update` works on any finished benchmark folder and caches each cell's
result in `fidelity/<scenario>/<method>/seed<k>.json`, keyed by the cell's fingerprint, a
hash of its equations and a hash of the test flights (a changed simulator recomputes it).
"""

from __future__ import annotations

import hashlib
import json
import re
from pathlib import Path

import numpy as np

from gpquad.benchmark.cells import settings_fingerprint
from gpquad.benchmark.evaluate import score
from gpquad.benchmark.peer_predictor import peer_predictor
from gpquad.benchmark.rollout import fly
from gpquad.data.score import FIDELITY_SUBSTEPS
from gpquad.engine.tree.export import from_sympy, parse_equation
from gpquad.engine.variables import TARGET_NAMES
from gpquad.errors import GpquadError
from gpquad.study.store import write_json

#: RSE below which two scores are not told apart (module notes).
FLOOR_RSE = 1e-6
#: The states and horizon of the fidelity ratio (issue 32's done-means criterion).
FIDELITY_STATES = ("p", "q", "r")
FIDELITY_HORIZON = "7s"
#: Largest ratio that passes.
RATIO_LIMIT = 1.5
#: A text's own-scheme RSE that differs from the stored one by more than this (relative,
#: above FLOOR_RSE) flags the cell: the text is not the scored model or the flights changed.
STORED_TOLERANCE = 0.05

_LHS = re.compile(
    r"^\s*(?P<target>[a-z_]+)\s*(?:\+\s*(?P<lag>[0-9.eE+-]+)\s*d\((?P=target)\)/dt\s*)?$"
)


def parse_line(line: str, target: str) -> tuple[str, float]:
    """(right-hand side, lag tau in s) of a printed gpquad line 'p_dot = ...' or
    'p_dot + 0.005 d(p_dot)/dt = ...' (gpquad.models.equation.Equation.text)."""
    lhs, sep, rhs = line.partition("=")
    match = _LHS.match(lhs)
    if not sep or match is None or match["target"] != target:
        raise GpquadError(f"not a printed {target} equation: {line[:80]!r}", field=target)
    return rhs.strip(), float(match["lag"] or 0.0)


def model_from_text(equations: dict, input_names, dt: float, integrator: str, substeps: int):
    """A DiscoveredModel (no trim: the text is in the model's own inputs) of printed lines."""
    from gpquad.models.equation import Equation
    from gpquad.models.equations import DiscoveredModel

    names = tuple(input_names)
    eqs = {}
    for target in TARGET_NAMES:
        if target not in equations:
            continue
        rhs, lag = parse_line(equations[target], target)
        expr, delays = parse_equation(rhs, names, source=target)
        tree = from_sympy(expr, delays, names)
        eqs[target] = Equation(target, tree, names, np.nan, np.nan, {}, [], 17, lag)
    return DiscoveredModel(
        eqs, names, {}, float(dt), 0, {}, integrator=integrator, substeps=substeps
    )


def own_scheme(cell: dict, group: str | None = None) -> tuple[str, int]:
    """The scheme a cell's method flies its equations with (module notes); of `group`'s
    model for a cell fitted per vehicle (each records its own)."""
    if cell["method"] != "gpquad":
        return "euler", 1
    scheme = cell.get("scheme") or {}
    if group is not None and group in scheme:
        scheme = scheme[group]
    if "integrator" in scheme:  # the finished model's (cells written before: the settings')
        return str(scheme["integrator"]), int(scheme["substeps"])
    evolution = (cell.get("settings") or {}).get("evolution") or {}
    return str(evolution.get("integrator", "euler")), int(evolution.get("substeps", 1))


def text_simulator(method: str, equations: dict, test, integrator: str, substeps: int):
    """simulate(starts, steps) of printed equations over a test dataset's windows."""
    if method == "gpquad":
        model = model_from_text(equations, test.input_names, test.dt, integrator, substeps)
        return lambda starts, steps: model.simulate(test, starts, steps)
    predict = peer_predictor(equations, test.input_names)
    return lambda starts, steps: fly(
        predict, test.arrays, starts, steps, integrator=integrator, substeps=substeps
    )


def cell_simulator(cell: dict, scenario, scheme_of):
    """simulate(starts, steps) on scenario.test of a cell's stored equations (per group
    when the cell was fitted per vehicle), each flown by scheme_of(group or None) ->
    (integrator, substeps)."""
    from gpquad.benchmark.cells import grouped_simulate

    method = cell["method"]
    if not scenario.groups:
        return text_simulator(method, cell["equations"], scenario.test, *scheme_of(None))
    return grouped_simulate(
        scenario,
        {
            g: text_simulator(method, cell["equations"][g], sub.test, *scheme_of(g))
            for g, sub in scenario.groups.items()
        },
    )


def _metrics(simulate, scenario, horizons_s) -> dict:
    with np.errstate(all="ignore"):
        out = score(simulate, scenario.test, scenario.measured, horizons_s)
    for m in out.values():
        m.pop("window_sse", None)
    return out


def cell_fidelity(cell: dict, scenario, horizons_s) -> dict:
    """{"own_scheme", "own", "rk4", "substeps", "ratio", "text_matches_stored"} of a cell."""
    integrator, substeps = own_scheme(cell)
    own = _metrics(
        cell_simulator(cell, scenario, lambda g: own_scheme(cell, g)), scenario, horizons_s
    )
    rk4 = _metrics(
        cell_simulator(cell, scenario, lambda g: ("rk4", FIDELITY_SUBSTEPS)), scenario, horizons_s
    )
    return {
        "own_scheme": {"integrator": integrator, "substeps": substeps},
        "substeps": FIDELITY_SUBSTEPS,
        "own": own,
        "rk4": rk4,
        "ratio_horizon": (at := ratio_horizon(own)),
        "ratio": cell_ratio(own.get(at), rk4.get(at)) if at else None,
        "text_matches_stored": matches_stored(own, cell.get("metrics", {})),
    }


def ratio_horizon(metrics: dict) -> str | None:
    """FIDELITY_HORIZON when it was flown, else the longest horizon flown (None: none)."""
    flown = [h for h, m in metrics.items() if m.get("windows")]
    if FIDELITY_HORIZON in flown:
        return FIDELITY_HORIZON
    return max(flown, key=lambda h: float(h.rstrip("s")), default=None)


def ratio(rk4: float | None, own: float | None) -> float | None:
    """max(rk4, FLOOR_RSE) / max(own, FLOOR_RSE); None when the state is not scored, inf
    when the RK4 flight has no score (every window diverged) and the own one has."""
    if own is None and rk4 is None:
        return None
    if rk4 is None or not np.isfinite(rk4):
        return float("inf")
    if own is None or not np.isfinite(own):
        return 0.0
    return max(rk4, FLOOR_RSE) / max(own, FLOOR_RSE)


def cell_ratio(own: dict | None, rk4: dict | None) -> float | None:
    """The largest ratio over FIDELITY_STATES at one horizon (None: not flown/measured)."""
    if not own or not rk4 or not own.get("windows"):
        return None
    values = [ratio(rk4["rse"].get(s), own["rse"].get(s)) for s in FIDELITY_STATES]
    values = [v for v in values if v is not None]
    return max(values) if values else None


def matches_stored(own: dict, stored: dict) -> bool:
    """Whether the text's own-scheme RSE is the stored score (STORED_TOLERANCE)."""
    for h, m in own.items():
        ref = stored.get(h)
        if not ref or not m.get("windows"):
            continue
        if m["diverged"] != ref.get("diverged"):
            return False
        for s, v in m["rse"].items():
            r = (ref.get("rse") or {}).get(s)
            if v is None or r is None:
                if (v is None) != (r is None):
                    return False
                continue
            if max(v, r) > FLOOR_RSE and abs(v - r) > STORED_TOLERANCE * max(v, r):
                return False
    return True


def _cell_key(cell: dict) -> dict:
    """The part of a fidelity record's key that the cell alone fixes (what `load` can check
    without the flights): its settings' fingerprint and its equations."""
    return {
        "fingerprint": cell.get("fingerprint"),
        "equations": settings_fingerprint(cell["equations"]),
    }


def flights_hash(scenario) -> str:
    """Hash of the test flights' states and inputs (a changed simulator changes it)."""
    arrays = scenario.test.arrays
    digest = hashlib.sha256(np.ascontiguousarray(arrays.states).tobytes())
    digest.update(np.ascontiguousarray(arrays.inputs).tobytes())
    return digest.hexdigest()[:16]


def fidelity_path(out: Path, cell: dict) -> Path:
    return Path(out) / "fidelity" / cell["scenario"] / cell["method"] / f"seed{cell['seed']}.json"


def update(out, cells: list[dict], scenarios: dict, horizons_s, log=print) -> list[dict]:
    """Each cell's fidelity (cached under out/fidelity; computed where missing or stale),
    in the order of `cells`; a cell whose scenario is not in `scenarios` is left out."""
    found = []
    hashes = {name: flights_hash(sc) for name, sc in scenarios.items()}
    for cell in cells:
        scenario = scenarios.get(cell["scenario"])
        if scenario is None:
            continue
        key = {
            **_cell_key(cell),
            "scheme": list(own_scheme(cell)),
            "flights": hashes[cell["scenario"]],
            "horizons_s": [float(h) for h in horizons_s],
            "substeps": FIDELITY_SUBSTEPS,
        }
        path = fidelity_path(Path(out), cell)
        try:
            saved = json.loads(path.read_text())
        except (OSError, ValueError):
            saved = None
        if not isinstance(saved, dict) or saved.get("key") != key:
            try:
                result = cell_fidelity(cell, scenario, horizons_s)
            except GpquadError as exc:  # a text this reader does not parse: say so, go on
                log(
                    f"gpquad benchmark: warning: no fidelity for {cell['scenario']}/"
                    f"{cell['method']}/seed{cell['seed']}: {exc}"
                )
                continue
            saved = {"scenario": cell["scenario"], "method": cell["method"], "seed": cell["seed"]}
            saved.update(key=key, **result)
            write_json(path, _finite(saved))
            log(
                f"  fidelity {cell['scenario']:<20} {cell['method']:<7} seed {cell['seed']}: "
                f"ratio {result['ratio_horizon']} {_shown(result['ratio'])}"
            )
        found.append(saved)
    return found


def load(out, cells: list[dict]) -> list[dict]:
    """The cached fidelity of each cell that has one made from its current equations."""
    found = []
    for cell in cells:
        try:
            saved = json.loads(fidelity_path(Path(out), cell).read_text())
        except (OSError, ValueError):
            continue
        key = saved.get("key", {}) if isinstance(saved, dict) else {}
        if {k: key.get(k) for k in ("fingerprint", "equations")} == _cell_key(cell):
            found.append(saved)
    return found


def _finite(obj):
    """JSON-safe: NaN becomes null, inf the string 'inf'."""
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    if isinstance(obj, (float, np.floating)):
        if np.isnan(obj):
            return None
        return float(obj) if np.isfinite(obj) else "inf"
    return obj


def _shown(x) -> str:
    if x is None:
        return "-"
    if x == "inf" or (isinstance(x, float) and np.isinf(x)):
        return "inf"
    return f"{float(x):.3g}"
