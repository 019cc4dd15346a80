"""A parser of the equations' own grammar, which builds sympy expressions from whitelisted
pieces and never evaluates the text as Python (no eval, sympify or parse_expr).

    expr    := term (("+" | "-") term)*
    term    := unary (("*" | "/") unary)*
    unary   := ("+" | "-") unary | power
    power   := atom [("**" | "^") unary]        exponent: an integer, |n| <= MAX_POWER
    atom    := NUMBER | NAME | NAME "(" "t" "-" INTEGER ")" | "(" expr ")"

NUMBER is a decimal number with an optional exponent (1.5e-3); NAME is a letter or "_"
followed by letters, digits or "_". What a name stands for is the caller's `leaf(name, k)`:
k is the delay of `name(t-k)`, None for a bare name; it returns a sympy expression or raises
GpquadError. Operator precedence is Python's (and sympy's): -p**2 is -(p**2).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable

import sympy as sp

from gpquad.engine.tree.encoding import MAX_TREE_DEPTH
from gpquad.errors import GpquadError

#: Largest |integer exponent| of a power: the leaves of the deepest tree a configuration
#: may ask for, so that every equation gpquad writes reads back (a tree's expression, however
#: sympy rearranges it, has no power of a name above the tree's leaves).
MAX_POWER = 2**MAX_TREE_DEPTH
#: Longest expression text read.
MAX_CHARACTERS = 20_000
#: Most bits of an integer power of a number (9**256 has 812).
MAX_NUMBER_BITS = 4096
#: Most terms an expression may expand to (the finishing steps and analyses expand the
#: equations with sympy): (p + q + r + v + w)**256 would be 1.9e8.
MAX_TERMS = 20_000
#: Deepest nesting of parentheses, signs and powers.
MAX_NESTING = 100

_TOKEN = re.compile(
    r"\s*(?:(?P<number>(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)"
    r"|(?P<name>[A-Za-z_][A-Za-z0-9_]*)|(?P<op>\*\*|[-+*/^()]))"
)

Leaf = Callable[[str, "int | None"], sp.Expr]


def tokenize(text: str, fail) -> list[tuple[str, str]]:
    """[(kind, text)] with kind number, name or op; `fail(message)` raises."""
    tokens = []
    pos = 0
    end = len(text.rstrip())
    while pos < end:
        match = _TOKEN.match(text, pos)
        if match is None:
            fail(f"unexpected {text[pos:].lstrip()[:1]!r} at character {pos + 1}")
        kind = match.lastgroup
        tokens.append((kind, match.group(kind)))
        pos = match.end()
    return tokens


class _Parser:
    def __init__(self, text: str, leaf: Leaf, caret: bool, fail):
        self.text = text
        self.leaf = leaf
        self.caret = caret
        self.fail = fail
        self.tokens = tokenize(text, fail)
        self.pos = 0
        self.nesting = 0

    def peek(self) -> tuple[str, str] | None:
        return self.tokens[self.pos] if self.pos < len(self.tokens) else None

    def take(self, op: str | None = None) -> tuple[str, str]:
        token = self.peek()
        if token is None:
            self.fail("ends too early" if op is None else f"expected {op!r} at the end")
        if op is not None and token != ("op", op):
            self.fail(f"expected {op!r} before {token[1]!r}")
        self.pos += 1
        return token

    def at(self, *ops: str) -> bool:
        token = self.peek()
        return token is not None and token[0] == "op" and token[1] in ops

    def nest(self):
        self.nesting += 1
        if self.nesting > MAX_NESTING:
            self.fail(f"nested deeper than {MAX_NESTING} levels")

    def parse(self) -> sp.Expr:
        if not self.tokens:
            self.fail("empty expression")
        expr = self.expr()
        if self.peek() is not None:
            self.fail(f"unexpected {self.peek()[1]!r} after a complete expression")
        # sympy merges powers of powers and products: (p**256)**256 is p**65536
        for power in expr.atoms(sp.Pow):
            if power.exp.is_Integer and abs(int(power.exp)) > MAX_POWER:
                self.fail(f"it makes a power above {MAX_POWER} ({power.base}**{power.exp})")
        if expanded_terms(expr) > MAX_TERMS:
            self.fail(f"it expands to more than {MAX_TERMS} terms")
        return expr

    def expr(self) -> sp.Expr:
        # one Add of every term: adding them one by one re-sorts the growing sum each time
        terms = [self.term()]
        while self.at("+", "-"):
            op = self.take()[1]
            right = self.term()
            terms.append(right if op == "+" else -right)
        return terms[0] if len(terms) == 1 else sp.Add(*terms)

    def term(self) -> sp.Expr:
        out = self.unary()
        while self.at("*", "/"):
            op = self.take()[1]
            right = self.unary()
            out = out * right if op == "*" else out / right
        return out

    def unary(self) -> sp.Expr:
        if self.at("+", "-"):
            self.nest()
            op = self.take()[1]
            inner = self.unary()
            self.nesting -= 1
            return inner if op == "+" else -inner
        return self.power()

    def power(self) -> sp.Expr:
        base = self.atom()
        if self.at("**") or (self.caret and self.at("^")):
            self.take()
            self.nest()
            exponent = self.unary()
            self.nesting -= 1
            if not (exponent.is_Integer and abs(int(exponent)) <= MAX_POWER):
                self.fail(
                    f"powers take an integer exponent from -{MAX_POWER} to {MAX_POWER}, "
                    f"not {exponent}"
                )
            if base.is_Rational:  # computed at once: bound its size first
                bits = max(abs(base.p).bit_length(), base.q.bit_length())
                if bits * abs(int(exponent)) > MAX_NUMBER_BITS:
                    self.fail(f"{base}**{exponent} is a number of more than {MAX_NUMBER_BITS} bits")
            return base**exponent
        if self.at("^"):
            self.fail("write powers as x**2")
        return base

    def atom(self) -> sp.Expr:
        kind, text = self.take()
        if kind == "number":
            return self.number(text)
        if kind == "name":
            if not self.at("("):
                return self.leaf(text, None)
            return self.leaf(text, self.delay(text))
        if text == "(":
            self.nest()
            inner = self.expr()
            self.take(")")
            self.nesting -= 1
            return inner
        self.fail(f"unexpected {text!r}")

    def number(self, text: str) -> sp.Expr:
        if len(text) > 40:
            self.fail(f"number {text[:20]}... has too many digits")
        if re.fullmatch(r"\d+", text):
            return sp.Integer(int(text))
        if not math.isfinite(float(text)):
            self.fail(f"number {text} is out of range")
        return sp.Float(text)

    def delay(self, name: str) -> int:
        """k of `name(t-k)` (the name already read)."""
        self.take("(")
        token = self.peek()
        if token != ("name", "t"):
            self.fail(
                f"'{name}(...)': equations use + - * / and integer powers of states, "
                "inputs and numbers, no functions (a delayed input is written "
                "name(t-k))"
            )
        self.take()
        if self.at(")"):
            self.take()
            return 0
        if not self.at("-"):
            self.fail(f"'{name}(t...)': a delay is written {name}(t-k) with k >= 0 samples")
        self.take()
        kind, k = self.take()
        if kind != "number" or not k.isdigit() or len(k) > 9:
            self.fail(f"'{name}(t-{k})': the delay k of {name}(t-k) is a whole number of samples")
        self.take(")")
        return int(k)


def expanded_terms(expr: sp.Expr, cap: int = MAX_TERMS + 1) -> int:
    """An upper bound (at most cap) of the terms sp.expand makes of expr or of any part it
    expands: a sum's terms add, a product's multiply, a power n of k terms gives
    C(n + k - 1, k - 1). A negative power is one term of its product (expand leaves the
    quotient), but its base's expansion counts on its own (expand expands denominators)."""
    memo: dict = {}
    inner = [0]  # the largest expansion inside a denominator

    def count(e) -> int:
        if e in memo:
            return memo[e]
        if e.is_Add:
            n = sum(count(a) for a in e.args)
        elif e.is_Mul:
            n = 1
            for a in e.args:
                n = min(n * count(a), cap)
        elif e.is_Pow and e.exp.is_Integer:
            k, m = count(e.base), abs(int(e.exp))
            n = 1 if k == 1 else min(math.comb(m + k - 1, k - 1), cap)
            if e.exp < 0:
                inner[0] = max(inner[0], n)
                n = 1
        else:
            n = 1
        memo[e] = min(n, cap)
        return memo[e]

    return max(count(expr), inner[0])


