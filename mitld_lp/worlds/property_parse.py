"""Our own reader of the PRISM property language, for the forms the door poses as tasks.

:func:`parse_properties_text` reads a property (``Pmax=? [F "goal"]``) or a properties
file's text (``"name":`` prefixes, ``//`` comments, ``const`` declarations, several
properties ended by ``;`` or a line's end) into :class:`PropertyText` records whose
formulas are small trees of tuples:

* expressions: ``("lit", kind, value)`` (kind ``int``, ``rat``, ``bool``), ``("id",
  name, line, column)``, ``("not", e)``, ``("neg", e)``, ``("bin", op, a, b)`` with
  ``op`` one of ``| => & = != < <= > >= + - * /``; in Storm's printing of a program's
  definitions (a formula over ``min`` and ``?:``, as csma's) also ``("call", name,
  *arguments)`` for ``min``, ``max``, ``floor``, ``ceil`` and ``("ite", c, a, b)``;
* state formulas: ``("label", name)``, ``("atom", expression)``, ``("fnot", f)``,
  ``("fbin", op, a, b)`` (``op`` ``&`` or ``|``);
* path formulas: ``("F", bound, f)``, ``("G", f)``, ``("X", f)``, ``("U", bound, a,
  b)``, ``bound`` None or ``("<=", e)``, ``("<", e)``, ``("[]", a, b)``;
* the property: ``("P", optimality, comparison, threshold, path)``.

The precedence is Storm's (``mitld_lp.worlds.property_own`` prints the trees as Storm
prints its formulas): in an expression ``|`` and ``=>`` bind loosest (left to right),
then ``&``, ``=`` and ``!=``, one comparison, ``+`` and ``-``, ``*`` and ``/``, the
prefixes ``!`` and ``-``; a state formula's operand is the longest expression there
(``y | x=1 & "goal"`` is ``(y | x=1) & "goal"``), labels combine with ``!``, ``&``,
``|`` and parentheses.

Every other form of the language (``R``, ``T``, ``S``, ``LRA``, ``multi``, other
filters, reward bounds, nested temporal operators, functions, ``?:``, ``^``, ``<=>``,
block comments, ...) raises :class:`Decline`: Storm's reader answers those (the door
then reads the text with it, so its answer or refusal is today's).  A text that is not
a property at all raises :class:`PropertySyntaxError` naming ``WHERE:LINE:COLUMN``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from fractions import Fraction
from typing import Any

from mitld_lp.worlds.properties import PropertyError

__all__ = ["Decline", "PropertySyntaxError", "PropertyText", "ConstantText",
           "parse_properties_text",
           "parse_expression_text"]


class Decline(Exception):
    """A form our reader leaves to Storm's (the message says which)."""


class PropertySyntaxError(PropertyError):
    """A text that is not a property (``WHERE:LINE:COLUMN: ...``)."""


@dataclass(frozen=True)
class ConstantText:
    """``const TYPE NAME [= EXPR];`` of a properties file (``kind`` int, double, bool)."""

    name: str
    kind: str
    value: Any  # an expression tree, or None when the file leaves it open
    line: int
    column: int


@dataclass(frozen=True)
class PropertyText:
    """One property of the text: its name (None when the file gives none), its tree,
    and where it starts."""

    name: str | None
    formula: tuple
    line: int
    column: int


_TOKEN = re.compile(r"""
    (?P<space>[ \t\r]+)
  | (?P<newline>\n)
  | (?P<comment>//[^\n]*)
  | (?P<number>\d+\.\d*(?:[eE][-+]?\d+)?|\d+[eE][-+]?\d+|\.\d+(?:[eE][-+]?\d+)?|\d+)
  | (?P<name>[A-Za-z_][A-Za-z0-9_]*)
  | (?P<label>"[^"\n]*")
  | (?P<op><=>|=>|<=|>=|!=|=\?|[-+*/()\[\],:;<>=!&|?^%{}'.])
""", re.VERBOSE)

_KEYWORDS = {"F", "G", "X", "U", "W", "R", "S", "T", "LRA", "P", "E", "A", "C", "I",
             "multi", "filter", "const", "formula", "label", "true", "false", "Pmax",
             "Pmin", "Rmax", "Rmin", "Tmax", "Tmin", "Smax", "Smin", "LRAmax", "LRAmin"}


