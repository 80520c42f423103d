"""A parser of the PRISM MDP language fragment the QVBS models use, without Storm.

:func:`parse` reads the text into a :class:`Parsed` program of raw pieces: constants,
global variables, formulas, modules (a renamed module ``module B = A [x=y, a=b]
endmodule`` copied from ``A`` with its identifiers renamed), labels; ``rewards``
blocks are skipped.  Expressions stay raw trees (``("id", name)``, ``("num", text)``,
``("bool", value)``, ``(operator, operand, ...)``) with their place, resolved and typed
by :mod:`mitld_lp.worlds.prism_front`.

Precedence as Storm's PRISM parser reads it (lowest first): ``c ? a : b`` (right to
left), ``|`` and ``=>`` (one level, left to right), ``&``, ``=`` and ``!=``, one
comparison ``< <= > >=``, ``+ -``, ``* /``, the prefixes ``-`` and ``!``.  ``<=>``,
``^``, ``init ... endinit``, ``system`` blocks, unbounded variables and model types other
than ``mdp`` are outside the fragment: :class:`Outside`, and the load leaves the file to
Storm.  A syntax error is :class:`PrismSyntaxError`, with its line and column.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any

__all__ = ["PrismSyntaxError", "Outside", "Parsed", "Module", "parse", "parse_expression"]


class PrismSyntaxError(Exception):
    """A PRISM syntax error at ``line``:``column`` (from 1)."""

    def __init__(self, message: str, line: int, column: int) -> None:
        super().__init__(f"{line}:{column}: {message}")
        self.line, self.column = line, column


class Outside(Exception):
    """A construct outside the parsed fragment (the message names it)."""


_TOKEN = re.compile(
    r"(?P<space>\s+|//[^\n]*)|(?P<num>\d+\.\d+(?:[eE][-+]?\d+)?|\.\d+(?:[eE][-+]?\d+)?"
    r"|\d+[eE][-+]?\d+|\d+)|(?P<id>[A-Za-z_][A-Za-z_0-9]*)|(?P<str>\"[^\"\n]*\")"
    r"|(?P<op><=>|->|=>|<=|>=|!=|\.\.|[-+*/&|!=<>?:;,()\[\]'{}^%])")

_KEYWORDS = {"module", "endmodule", "const", "global", "formula", "label", "rewards",
             "endrewards", "init", "endinit", "int", "double", "bool", "true", "false",
             "mdp", "nondeterministic", "system", "endsystem", "min", "max", "floor",
             "ceil", "pow", "mod", "log"}
_MODEL_TYPES = {"mdp", "nondeterministic", "dtmc", "probabilistic", "ctmc", "stochastic",
                "pta", "pomdp", "smg", "ma"}
_FUNCTIONS = {"min": "MIN", "max": "MAX", "floor": "FLOOR", "ceil": "CEIL", "pow": "POWER",
              "mod": "MODULO"}
_RELATIONS = {"<": "LESS", "<=": "LESS_OR_EQUAL", ">": "GREATER", ">=": "GREATER_OR_EQUAL"}


@dataclass
class Module:
    """A module's raw pieces; ``variables``: ``(name, bounds or None for a Boolean, init
    or None)``; ``commands``: ``(action or "", guard, [(probability or None,
    [(variable, expression)])])``."""

    name: str
    variables: list[tuple[str, tuple[Any, Any] | None, Any]] = field(default_factory=list)
    commands: list[tuple[str, Any, list[tuple[Any, list[tuple[str, Any]]]]]] = field(
        default_factory=list)
    renamed: bool = False
    base: str = ""  # the module a renamed one copies
    renaming: dict[str, str] = field(default_factory=dict)


@dataclass
class Parsed:
    """A parsed PRISM program (module docstring)."""

    model_type: str = ""
    constants: list[tuple[str, str, Any]] = field(default_factory=list)  # name, type, expr
    globals: list[tuple[str, tuple[Any, Any] | None, Any]] = field(default_factory=list)
    formulas: list[tuple[str, Any]] = field(default_factory=list)
    modules: list[Module] = field(default_factory=list)
    labels: list[tuple[str, Any]] = field(default_factory=list)


class _Tokens:
    def __init__(self, text: str) -> None:
        self.items: list[tuple[str, str, int]] = []  # kind, text, offset
        self.text = text
        pos = 0
        while pos < len(text):
            m = _TOKEN.match(text, pos)
            if m is None:
                self.fail(f"unexpected character {text[pos]!r}", pos)
            kind = m.lastgroup or ""
            if kind != "space":
                self.items.append((kind, m.group(), pos))
            pos = m.end()
        self.items.append(("end", "", len(text)))
        self.i = 0

    def place(self, offset: int) -> tuple[int, int]:
        line = self.text.count("\n", 0, offset) + 1
        return line, offset - (self.text.rfind("\n", 0, offset) + 1) + 1

    def fail(self, message: str, offset: int | None = None) -> Any:
        at = self.items[self.i][2] if offset is None else offset
        raise PrismSyntaxError(message, *self.place(at))

    def peek(self, k: int = 0) -> str:
        return self.items[min(self.i + k, len(self.items) - 1)][1]

    def kind(self) -> str:
        return self.items[self.i][0]

    def take(self) -> str:
        item = self.items[self.i]
        self.i += 1
        return item[1]

    def accept(self, text: str) -> bool:
        if self.peek() == text and self.kind() != "str":
            self.i += 1
            return True
        return False

    def expect(self, text: str) -> None:
        if not self.accept(text):
            shown = self.peek() or "the end of the file"
            self.fail(f"expecting {text!r}, found {shown!r}")

    def name(self) -> str:
        if self.kind() != "id" or self.peek() in _KEYWORDS:
            self.fail(f"expecting an identifier, found {self.peek() or 'the end'!r}")
        return self.take()


def _expression(t: _Tokens) -> Any:
    cond = _or(t)
    if t.accept("?"):
        a = _expression(t)
        t.expect(":")
        b = _expression(t)
        return ("ITE", cond, a, b)
    return cond


def _left(t: _Tokens, operand: Any, ops: dict[str, str]) -> Any:
    """Operands of ``operand`` joined by the operators ``ops``, left to right."""
    e = operand(t)
    while t.peek() in ops:
        e = (ops[t.take()], e, operand(t))
    return e


def _or(t: _Tokens) -> Any:
    return _left(t, _and, {"|": "OR", "=>": "IMPLIES"})


def _and(t: _Tokens) -> Any:
    return _left(t, _equality, {"&": "AND"})


def _equality(t: _Tokens) -> Any:
    return _left(t, _relation, {"=": "EQ", "!=": "NEQ"})


def _relation(t: _Tokens) -> Any:
    e = _plus(t)
    if t.peek() in _RELATIONS:
        e = (_RELATIONS[t.take()], e, _plus(t))
        if t.peek() in _RELATIONS:
            raise Outside("a chain of comparisons")
    return e


def _plus(t: _Tokens) -> Any:
    return _left(t, _times, {"+": "PLUS", "-": "MINUS"})


def _times(t: _Tokens) -> Any:
    return _left(t, _unary, {"*": "TIMES", "/": "DIVIDE"})


def _unary(t: _Tokens) -> Any:
    if t.accept("-"):
        return ("MINUS", _unary(t))
    if t.accept("!"):
        return ("NOT", _unary(t))
    return _atom(t)


def _atom(t: _Tokens) -> Any:
    at = t.items[t.i][2]
    kind, text = t.kind(), t.peek()
    if text in ("<=>", "^", "%", "{"):
        raise Outside(f"the operator {text!r}")
    if kind == "num":
        t.take()
        return ("num", text)
    if text in ("true", "false") and kind == "id":
        t.take()
        return ("bool", text == "true")
    if kind == "id" and text in _FUNCTIONS:
        t.take()
        t.expect("(")
        args = [_expression(t)]
        while t.accept(","):
            args.append(_expression(t))
        t.expect(")")
        want = 1 if text in ("floor", "ceil") else 2
        if len(args) != want and not (text in ("min", "max") and len(args) > 2):
            t.fail(f"{text} takes {want} arguments", at)
        e = args[0]
        for a in args[1:]:  # min(a, b, c): min(min(a, b), c)
            e = (_FUNCTIONS[text], e, a)
        return (_FUNCTIONS[text], e) if want == 1 else e
    if kind == "id" and text not in _KEYWORDS:
        t.take()
        return ("id", text, at)
    if t.accept("("):
        e = _expression(t)
        t.expect(")")
        return e
    if kind == "id" and text == "log":
        raise Outside("log()")
    return t.fail(f"expecting an expression, found {text or 'the end of the file'!r}", at)


def _bounds(t: _Tokens) -> tuple[Any, Any] | None:
    if t.accept("bool"):
        return None
    if t.accept("int") or t.peek() in ("double", "clock"):
        raise Outside("an unbounded or non-integer variable")
    t.expect("[")
    low = _expression(t)
    t.expect("..")
    high = _expression(t)
    t.expect("]")
    return (low, high)


def _variable(t: _Tokens) -> tuple[str, tuple[Any, Any] | None, Any]:
    name = t.name()
    t.expect(":")
    bounds = _bounds(t)
    init = _expression(t) if t.accept("init") else None
    t.expect(";")
    return name, bounds, init


def _assignments(t: _Tokens) -> list[tuple[str, Any]]:
    if t.accept("true"):
        return []
    out = [_assignment(t)]
    while t.accept("&"):
        out.append(_assignment(t))
    return out


def _assignment(t: _Tokens) -> tuple[str, Any]:
    t.expect("(")
    name = t.name()
    t.expect("'")
    t.expect("=")
    e = _expression(t)
    t.expect(")")
    return name, e


def _update(t: _Tokens) -> tuple[Any, list[tuple[str, Any]]]:
    bare = (t.peek() == "true" and t.peek(1) in (";", "+")) or (
        t.peek() == "(" and t.items[t.i + 1][0] == "id" and t.peek(2) == "'")
    if bare:
        return None, _assignments(t)
    p = _expression(t)
    t.expect(":")
    return p, _assignments(t)


def _command(t: _Tokens) -> tuple[str, Any, list[tuple[Any, list[tuple[str, Any]]]]]:
    t.expect("[")
    action = "" if t.peek() == "]" else t.name()
    t.expect("]")
    guard = _expression(t)
    t.expect("->")
    updates = [_update(t)]
    while t.accept("+"):
        updates.append(_update(t))
    t.expect(";")
    return action, guard, updates


def _module(t: _Tokens, out: Parsed) -> Module:
    name = t.name()
    if t.accept("="):
        base_name = t.name()
        base = next((m for m in out.modules if m.name == base_name and not m.renamed), None)
        if base is None:
            raise Outside(f"module {name} renames {base_name}, not a module before it")
        t.expect("[")
        names: dict[str, str] = {}
        while True:
            old = t.name()
            t.expect("=")
            names[old] = t.name()
            if not t.accept(","):
                break
        t.expect("]")
        t.expect("endmodule")
        if len(set(names.values())) != len(names):
            raise Outside(f"module {name}: two names renamed to one")
        module = Module(name, renamed=True, base=base_name, renaming=names)
        # the expressions stay the base's, read with the renaming (and the formulas
        # expanded under it) by prism_front
        module.variables = [(names.get(v), b, i) for v, b, i in base.variables]
        module.commands = [(names.get(a, a), g, [(p, [(names.get(x, x), e) for x, e in asg])
                                                 for p, asg in ups])
                           for a, g, ups in base.commands]
        if any(v[0] is None for v in module.variables):
            raise Outside(f"module {name}: a variable of {base_name} not renamed")
        return module
    module = Module(name)
    while not t.accept("endmodule"):
        if t.peek() == "[":
            module.commands.append(_command(t))
        elif t.kind() == "id" and t.peek() not in _KEYWORDS:
            if module.commands:
                raise Outside("a variable declared after a command")
            module.variables.append(_variable(t))
        else:
            t.fail(f"expecting a variable, a command or 'endmodule', found {t.peek()!r}")
    return module


def parse(text: str) -> Parsed:
    """The PRISM program ``text`` (module docstring)."""
    t = _Tokens(text)
    out = Parsed()
    while t.kind() != "end":
        word = t.peek()
        if word in _MODEL_TYPES and t.kind() == "id":
            if out.model_type:
                t.fail("a second model type")
            out.model_type = t.take()
        elif t.accept("const"):
            kind = t.take() if t.peek() in ("int", "double", "bool") else "int"
            name = t.name()
            e = _expression(t) if t.accept("=") else None
            t.expect(";")
            out.constants.append((name, kind, e))
        elif t.accept("global"):
            out.globals.append(_variable(t))
        elif t.accept("formula"):
            name = t.name()
            t.expect("=")
            out.formulas.append((name, _expression(t)))
            t.expect(";")
        elif t.accept("label"):
            if t.kind() != "str":
                t.fail("expecting a label's name in double quotes")
            name = t.take()[1:-1]
            t.expect("=")
            out.labels.append((name, _expression(t)))
            t.expect(";")
        elif t.accept("module"):
            out.modules.append(_module(t, out))
        elif t.accept("rewards"):
            while t.kind() != "end" and not t.accept("endrewards"):
                t.take()
        elif word in ("init", "system", "player"):
            raise Outside(f"an {word} block")
        else:
            t.fail(f"unexpected {word or 'end of the file'!r}")
    return out


def parse_expression(text: str) -> Any:
    """One PRISM expression (a label's text, the decided-states condition)."""
    t = _Tokens(text)
    e = _expression(t)
    if t.kind() != "end":
        t.fail(f"unexpected {t.peek()!r} after the expression")
    return e
