"""Exports that are the model: every form carries dt, the input delays, the lags and the trim.

One function per format, export_<format>(model, ...) -> str (or {file name: text} for C),
and `export(model, fmt)` choosing among them. The code exports (python, c, casadi) and the
sympy right-hand sides are built from the prefix trees by one generator
(gpquad.models.exports.codegen) and fly as DiscoveredModel.fly_states does.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from pathlib import Path

from gpquad.errors import GpquadError

#: Public names -> the module that defines them (imported on first use, so that the command
#: line's parser reads FORMATS without importing sympy or casadi).
_LAZY = {
    "export_text": "text_forms",
    "export_latex": "text_forms",
    "export_markdown": "text_forms",
    "export_json": "text_forms",
    "export_sympy": "symbolic",
    "sympy_equations": "symbolic",
    "SympyModel": "symbolic",
    "export_python": "python_module",
    "export_c": "c_source",
    "export_casadi": "casadi_function",
    "casadi_functions": "casadi_function",
    "exported_function": "casadi_function",
}


def __getattr__(name: str):
    if name in _LAZY:
        module = importlib.import_module(f"{__name__}.{_LAZY[name]}")
        return getattr(module, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


@dataclass(frozen=True)
class Format:
    """One export format: its function's name, the file suffix, and its description."""

    name: str
    function_name: str
    suffix: str
    about: str
    #: Takes raw= (equations written in the raw, untrimmed inputs).
    raw_option: bool = False

    @property
    def function(self):
        return __getattr__(self.function_name)


FORMATS: dict[str, Format] = {
    f.name: f
    for f in (
        Format(
            "text",
            "export_text",
            ".txt",
            "one equation per line after a dt line, e.g. "
            "'p_dot + 0.035 d(p_dot)/dt = -4.1*p + 10.3*u_R(t-1)'",
            raw_option=True,
        ),
        Format(
            "latex",
            "export_latex",
            ".tex",
            r"an align environment, e.g. '\dot{p} &= - 4.1 p + "
            r"10.3 u_{R-1}', and a sentence stating dt",
            raw_option=True,
        ),
        Format(
            "markdown",
            "export_markdown",
            ".md",
            "a table of the equations and their errors, after a dt line",
        ),
        Format(
            "sympy",
            "export_sympy",
            ".py",
            "a python script building sympy equations: "
            "symbols 'u_R(t-1)' per delay, lags as Eq(tau*Derivative(p_dot(t), t) + p_dot(t), "
            "rhs), DT, TRIM",
            raw_option=True,
        ),
        Format("json", "export_json", ".json", "model.json (full constants, delays, lags, dt)"),
        Format(
            "python",
            "export_python",
            ".py",
            "a self-contained numpy module: DT, INPUT_NAMES, TRIM, "
            "fly(inputs, x0) -> states (as gpquad flies the model), commanded and "
            "rhs(state, input_history, lag) (the continuous-time right-hand side)",
        ),
        Format(
            "c",
            "export_c",
            ".c",
            "a C99 source and header (libm only): "
            "int gpquad_fly(const double *inputs, int n_rows, const double x0[9], "
            "double *states) (as gpquad flies the model), gpquad_commanded and "
            "gpquad_rhs(...) (the continuous-time right-hand side)",
        ),
        Format(
            "casadi",
            "export_casadi",
            ".casadi",
            "a casadi.Function for MPC (needs casadi): rhs(x[9], H[history+1 x inputs], "
            "lag[6]) -> (a, lag_dot), the continuous-time right-hand side (an euler model: "
            "accel(x, H, prev), eq. 2's step); with --out saved (casadi.Function.load), "
            "else printed serialised (casadi.Function.deserialize)",
        ),
    )
}


def export(model, fmt: str, **options) -> str | dict[str, str]:
    """The model in format `fmt` (a FORMATS key): a string, or {file name: text} for "c".
    options go to the format's function (raw=True for text/latex/sympy; name=, prefix=
    for c)."""
    if fmt not in FORMATS:
        raise GpquadError(
            f"unknown export format '{fmt}'; choose one of {sorted(FORMATS)}", field="format"
        )
    if options.get("raw") and not FORMATS[fmt].raw_option:
        raise GpquadError(
            f"raw inputs (--raw-inputs) apply to the formats "
            f"{[f.name for f in FORMATS.values() if f.raw_option]}; the code "
            "exports always take raw inputs",
            field="--raw-inputs",
        )
    return FORMATS[fmt].function(model, **options)


def write_export(model, fmt: str, out, raw: bool = False) -> list[Path]:
    """Write the model in format `fmt` to `out`; returns the files written. "c" writes
    <stem>.c and <stem>.h beside each other (out may end in .c, .h or neither); "casadi"
    saves exported_function (rhs of an rk4 model, accel of an euler one; casadi.Function.load
    reads it)."""
    out = Path(out)
    options: dict[str, object] = {"raw": True} if raw else {}
    if fmt == "c":
        name = out.stem if out.suffix in (".c", ".h") else out.name
        options["name"] = name
        if not name.replace("-", "_").isidentifier():
            raise GpquadError(
                f"'{out.name}' cannot name a C source and header; give a path "
                "such as model.c (writes model.c and model.h)",
                field="--out",
            )
    out.parent.mkdir(parents=True, exist_ok=True)
    if fmt == "casadi":
        export(model, fmt, **options)  # the checks (and casadi's presence)
        __getattr__("exported_function")(model).save(str(out))
        return [out]
    result = export(model, fmt, **options)
    files = result if isinstance(result, dict) else {out.name: result}
    for name, text in files.items():
        out.with_name(name).write_text(text)
    return [out.with_name(name) for name in files]


__all__ = [
    "FORMATS",
    "Format",
    "SympyModel",
    "casadi_functions",
    "export",
    "export_c",
    "export_casadi",
    "export_json",
    "export_latex",
    "export_markdown",
    "export_python",
    "export_sympy",
    "export_text",
    "sympy_equations",
    "write_export",
]
