"""Properties read and posed without Storm, for the forms :func:`pose_property` takes.

:func:`read_own` reads a property or a properties file's text
(:mod:`mitld_lp.worlds.property_parse`) against a program's :class:`Symbols` (its
labels, constants, variables and formulas: all a property needs of it), puts in the
file's defined constants and the ``--const`` values, checks the types, and gives
:class:`OwnProperty` records that pose the same :class:`Query` as Storm's reader and
:func:`pose_property` do: the property printed as Storm prints it, the same labels
``define``'d, the same refusals.  :func:`read_any` is the door's reader: ours, or
Storm's (:func:`read_properties`) for every text ours declines (R, T, S, multi-objective
queries, other filters, reward bounds, LTL, functions, a name it does not know, a text
that does not parse: Storm's answer or refusal is then today's, word for word).

:func:`symbols_of_storm` builds the :class:`Symbols` of a Storm PRISM program (its
definitions are Storm's printing); :func:`mitld_lp.worlds.prism_symbols.own_symbols`
builds the same record from our own parse of the PRISM text, printed as Storm prints
it, so that a file the own parse takes is read without stormpy.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass
from fractions import Fraction
from typing import Any

from mitld_lp.worlds.prism_symbols import Symbols
from mitld_lp.worlds.properties import (
    PropertyError,
    Query,
    StatePoser,
    objective_of,
    refusal,
)
from mitld_lp.worlds.property_parse import (
    Decline,
    PropertySyntaxError,
    parse_expression_text,
    parse_properties_text,
)

__all__ = ["Symbols", "OwnProperty", "symbols_of_storm", "symbols_of", "read_own", "read_any",
           "print_formula"]


def symbols_of_storm(program: Any, labels: Mapping[str, str], *,
                     chain: bool = False) -> Symbols:
    """The :class:`Symbols` of Storm's PRISM ``program`` (``labels``: its labels as
    :class:`~mitld_lp.worlds.properties.Program` holds them)."""
    kinds = {"int": "int", "bool": "bool", "rational": "double", "double": "double"}
    constants = {}
    for c in program.constants:
        kind = kinds.get(str(c.type).rsplit(".", 1)[-1].lower())
        if kind is None:
            raise Decline(f"the constant {c.name!r} of type {c.type}")
        constants[c.name] = (kind, str(c.definition) if c.defined else None)
    variables = {}
    for owner in (program, *program.modules):
        for attr, kind in (("boolean_variables", "bool"), ("integer_variables", "int"),
                           ("global_boolean_variables", "bool"),
                           ("global_integer_variables", "int")):
            for v in getattr(owner, attr, ()):
                variables[v.name] = kind
    formulas = dict(_FORMULA.findall(str(program)))  # stormpy binds no list of them
    return Symbols(dict(labels), constants, variables, formulas, chain, storm_printed=True)


def symbols_of(program: Any) -> Symbols | None:
    """The :class:`Symbols` of a :class:`~mitld_lp.worlds.properties.Program`, None for a
    JANI model or a program our reader does not take (Storm's reader then reads its
    properties)."""
    if program.jani:
        return None
    if program.symbols is not None:  # our own parse's (prism_symbols): no stormpy
        return program.symbols
    try:
        return symbols_of_storm(program.program, program.labels, chain=program.chain)
    except Decline:
        return None


_FORMULA = re.compile(r"^formula (\w+) = (.*);$", re.MULTILINE)


# --------------------------------------------------------------------------- printing

_NUMERIC = ("int", "double")


def print_expression(e: tuple) -> str:
    """An expression as Storm prints it (every binary operation in parentheses)."""
    tag = e[0]
    if tag == "lit":
        if e[1] == "bool":
            return "true" if e[2] else "false"
        value = Fraction(e[2])
        return str(value.numerator) if value.denominator == 1 else \
            f"{value.numerator}/{value.denominator}"
    if tag == "var":
        return e[1]
    if tag == "not":
        return f"!({print_expression(e[1])})"
    if tag == "neg":
        return f"-({print_expression(e[1])})"
    if tag == "ite":
        return "({} ? {} : {})".format(*map(print_expression, e[1:]))
    if tag == "call":
        inner = f"{e[1]}({', '.join(map(print_expression, e[2:]))})"
        return f"({inner})" if e[1] in ("min", "max") else inner  # as Storm prints them
    return f"({print_expression(e[2])} {e[1]} {print_expression(e[3])})"


def print_formula(f: tuple, within: str = "") -> str:
    """A state, path or P formula as Storm prints it, alone (``within`` ``""``), as the
    operand of ``F``, ``G``, ``X`` or ``!`` (``"unary"``), or of ``&``, ``|`` or ``U``
    (``"binary"``): Storm's parentheses depend on where a formula stands."""
    tag = f[0]
    if tag == "label":
        return f'"{f[1]}"'
    if tag == "boollit":
        return "true" if f[1] else "false"
    if tag == "atom":
        shown = print_expression(f[1])
        return f"({shown})" if within and f[1][0] in ("var", "lit") else shown
    if tag == "fnot":
        shown = f"!{print_formula(f[1], 'unary')}"
        return f"({shown})" if within == "binary" else shown
    if tag == "fbin":
        shown = f"{print_formula(f[2], 'binary')} {f[1]} {print_formula(f[3], 'binary')}"
        return f"({shown})" if within else shown
    if tag == "F" and f[1] is None:
        return f"F {print_formula(f[2], 'unary')}"
    if tag in ("G", "X"):
        return f"{tag} {print_formula(f[1], 'unary')}"
    if tag in ("F", "U"):
        left, right = _sides(f)
        return (f"{print_formula(left, 'binary')} U{_bound(f[1])} "
                f"{print_formula(right, 'binary')}")
    optimality, comparison, threshold, path = f[1:]
    ask = "=?" if comparison is None else comparison + print_expression(threshold)
    return f"P{optimality or ''}{ask} [{print_formula(path)}]"