def parse_arithmetic(
    text,
    leaf: Leaf,
    *,
    caret_power: bool = False,
    source: str | None = None,
    field: str | None = None,
) -> sp.Expr:
    """The sympy expression of `text` (module grammar); names go through `leaf`.
    caret_power: also read a ^ b as a power. Errors are GpquadError naming source/field."""

    def fail(message: str):
        shown = text if len(text) <= 80 else text[:77] + "..."
        raise GpquadError(f"cannot parse '{shown}': {message}", source=source, field=field)

    if not isinstance(text, str):
        raise GpquadError(
            f"expected an equation as text, not {type(text).__name__}", source=source, field=field
        )
    if len(text) > MAX_CHARACTERS:
        raise GpquadError(
            f"an equation of {len(text)} characters is longer than the {MAX_CHARACTERS} read",
            source=source,
            field=field,
        )
    return _Parser(text, leaf, caret_power, fail).parse()


def parse_in_symbols(
    text,
    symbols: dict[str, sp.Symbol] | None,
    *,
    caret_power: bool = False,
    source: str | None = None,
    field: str | None = None,
) -> sp.Expr:
    """`text` in the given symbols only (no delays written name(t-k)); symbols=None: every
    name is a real Symbol of that name."""

    def leaf(name: str, k):
        if k is not None:
            raise GpquadError(
                f"'{name}(t-{k})' in '{text}': delays are given beside the "
                "expression here, not in it",
                source=source,
                field=field,
            )
        if symbols is None:
            return sp.Symbol(name, real=True)
        if name not in symbols:
            raise GpquadError(
                f"unknown name '{name}' in '{text}'; the names are {sorted(symbols)}",
                source=source,
                field=field,
            )
        return symbols[name]

    return parse_arithmetic(text, leaf, caret_power=caret_power, source=source, field=field)


__all__ = ["MAX_POWER", "expanded_terms", "parse_arithmetic", "parse_in_symbols"]