def _tokens(text: str, where: str) -> list[tuple[str, str, int, int]]:
    out, pos, line, start = [], 0, 1, 0
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if m is None:
            if text.startswith("/*", pos):
                raise Decline("a block comment")
            raise PropertySyntaxError(f"{where}:{line}:{pos - start + 1}: property parse error: "
                                f"unexpected {text[pos]!r}")
        kind = m.lastgroup or ""
        if kind == "newline":
            out.append(("newline", "\n", line, pos - start + 1))
            line, start = line + 1, m.end()
        elif kind not in ("space", "comment"):
            out.append((kind, m[0], line, pos - start + 1))
        pos = m.end()
    out.append(("end", "", line, pos - start + 1))
    return out


_TEMPORAL = ("F", "G", "X", "U")


class _NoExpression(Exception):
    """Internal: no expression starts here (the caller backs off)."""


class _Parser:
    def __init__(self, text: str, where: str) -> None:
        self.where = where
        self.all = _tokens(text, where)
        self.toks = [t for t in self.all if t[0] != "newline"]
        self.i = 0

    # ------------------------------------------------------------ helpers
    def peek(self, k: int = 0) -> tuple[str, str, int, int]:
        return self.toks[min(self.i + k, len(self.toks) - 1)]

    def at(self, *values: str) -> bool:
        kind, value, _, _ = self.peek()
        return kind in ("op", "name") and value in values

    def error(self, expected: str) -> PropertySyntaxError:
        kind, value, line, col = self.peek()
        near = f"at {value!r}" if kind != "end" else "at the end"
        return PropertySyntaxError(f"{self.where}:{line}:{col}: property parse error: expecting "
                             f"{expected} {near}")

    def expect(self, value: str) -> None:
        if not self.at(value):
            raise self.error(repr(value))
        self.i += 1

    def newline_before(self, index: int) -> bool:
        """Whether a line ends between token ``index - 1`` and token ``index``."""
        before, after = self.toks[index - 1], self.toks[index]
        return any(t[0] == "newline" and (before[2], before[3]) < (t[2], t[3])
                   <= (after[2], after[3]) for t in self.all)

    # ------------------------------------------------------------ expressions
    def expression(self) -> tuple:
        """The longest expression from here (:class:`_NoExpression` when none)."""
        return self.binary(0)

    _LEVELS: tuple[tuple[str, ...], ...] = (("|", "=>"), ("&",), ("=", "!="),
                                            ("<", "<=", ">", ">="), ("+", "-"), ("*", "/"))

    def binary(self, level: int) -> tuple:
        if level == len(self._LEVELS):
            return self.unary()
        left = self.binary(level + 1)
        ops = self._LEVELS[level]
        while self.peek()[0] == "op" and self.peek()[1] in ops:
            saved = self.i
            op = self.peek()[1]
            self.i += 1
            try:
                right = self.binary(level + 1)
            except _NoExpression:
                self.i = saved  # ``y & "goal"``: the expression ends before ``&``
                break
            left = ("bin", op, left, right)
            if level == 3:  # one comparison: ``a < b < c`` is not PRISM
                break
        self.refuse_unknown_operator()
        return left

    def refuse_unknown_operator(self) -> None:
        kind, value, _, _ = self.peek()
        if kind == "op" and value in ("?", "^", "%", "<=>"):
            raise Decline(f"the operator {value!r}")

    def unary(self) -> tuple:
        kind, value, line, col = self.peek()
        if kind == "op" and value in ("!", "-"):
            return ("not" if value == "!" else "neg", self.past_one(self.unary))
        return self.atom()

    def past_one(self, parse: Any) -> tuple:
        """``parse()`` after this token; no expression (the place kept) when it fails."""
        saved = self.i
        self.i += 1
        try:
            return parse()
        except _NoExpression:
            self.i = saved
            raise

    def atom(self) -> tuple:
        kind, value, line, col = self.peek()
        if kind == "number":
            self.i += 1
            if re.fullmatch(r"\d+", value):
                return ("lit", "int", int(value))
            return ("lit", "rat", Fraction(value))
        if kind == "name":
            if value in ("true", "false"):
                self.i += 1
                return ("lit", "bool", value == "true")
            if value in _KEYWORDS:
                raise _NoExpression()
            if self.peek(1)[1] == "(" and self.peek(1)[0] == "op":
                raise Decline(f"the function {value!r}")
            self.i += 1
            return ("id", value, line, col)
        if kind == "op" and value == "(":
            saved = self.i
            inner = self.past_one(self.expression)
            if not self.at(")"):
                self.i = saved  # ``(y & "goal")``: a state formula in parentheses
                raise _NoExpression()
            self.i += 1
            return inner
        raise _NoExpression()

    # ------------------------------------------------------------ state formulas
    def state(self, op: str = "|") -> tuple:
        """A state formula: ``|`` over ``&`` over the prefix ``!`` (left to right)."""
        operand = (lambda: self.state("&")) if op == "|" else self.state_unary
        left = operand()
        while self.at(op):
            self.i += 1
            left = ("fbin", op, left, operand())
        return left

    def state_unary(self) -> tuple:
        saved = self.i
        try:
            expression = self.expression()
        except _NoExpression:
            self.i = saved
        else:
            if expression[0] == "lit" and expression[1] == "bool":
                return ("boollit", expression[2])
            return ("atom", expression)
        kind, value, _, _ = self.peek()
        if kind == "label":
            self.i += 1
            return ("label", value[1:-1])
        if self.at("!"):
            self.i += 1
            return ("fnot", self.state_unary())
        if self.at("("):
            self.i += 1
            inner = self.path()  # a path formula in parentheses: refused as LTL by Storm
            self.expect(")")
            if inner[0] in ("F", "G", "X", "U"):
                raise Decline("a temporal operator in parentheses")
            return inner
        if kind in ("op", "end") and value not in ("{", "^", "?", "%", "<=>"):
            raise self.error("a state formula")
        raise Decline(f"{value!r} where a state formula belongs")

    # ------------------------------------------------------------ path formulas
    def bound(self) -> tuple | None:
        if self.at("<=", "<"):
            op = self.peek()[1]
            self.i += 1
            return (op, self.bound_expression())
        if self.at("["):
            self.i += 1
            a = self.bound_expression()
            self.expect(",")
            b = self.bound_expression()
            self.expect("]")
            return ("[]", a, b)
        if self.at(">=", ">", "^", "{", "="):
            raise Decline("a bound with only a lower end, or on a reward or time")
        return None

    def bound_expression(self) -> tuple:
        try:
            return self.unary_bound()
        except _NoExpression:
            raise self.error("a bound") from None

    def unary_bound(self) -> tuple:
        return self.binary(4)  # a bound is a number: sums and products, no comparison

    def temporal(self) -> tuple:
        kind, value, _, _ = self.peek()
        if kind == "name" and value in ("F", "G", "X"):
            self.i += 1
            bound = self.bound() if value != "X" else None
            if value == "G" and bound is not None:
                raise Decline("a bounded G")
            operand = self.temporal()
            if operand[0] in _TEMPORAL:
                raise Decline("a temporal operator nested in another")
            if value == "F":
                return ("F", bound, operand)
            return (value, operand)
        if kind == "name" and value in ("W", "R"):
            raise Decline(f"the operator {value!r}")
        return self.state()

    def path(self) -> tuple:
        left = self.temporal()
        if self.at("U"):
            self.i += 1
            bound = self.bound()
            right = self.temporal()
            if self.at("U", "W", "R") or left[0] in _TEMPORAL or right[0] in _TEMPORAL:
                raise Decline("a temporal operator nested in another")
            return ("U", bound, left, right)
        if self.at("W", "R"):
            raise Decline(f"the operator {self.peek()[1]!r}")
        return left

    # ------------------------------------------------------------ properties
    def operator(self) -> tuple:
        if self.at("filter"):
            return self.filtered()
        if not self.at("P", "Pmax", "Pmin"):
            raise Decline("a property that is not one P operator")
        optimality = {"P": None, "Pmax": "max", "Pmin": "min"}[self.peek()[1]]
        self.i += 1
        comparison = threshold = None
        if self.at("=?"):
            self.i += 1
        elif self.at(">=", ">", "<=", "<"):
            comparison = self.peek()[1]
            self.i += 1
            try:
                threshold = self.expression()
            except _NoExpression:
                raise self.error("a probability") from None
        elif self.at("="):
            raise Decline("'=' without '?'")
        else:
            raise self.error("'=?' or a comparison")
        if self.at("{"):
            raise Decline("a reward model or a named objective")
        self.expect("[")
        path = self.path()
        self.expect("]")
        return ("P", optimality, comparison, threshold, path)

    def filtered(self) -> tuple:
        self.i += 1
        self.expect("(")
        if not self.at("max", "min", "values"):
            raise Decline("a filter other than max, min or values")
        self.i += 1
        self.expect(",")
        inner = self.operator()
        if not self.at(","):
            raise Decline("a filter without its states")
        self.i += 1
        if self.peek()[:2] != ("label", '"init"'):
            raise Decline("a filter over states other than the initial ones")
        self.i += 1
        self.expect(")")
        return inner

    def constant(self) -> ConstantText:
        _, _, line, col = self.peek()
        self.i += 1
        kind = "int"
        if self.at("int", "double", "bool"):
            kind = self.peek()[1]
            self.i += 1
        name_kind, name, _, _ = self.peek()
        if name_kind != "name" or name in _KEYWORDS:
            raise self.error("a constant's name")
        self.i += 1
        value = None
        if self.at("="):
            self.i += 1
            try:
                value = self.expression()
            except _NoExpression:
                raise self.error("an expression") from None
        self.expect(";")
        return ConstantText(name, kind, value, line, col)

    def text(self) -> tuple[list[ConstantText], list[PropertyText]]:
        constants: list[ConstantText] = []
        props: list[PropertyText] = []
        while self.peek()[0] != "end":
            if self.at(";"):
                self.i += 1
                continue
            if self.at("const"):
                constants.append(self.constant())
                continue
            if self.at("formula", "label"):
                raise Decline(f"a {self.peek()[1]} in a properties file")
            _, _, line, col = self.peek()
            name = None
            if self.peek()[0] == "label" and self.peek(1)[1] == ":":
                name = self.peek()[1][1:-1]
                if not re.fullmatch(r"[A-Za-z_]\w*", name):
                    raise Decline(f"the name {name!r}")  # Storm's reader refuses it
                self.i += 2
            formula = self.operator()
            props.append(PropertyText(name, formula, line, col))
            if self.at(";"):
                continue
            if self.peek()[0] != "end" and not self.newline_before(self.i):
                raise self.error("';' or the line's end")
            if self.peek()[0] != "end":
                raise Decline("properties separated by a line's end alone")
        return constants, props