def _sides(f: tuple) -> tuple[tuple, tuple]:
    """The two sides of an until (``F<=k phi`` is Storm's ``true U<=k phi``)."""
    return (("boollit", True), f[2]) if f[0] == "F" else (f[2], f[3])


def _bound(b: tuple | None) -> str:
    if b is None:
        return ""
    if b[0] == "[]":
        return f"[{print_expression(b[1])}, {print_expression(b[2])}]"
    return f"{b[0]}{print_expression(b[1])}"


# --------------------------------------------------------------------------- resolving


class _Resolver:
    """Names put in (defined constants, formulas, ``--const`` values) and types checked,
    as Storm's reader does."""

    def __init__(self, symbols: Symbols, own: Mapping[str, Any], given: Mapping[str, Any],
                 where: str) -> None:
        self.symbols, self.own, self.given, self.where = symbols, own, given, where
        self.open_used: set[str] = set()
        self.cache: dict[str, tuple[tuple, str]] = {}
        self.active: set[str] = set()

    def definition(self, name: str, text: Any, storm: bool) -> tuple[tuple, str]:
        if name in self.cache:
            return self.cache[name]
        if name in self.active:
            raise Decline(f"{name!r} defined through itself")
        self.active.add(name)
        tree = text if isinstance(text, tuple) else parse_expression_text(
            text, name, storm_printed=storm)
        out = self.expression(tree)
        self.active.discard(name)
        self.cache[name] = out
        return out

    def value(self, name: str, kind: str) -> tuple[tuple, str]:
        value = self.given[name]
        if isinstance(value, bool) != (kind == "bool"):
            raise Decline(f"--const {name}: a value of another type")
        if isinstance(value, bool):
            return ("lit", "bool", value), "bool"
        if isinstance(value, int):
            return ("lit", "int", value), kind
        return ("lit", "rat", Fraction(str(value))), kind

    def name(self, name: str) -> tuple[tuple, str]:
        s = self.symbols
        if name in self.own:  # a constant of the properties file
            kind, tree = self.own[name]
            if tree is not None:
                return self.definition(name, tree, False)
            if name in self.given:
                return self.value(name, kind)
            self.open_used.add(name)
            return ("var", name), kind
        if name in s.variables:
            return ("var", name), s.variables[name]
        if name in s.constants:
            kind, text = s.constants[name]
            if text is not None:
                return self.definition(name, text, s.storm_printed)
            if name in self.given:
                return self.value(name, kind)
            return ("var", name), kind
        if name in s.formulas:
            return self.definition(name, s.formulas[name], s.storm_printed)
        raise Decline(f"the name {name!r} is not the program's")

    def expression(self, e: tuple) -> tuple[tuple, str]:
        tag = e[0]
        if tag == "lit":
            return e, {"int": "int", "rat": "double", "bool": "bool"}[e[1]]
        if tag == "id":
            return self.name(e[1])
        if tag in ("not", "neg"):
            inner, kind = self.expression(e[1])
            if (kind == "bool") != (tag == "not"):
                raise Decline("an operand of the wrong type")
            return (tag, inner), kind
        if tag in ("ite", "call"):
            return self.function(e)
        op = e[1]
        (a, ka), (b, kb) = self.expression(e[2]), self.expression(e[3])
        if op in ("|", "=>", "&"):
            ok, kind = ka == kb == "bool", "bool"
        elif op in ("=", "!="):
            ok, kind = (ka == kb == "bool") or (ka in _NUMERIC and kb in _NUMERIC), "bool"
        elif op in ("<", "<=", ">", ">="):
            ok, kind = ka in _NUMERIC and kb in _NUMERIC, "bool"
        else:
            ok = ka in _NUMERIC and kb in _NUMERIC
            kind = "int" if ka == kb == "int" and op != "/" else "double"
        if not ok:
            raise Decline("an operand of the wrong type")
        return ("bin", op, a, b), kind

    def function(self, e: tuple) -> tuple[tuple, str]:
        """A condition ``c ? a : b`` or a function of Storm's printing, typed as Storm
        types them (``min``/``max`` an integer of integers, ``floor``/``ceil`` one)."""
        if e[0] == "ite":
            (c, kc), (a, ka), (b, kb) = (self.expression(x) for x in e[1:])
            if kc != "bool" or (ka == "bool") != (kb == "bool"):
                raise Decline("a condition of the wrong type")
            return ("ite", c, a, b), ka if ka == kb else "double"
        parts = [self.expression(x) for x in e[2:]]
        if any(kind not in _NUMERIC for _, kind in parts):
            raise Decline("a function of the wrong type")
        kind = "int" if e[1] in ("floor", "ceil") or all(k == "int" for _, k in parts) \
            else "double"
        return ("call", e[1], *(x for x, _ in parts)), kind

    def state(self, f: tuple) -> tuple:
        tag = f[0]
        if tag == "atom":
            e, kind = self.expression(f[1])
            if kind != "bool":
                raise Decline("a state formula that is not Boolean")
            return ("atom", e)
        if tag == "fnot":
            return ("fnot", self.state(f[1]))
        if tag == "fbin":
            return ("fbin", f[1], self.state(f[2]), self.state(f[3]))
        return f

    def bound(self, b: tuple | None) -> tuple | None:
        if b is None:
            return None
        parts = [self.expression(x) for x in b[1:]]
        if any(kind == "bool" for _, kind in parts):
            raise Decline("a Boolean bound")
        return (b[0], *(e for e, _ in parts))

    def path(self, f: tuple) -> tuple:
        tag = f[0]
        if tag == "F":
            return ("F", self.bound(f[1]), self.state(f[2]))
        if tag in ("G", "X"):
            return (tag, self.state(f[1]))
        if tag == "U":
            return ("U", self.bound(f[1]), self.state(f[2]), self.state(f[3]))
        return self.state(f)

    def prop(self, f: tuple) -> tuple:
        _, optimality, comparison, threshold, path = f
        if threshold is not None:
            threshold, kind = self.expression(threshold)
            if kind == "bool":
                raise Decline("a Boolean threshold")
        return ("P", optimality, comparison, threshold, self.path(path))


