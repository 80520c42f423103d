"""PRISM expressions as trees, typed and simplified as Storm's parser leaves them.

An :class:`Expr` is what :mod:`mitld_lp.worlds.prism_compile` reads from a stormpy
``Expression`` (``is_literal``, ``is_variable``, ``get_identifier``, ``operator``,
``arity``, ``get_operand``, ``has_boolean_type``, ``has_integer_type``,
``evaluate_as_*``, ``contains_variables``), so that the own front
(:mod:`mitld_lp.worlds.prism_front`) hands the compile the same trees Storm does.

Types are Storm's: ``bool``, ``int`` and ``double`` (a rational); ``/`` is real division
(a double), ``floor``/``ceil`` give integers, ``+ - * min max pow`` an integer when both
operands are.  A literal is a bool, an int or a :class:`~fractions.Fraction`.

:func:`simplify` is Storm's ``BaseExpression::simplify``, which its PRISM parser and its
instantiation of constants apply: a numerical operation of two literals is folded
exactly (never a division), a unary minus, ``floor`` or ``ceil`` of a literal too, a
comparison of two literals, an ``if-then-else`` with a literal condition, and ``&``,
``|``, ``=>`` with a literal operand as Storm shortens them.  Which of these folds happen
matters: a folded rational is turned into a double once, at the end (``1 - 1/10`` is the
literal ``9/10``), an unfolded one is computed in doubles by the explorer.

Errors: :class:`PrismTypeError` for an expression Storm's type checks refuse (the front
then leaves the file to Storm, which words the error).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from fractions import Fraction
from typing import Any

__all__ = ["Expr", "PrismTypeError", "literal", "variable", "node", "simplify",
           "substitute", "evaluate", "has_divide"]

BOOL, INT, DOUBLE = "bool", "int", "double"

_SYMBOL = {"PLUS": "+", "MINUS": "-", "TIMES": "*", "DIVIDE": "/", "AND": "&", "OR": "|",
           "IMPLIES": "=>", "IFF": "=", "XOR": "!=", "EQUAL": "=", "NOT_EQUAL": "!=",
           "LESS": "<", "LESS_OR_EQUAL": "<=", "GREATER": ">", "GREATER_OR_EQUAL": ">=",
           "MODULO": "%"}
_FUNCTION = {"MIN": "min", "MAX": "max", "FLOOR": "floor", "CEIL": "ceil", "POWER": "pow"}
_NUMERIC = ("PLUS", "MINUS", "TIMES", "MIN", "MAX", "POWER")
_RELATION = ("EQUAL", "NOT_EQUAL", "LESS", "LESS_OR_EQUAL", "GREATER", "GREATER_OR_EQUAL")


class PrismTypeError(Exception):
    """An expression Storm's type checks refuse (the message says which)."""


class Expr:
    """A typed PRISM expression: a literal (``op`` ``"LIT"``), a variable (``"VAR"``) or
    an operator (Storm's ``OperatorType`` name) over ``args``."""

    __slots__ = ("op", "type", "args", "value")

    def __init__(self, op: str, kind: str, args: tuple[Expr, ...] = (), value: Any = None):
        self.op, self.type, self.args, self.value = op, kind, args, value

    # ---- the stormpy Expression interface read by prism_compile and prism_program
    def is_literal(self) -> bool:
        return self.op == "LIT"

    def is_variable(self) -> bool:
        return self.op == "VAR"

    def get_identifier(self) -> str:
        return str(self.value)

    @property
    def operator(self) -> str:
        if self.op in ("LIT", "VAR"):
            raise ValueError(f"{self}: not an operator")
        return f"OperatorType.{self.op}"

    @property
    def arity(self) -> int:
        return len(self.args)

    def get_operand(self, i: int) -> Expr:
        return self.args[i]

    def has_boolean_type(self) -> bool:
        return self.type == BOOL

    def has_integer_type(self) -> bool:
        return self.type == INT

    def contains_variables(self) -> bool:
        return self.op == "VAR" or any(a.contains_variables() for a in self.args)

    def evaluate_as_bool(self) -> bool:
        return bool(evaluate(self, {}))

    def evaluate_as_int(self) -> int:
        value = evaluate(self, {})
        if isinstance(value, Fraction):
            raise PrismTypeError(f"{self} is not an integer")
        return int(value)

    def evaluate_as_rational(self) -> Fraction:
        return Fraction(evaluate(self, {}))

    def __str__(self) -> str:
        if self.op == "LIT":
            v = self.value
            if isinstance(v, bool):
                return "true" if v else "false"
            if isinstance(v, Fraction):
                text = str(v.numerator) if v.denominator == 1 else f"{v.numerator}/{v.denominator}"
                return f"({text})"
            return str(v) if v >= 0 else f"({v})"
        if self.op == "VAR":
            return str(self.value)
        a = [str(x) for x in self.args]
        if self.op == "NOT":
            return f"!({a[0]})"
        if self.op == "MINUS" and len(a) == 1:
            return f"-({a[0]})"
        if self.op == "ITE":
            return f"({a[0]} ? {a[1]} : {a[2]})"
        if self.op in _FUNCTION:
            return f"{_FUNCTION[self.op]}({', '.join(a)})"
        if self.op == "MODULO":
            return f"mod({a[0]}, {a[1]})"
        return f"({a[0]} {_SYMBOL[self.op]} {a[1]})"

    __repr__ = __str__