def parse_properties_text(text: str, where: str) -> tuple[list[ConstantText],
                                                          list[PropertyText]]:
    """The ``const`` declarations and the properties of ``text`` (``where`` names it in
    errors), or :class:`Decline` for a form Storm's reader is left to read."""
    parser = _Parser(text, where)
    constants, props = parser.text()
    if not props:
        raise PropertySyntaxError(f"{where}: no property in it")
    return constants, props


def parse_expression_text(text: str, where: str, *, storm_printed: bool = False) -> tuple:
    """One expression (a constant's definition); ``storm_printed``: the text is Storm's
    printing, where ``1/2`` without spaces is a rational number."""
    parser = _StormPrinted(text, where) if storm_printed else _Parser(text, where)
    try:
        tree = parser.expression()
    except _NoExpression:
        raise Decline(f"{where}: not an expression") from None
    if parser.peek()[0] != "end":
        raise Decline(f"{where}: more than one expression")
    return tree


class _StormPrinted(_Parser):
    """Storm's printing of an expression, where ``N/D`` without spaces is the rational
    number N/D (Storm prints a division with spaces: ``(N / D)``)."""

    def __init__(self, text: str, where: str) -> None:
        parts = re.split(r"(?<![\w.])(\d+/\d+)(?![\w.])", text)
        self.rationals: dict[str, Fraction] = {}
        out = []
        for k, part in enumerate(parts):
            if k % 2:
                n, d = part.split("/")
                key = f"rational_{len(self.rationals)}"
                self.rationals[key] = Fraction(int(n), int(d))
                out.append(key)
            else:
                out.append(part)
        super().__init__("".join(out), where)

    def atom(self) -> tuple:
        """Also Storm's printing of the functions ``(min(a, b))``, ``(max(a, b))``,
        ``floor(a)``, ``ceil(a)`` (``("call", name, *arguments)``) and of a condition
        ``(c ? a : b)`` (``("ite", c, a, b)``), always in parentheses there."""
        kind, value, _, _ = self.peek()
        if kind == "name" and value in self.rationals:
            self.i += 1
            return ("lit", "rat", self.rationals[value])
        if kind == "name" and value in _ARITY and self.peek(1)[:2] == ("op", "("):
            self.i += 2
            arguments = [self.expression()]
            while self.at(","):
                self.i += 1
                arguments.append(self.expression())
            self.expect(")")
            if len(arguments) != _ARITY[value]:
                raise Decline(f"the function {value!r} with {len(arguments)} arguments")
            return ("call", value, *arguments)
        if self.at("("):
            saved = self.i
            self.i += 1
            condition = self.expression()
            if self.at("?"):
                self.i += 1
                a = self.expression()
                self.expect(":")
                b = self.expression()
                self.expect(")")
                return ("ite", condition, a, b)
            self.i = saved
        return super().atom()

    def refuse_unknown_operator(self) -> None:
        if not self.at("?"):  # a condition's, read by atom
            super().refuse_unknown_operator()


_ARITY = {"min": 2, "max": 2, "floor": 1, "ceil": 1}