def _evaluate(e: tuple) -> Fraction:
    """A closed number expression's value (:class:`Decline` when it has an open name)."""
    tag = e[0]
    if tag == "lit":
        return Fraction(e[2])
    if tag == "neg":
        return -_evaluate(e[1])
    if tag != "bin" or e[1] not in "+-*/":
        raise Decline("a threshold that is not a number")
    a, b = _evaluate(e[2]), _evaluate(e[3])
    if e[1] == "/":
        if b == 0:
            raise Decline("a threshold divided by zero")
        return a / b
    return {"+": a + b, "-": a - b, "*": a * b}[e[1]]


# --------------------------------------------------------------------------- posing


@dataclass(frozen=True)
class OwnProperty:
    """A property read by our reader: its name (``""`` when the file gives none) and
    its tree with the names put in; Storm's property's ``get_name`` and ``__str__``."""

    name: str
    formula: tuple

    def get_name(self) -> str:
        return self.name

    def text(self) -> str:
        return print_formula(self.formula)

    def pose(self, name: str, labels: Mapping[str, str],
             reserved: frozenset[str] = frozenset(), *, chain: bool = False) -> Query:
        """The task, as :func:`~mitld_lp.worlds.properties.pose_property` poses Storm's
        reading of the same property."""
        _, optimality, comparison, threshold, path = self.formula
        text = self.text()
        value = None if threshold is None else _evaluate(threshold)
        objective, comparison, value = objective_of(
            name, text, optimality, comparison, value, chain=chain)
        poser = StatePoser(name, text, labels, reserved)
        spec = _pose_path(poser, path)
        return Query(name=name, text=text, spec=spec, define=poser.define,
                     objective=objective, comparison=comparison, threshold=value)