def literal(value: bool | int | Fraction) -> Expr:
    kind = BOOL if isinstance(value, bool) else INT if isinstance(value, int) else DOUBLE
    return Expr("LIT", kind, (), value)


def variable(name: str, kind: str) -> Expr:
    return Expr("VAR", kind, (), name)


def _numeric(e: Expr, what: str) -> None:
    if e.type == BOOL:
        raise PrismTypeError(f"{what}: {e} is not a number")


def node(op: str, *args: Expr) -> Expr:
    """The operator ``op`` over ``args``, typed as Storm types it (:class:`PrismTypeError`
    where Storm refuses the operands)."""
    kinds = [a.type for a in args]
    if op in ("AND", "OR", "IMPLIES", "IFF", "XOR", "NOT"):
        if any(k != BOOL for k in kinds):
            raise PrismTypeError(f"{op.lower()} of a number")
        return Expr(op, BOOL, args)
    if op in _RELATION:
        for a in args:
            _numeric(a, op.lower())
        return Expr(op, BOOL, args)
    if op == "ITE":
        if kinds[0] != BOOL:
            raise PrismTypeError(f"the condition {args[0]} is not Boolean")
        if (kinds[1] == BOOL) != (kinds[2] == BOOL):
            raise PrismTypeError("a condition's branches of different types")
        kind = kinds[1] if kinds[1] == kinds[2] else DOUBLE
        return Expr(op, kind, args)
    for a in args:
        _numeric(a, op.lower())
    if op in ("FLOOR", "CEIL"):
        return Expr(op, INT, args)
    if op == "MODULO":
        if any(k != INT for k in kinds):
            raise PrismTypeError("mod of a non-integer")
        return Expr(op, INT, args)
    if op == "DIVIDE":
        return Expr(op, DOUBLE, args)
    kind = INT if all(k == INT for k in kinds) else DOUBLE
    return Expr(op, kind, args)


def _truth(e: Expr) -> bool | None:
    return e.value if e.op == "LIT" and isinstance(e.value, bool) else None


def _apply(op: str, x: Any, y: Any) -> Any:
    if op == "PLUS":
        return x + y
    if op == "MINUS":
        return x - y
    if op == "TIMES":
        return x * y
    if op == "MIN":
        return min(x, y)
    if op == "MAX":
        return max(x, y)
    if op == "POWER":
        if isinstance(x, int) and isinstance(y, int):
            return int(math.pow(x, y))  # Storm: static_cast<int>(std::pow(a, b))
        if Fraction(y).denominator != 1:
            raise PrismTypeError("pow() with a fractional exponent")
        return Fraction(x) ** int(y)
    raise AssertionError(op)


def _as(kind: str, value: Any) -> Any:
    return Fraction(value) if kind == DOUBLE else int(value)


