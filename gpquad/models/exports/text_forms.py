"""`text`, `latex`, `markdown` and `json` exports: the printed forms, each stating dt.

The equations are DiscoveredModel's (constants at the digits that keep each form the model,
gpquad.models.precision); these add the sample period, what a delay means and the trim.
"""

from __future__ import annotations

import json

from gpquad.engine.variables import input_latex
from gpquad.models.exports.codegen import short_number


def _trim_note(model, raw: bool) -> str:
    trim = {n: v for n, v in model.trim.items() if v}
    if not trim:
        return ""
    values = ", ".join(f"{n} {short_number(v)}" for n, v in trim.items())
    return f"; inputs raw (trim {values})" if raw else f"; inputs minus their trim ({values})"


def dt_line(model, form: str = "text", raw: bool = False) -> str:
    """ "dt = 0.04 s; delays in samples (u_R(t-2) is u_R 2 samples back)", with the trim and
    the scheme; form "text", "latex" or "markdown" (math in $...$)."""
    name = model.input_names[0] if model.input_names else "u"
    if form == "text":
        dt, example = f"dt = {short_number(model.dt)} s", f"{name}(t-2)"
    else:
        dt, example = rf"$\Delta t = {short_number(model.dt)}$ s", f"${input_latex(name, 2)}$"
    return (
        f"{dt}; delays in samples ({example} is {name} 2 samples back)"
        f"{_trim_note(model, raw)}{_scheme_note(model)}"
    )


def _scheme_note(model) -> str:
    """How the equations fly: continuous time (RK4) or the paper's eq. 2."""
    if model.integrator == "euler":
        return "; flown by one explicit step per sample (eq. 2)"
    return (
        f"; continuous time, inputs held over each sample (fitted by RK4, "
        f"{model.substeps} step(s) per sample)"
    )


def export_text(model, raw: bool = False) -> str:
    """The equations one per line after a line stating dt, the delays and the trim."""
    return f"{dt_line(model, 'text', raw)}\n{model.text(raw=raw)}\n"


def export_latex(model, raw: bool = False) -> str:
    """An align environment, then a sentence stating dt, the delays and the trim."""
    return f"{model.latex(raw=raw)}{dt_line(model, 'latex', raw)}.\n"


def export_markdown(model) -> str:
    """A table of the equations, after a line stating dt, the delays and the trim."""
    return f"{dt_line(model, 'markdown')}.\n\n{model.markdown()}"


def export_json(model) -> str:
    """model.json (DiscoveredModel.to_dict; it holds dt and every delay and lag)."""
    return json.dumps(model.to_dict(), indent=2) + "\n"