class _Shown:
    """A formula whose ``str`` is its Storm printing (for :meth:`StatePoser.bound`)."""

    def __init__(self, text: str) -> None:
        self.shown = text

    def __str__(self) -> str:
        return self.shown


def _pose_path(poser: StatePoser, f: tuple) -> str:
    """The path formula's task, read from the printings :class:`StatePoser` reads of
    Storm's formula (each operand printed alone; ``X``'s from its path's printing)."""
    tag = f[0]
    if tag == "F" and f[1] is None:
        return f"F {poser.state(print_formula(f[2]))}"
    if tag == "G":
        return f"G {poser.state(print_formula(f[1]))}"
    if tag == "X":
        return f"X {poser.state(print_formula(f)[2:])}"
    if tag in ("F", "U"):
        left, right = (print_formula(side) for side in _sides(f))
        if f[1] is not None:
            a, b = poser.bound(_Shown(print_formula(f)), _Shown(left))
            lhs, target = poser.state(left), poser.state(right)
            return f"F[{a},{b}] {target}" if lhs == "true" else \
                f"{lhs} U[{a},{b}] {target}"
        return f"{poser.state(left)} U {poser.state(right)}"
    raise refusal(poser.name, poser.text, "a state formula where a path formula belongs",
                  "the property asks nothing over time")


# --------------------------------------------------------------------------- reading


def read_own(symbols: Symbols, text: str, where: str,
             constants: Mapping[str, Any] | None = None) -> list[OwnProperty]:
    """The properties of ``text`` read by our reader against ``symbols`` with the
    ``constants`` given (:class:`Decline` for a form it leaves to Storm's reader;
    :class:`PropertyError` for a constant the properties leave without a value, as
    Storm's reader says it)."""
    file_constants, props = parse_properties_text(text, where)
    own: dict[str, tuple[str, Any]] = {}
    for c in file_constants:
        if c.name in own or c.name in symbols.constants or c.name in symbols.variables \
                or c.name in symbols.formulas:
            raise Decline(f"the constant {c.name!r} declared again")
        own[c.name] = (c.kind, c.value)
    resolver = _Resolver(symbols, own, dict(constants or {}), where)
    resolved = [(p.name, resolver.prop(p.formula)) for p in props]
    missing = sorted(resolver.open_used)
    if missing:
        raise PropertyError(f"{where}: constants {', '.join(missing)} have no value: give "
                            "them with --const NAME=VALUE")
    return [OwnProperty(name or str(i), formula)
            for i, (name, formula) in enumerate(resolved, 1)]


def read_any(program: Any, text: str, where: str,
             constants: Mapping[str, Any] | None = None) -> list[Any]:
    """The door's reading of ``text`` for ``program`` (a
    :class:`~mitld_lp.worlds.properties.Program`): ours when it covers the text, else
    Storm's (:func:`~mitld_lp.worlds.properties.read_properties`)."""
    from mitld_lp.worlds.properties import read_properties

    symbols = symbols_of(program)
    if symbols is not None:
        try:
            return list(read_own(symbols, text, where, constants))
        except (Decline, PropertySyntaxError):
            pass  # Storm's reader reads it, or words the error as today
    return read_properties(program.program, text, where, constants)