def simplify(e: Expr) -> Expr:
    """Storm's ``simplify`` of ``e`` (module docstring)."""
    if not e.args:
        return e
    args = tuple(simplify(a) for a in e.args)
    op = e.op
    lits = all(a.op == "LIT" for a in args)
    if op in _NUMERIC and lits and len(args) == 2:
        return literal(_as(e.type, _apply(op, args[0].value, args[1].value)))
    if op == "MINUS" and len(args) == 1 and lits:
        return literal(_as(e.type, -args[0].value))
    if op in ("FLOOR", "CEIL") and lits:
        f = math.floor if op == "FLOOR" else math.ceil
        return literal(int(f(args[0].value)))
    if op == "MODULO" and lits:
        x, y = args[0].value, args[1].value
        if y != 0:
            return literal(int(math.fmod(x, y)))
    if op == "NOT" and lits:
        return literal(not args[0].value)
    if op in _RELATION and lits:
        return literal(bool(evaluate(Expr(op, BOOL, args), {})))
    if op == "ITE" and args[0].op == "LIT":
        return args[1] if args[0].value else args[2]
    if op in ("AND", "OR", "IMPLIES", "IFF", "XOR"):
        short = _boolean(op, args[0], args[1])
        if short is not None:
            return short
    return Expr(op, e.type, args)


def _boolean(op: str, a: Expr, b: Expr) -> Expr | None:
    """Storm's shortening of a binary Boolean operation with a literal operand."""
    x, y = _truth(a), _truth(b)
    if x is None and y is None:
        return None
    if op == "AND":
        return b if x is True else a if x is False else a if y is True else b if y is False \
            else None
    if op == "OR":
        return a if x is True else b if x is False else b if y is True else a if y is False \
            else None
    if op == "IMPLIES":
        return b if x is True else literal(True) if x is False or y is True else None
    if x is not None and y is not None:
        return literal(x == y if op == "IFF" else x != y)
    return None


def substitute(e: Expr, values: Mapping[str, Expr]) -> Expr:
    """``e`` with each variable named in ``values`` replaced by its expression."""
    if e.op == "VAR":
        return values.get(e.value, e)
    if not e.args:
        return e
    return Expr(e.op, e.type, tuple(substitute(a, values) for a in e.args), e.value)


def has_divide(e: Expr) -> bool:
    return e.op == "DIVIDE" or any(has_divide(a) for a in e.args)


def _div(x: Any, y: Any) -> Fraction:
    if y == 0:
        raise PrismTypeError("division by zero")
    return Fraction(x) / Fraction(y)


_EVAL: dict[str, Callable[..., Any]] = {
    "NOT": lambda x: not x, "AND": lambda x, y: x and y, "OR": lambda x, y: x or y,
    "IMPLIES": lambda x, y: (not x) or y, "IFF": lambda x, y: x == y,
    "XOR": lambda x, y: x != y, "EQUAL": lambda x, y: x == y,
    "NOT_EQUAL": lambda x, y: x != y, "LESS": lambda x, y: x < y,
    "LESS_OR_EQUAL": lambda x, y: x <= y, "GREATER": lambda x, y: x > y,
    "GREATER_OR_EQUAL": lambda x, y: x >= y, "DIVIDE": _div,
    "FLOOR": lambda x: math.floor(x), "CEIL": lambda x: math.ceil(x),
}


def evaluate(e: Expr, values: Mapping[str, Any]) -> Any:
    """``e``'s exact value (a bool, an int or a Fraction), the variables from ``values``
    (:class:`PrismTypeError` for one not there)."""
    if e.op == "LIT":
        return e.value
    if e.op == "VAR":
        if e.value not in values:
            raise PrismTypeError(f"{e.value} has no value")
        return values[e.value]
    if e.op == "ITE":
        return evaluate(e.args[1] if evaluate(e.args[0], values) else e.args[2], values)
    args = [evaluate(a, values) for a in e.args]
    if e.op == "MINUS" and len(args) == 1:
        return -args[0]
    if e.op == "MODULO":
        if args[1] == 0:
            raise PrismTypeError("modulo by zero")
        return int(math.fmod(args[0], args[1]))
    if e.op in _EVAL:
        return _EVAL[e.op](*args)
    return _as(e.type, _apply(e.op, *args))
