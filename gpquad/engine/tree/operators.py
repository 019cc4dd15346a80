"""The ONE operator table: kernel codes, arity, and export forms.

Trees are flat prefix arrays of integer codes plus a float array of constants.
Codes 0..3 are the binary operators, CONST is a constant leaf, and codes
VAR_BASE + k are variable leaves k (the 9 states then the inputs, see
gpquad.engine.variables.terminal_names). The kernels read the integer constants
below; export reads OPERATORS. Division is protected: |b| < DIV_EPS gives 1.
"""

from collections.abc import Callable
from dataclasses import dataclass

ADD, SUB, MUL, DIV = 0, 1, 2, 3
CONST = 4
VAR_BASE = 5
N_OPERATORS = 4
DIV_EPS = 1e-6


@dataclass(frozen=True)
class Operator:
    """One binary operator: kernel code, name, infix symbol and its export functions."""

    code: int
    name: str
    symbol: str
    numpy: Callable
    sympy: Callable


def _protected_div(a, b):
    import numpy as np

    b = np.asarray(b, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        safe = np.where(b == 0, 1, b)
        return np.where(np.abs(b) < DIV_EPS, 1.0, np.asarray(a, dtype=float) / safe)


OPERATORS: tuple[Operator, ...] = (
    Operator(ADD, "add", "+", lambda a, b: a + b, lambda a, b: a + b),
    Operator(SUB, "sub", "-", lambda a, b: a - b, lambda a, b: a - b),
    Operator(MUL, "mul", "*", lambda a, b: a * b, lambda a, b: a * b),
    # sympy export writes plain division; protection only matters at |b| < DIV_EPS.
    Operator(DIV, "div", "/", _protected_div, lambda a, b: a / b),
)

OPERATOR_BY_CODE = {op.code: op for op in OPERATORS}


def arity(code: int) -> int:
    """Number of children of a node code."""
    return 2 if code < N_OPERATORS else 0
