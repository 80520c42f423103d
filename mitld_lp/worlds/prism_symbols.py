"""What a property reads of a PRISM program, from our own parse: no stormpy.

A property (:mod:`mitld_lp.worlds.property_own`) reads its program only through a
:class:`Symbols` record: the labels' texts, the constants (kind, definition), the
variables' kinds, the formulas' texts.  :func:`own_symbols` fills it from the own parse
(:mod:`mitld_lp.worlds.prism_parse`) with every text printed as Storm prints its
program (:func:`storm_text`), so that it is the record
:func:`~mitld_lp.worlds.property_own.symbols_of_storm` builds from Storm's program:
Storm's parser simplifies each expression (:func:`~mitld_lp.worlds.prism_expr.simplify`)
and keeps the names of constants and formulas (a constant's definition has the defined
constants before it put in, after its simplification: ``2*sigma`` prints ``(2 * 1)``),
and the labels' texts reach the task's labels (a state formula over a label is written
out with the label's text).

:func:`own_symbols` gives None where the front (:mod:`mitld_lp.worlds.prism_front`)
would leave the program to Storm with the constants given (a syntax or type error, a
constant without a value, a construct outside the fragment) and where Storm's printing
is not known to be reproduced: the caller then reads the
program with Storm, whose messages stay word for word.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from mitld_lp.worlds.prism_expr import (
    BOOL,
    DOUBLE,
    INT,
    Expr,
    PrismTypeError,
    simplify,
    substitute,
)
from mitld_lp.worlds.prism_expr import variable as variable_of

__all__ = ["Symbols", "Unprinted", "storm_text", "own_symbols", "read_own_program"]


@dataclass(frozen=True)
class Symbols:
    """What a property reads of its program.

    Attributes:
        labels: ``name -> expression text`` of the file's labels.
        constants: ``name -> (kind, definition text or None)`` (kind ``int``,
            ``double``, ``bool``; None: the file leaves it open).
        variables: ``name -> kind`` (``int`` or ``bool``).
        formulas: ``name -> expression text`` (a name used and absent here is
            declined, so a reader may leave them out).
        chain: the file is a DTMC.
        storm_printed: the definition texts are Storm's printing (``1/2`` a number).
    """

    labels: Mapping[str, str]
    constants: Mapping[str, tuple[str, str | None]]
    variables: Mapping[str, str]
    formulas: Mapping[str, str] = field(default_factory=dict)
    chain: bool = False
    storm_printed: bool = False


class Unprinted(Exception):
    """An expression whose Storm printing :func:`storm_text` does not reproduce."""


_SYMBOL = {"PLUS": "+", "MINUS": "-", "TIMES": "*", "DIVIDE": "/", "AND": "&", "OR": "|",
           "IMPLIES": "=>", "IFF": "<=>", "XOR": "!=", "EQUAL": "=", "NOT_EQUAL": "!=",
           "LESS": "<", "LESS_OR_EQUAL": "<=", "GREATER": ">", "GREATER_OR_EQUAL": ">=",
           "MODULO": "%"}
_FORMS = {"NOT": "!({0})", "ITE": "({0} ? {1} : {2})", "FLOOR": "floor({0})",
          "CEIL": "ceil({0})", "MIN": "(min({0}, {1}))", "MAX": "(max({0}, {1}))",
          "POWER": "({0} ^ {1})", **{op: f"({{0}} {sign} {{1}})" for op, sign in _SYMBOL.items()}}


def storm_text(e: Expr) -> str:
    """``e`` as Storm prints an expression of its program: every binary operation in
    parentheses, ``!(a)``, ``-(a)``, ``(c ? a : b)``, ``(min(a, b))``, ``(a ^ b)``, a
    rational literal ``n/d`` (:class:`Unprinted` for another operator, and for ``a <=>
    b`` with a literal side, which Storm shortens as our simplify does not)."""
    if e.op == "LIT":
        v = e.value
        if isinstance(v, bool):
            return "true" if v else "false"
        return f"{v.numerator}/{v.denominator}" if v.denominator != 1 else str(int(v))
    if e.op == "VAR":
        return str(e.value)
    parts = [storm_text(x) for x in e.args]
    if e.op == "MINUS" and len(parts) == 1:
        return f"-({parts[0]})"
    if e.op not in _FORMS or e.op == "IFF" and any(x.op == "LIT" for x in e.args):
        raise Unprinted(e.op)
    return _FORMS[e.op].format(*parts)


_KINDS = {"int": INT, "double": DOUBLE, "bool": BOOL}


def own_symbols(parsed: Any, given: Mapping[str, Any]) -> Symbols | None:
    """The :class:`Symbols` of the own parse ``parsed`` (a
    :class:`~mitld_lp.worlds.prism_parse.Parsed` program) with the open constants'
    values ``given`` (None: leave the program to Storm; module docstring)."""
    from mitld_lp.worlds.prism_front import Declined, front_program, resolve

    try:
        front_program(parsed, {k: v for k, v in given.items() if any(
            k == name and raw is None for name, _, raw in parsed.constants)}, {})
        scope: dict[str, Expr] = {}  # every name kept, as Storm's program keeps it
        constants: dict[str, tuple[str, str | None]] = {}
        values: dict[str, Expr] = {}  # a definition reads the ones before it put in
        for name, kind, raw in parsed.constants:
            text = None
            if raw is not None:
                values[name] = substitute(simplify(resolve(raw, scope)), values)
                text = storm_text(values[name])
            constants[name] = (kind, text)
            scope[name] = variable_of(name, _KINDS[kind])
        variables = {}
        for name, bounds, _ in list(parsed.globals) + [
                v for m in parsed.modules for v in m.variables]:
            variables[name] = "bool" if bounds is None else "int"
            scope[name] = variable_of(name, BOOL if bounds is None else INT)
        formulas = {}
        for name, raw in parsed.formulas:
            e = simplify(resolve(raw, scope))
            formulas[name] = storm_text(e)
            scope[name] = variable_of(name, e.type)
        labels = {name: storm_text(simplify(resolve(raw, scope)))
                  for name, raw in parsed.labels}
    except (Declined, PrismTypeError, Unprinted, RecursionError, ZeroDivisionError,
            OverflowError, ValueError):
        return None
    return Symbols(labels, constants, variables, formulas, chain=False, storm_printed=True)


def read_own_program(path: str, given: Mapping[str, Any]) -> Symbols | None:
    """The :class:`Symbols` of the PRISM file at ``path`` read by our own parse with the
    constants ``given`` (the names it does not declare ignored here: the door names
    them), or None: Storm's builder is asked for (``MITLD_PRISM_BUILDER=storm``), or the
    file is not one the own parse takes (module docstring)."""
    from mitld_lp.worlds.prism_explore import chosen_builder
    from mitld_lp.worlds.prism_parse import Outside, PrismSyntaxError, parse

    if chosen_builder() == "storm":
        return None
    try:
        with open(path, encoding="utf-8") as f:
            parsed = parse(f.read())
    except (OSError, UnicodeDecodeError, Outside, PrismSyntaxError, RecursionError):
        return None
    return own_symbols(parsed, given)
