"""The own parse of a PRISM program presented as stormpy's ``Program``, to the compile.

:func:`front_program` turns a :class:`~mitld_lp.worlds.prism_parse.Parsed` program, the
constants given and the labels to add into a :class:`Program` with the attributes
:mod:`mitld_lp.worlds.prism_compile`, :func:`~mitld_lp.worlds.prism_program.check_program`
and the naming (:mod:`mitld_lp.worlds.prism_names`, :mod:`mitld_lp.worlds.prism_origins`)
read from the program Storm gives ``load_prism`` (its constants substituted), so that the
own explorer builds the same world from either.

What Storm's parser does to a program, done here in its order: the constants defined in
the file and the formulas are substituted and every expression simplified
(:func:`~mitld_lp.worlds.prism_expr.simplify`); a command whose guard is then the
literal ``false`` is dropped (the commands keep their numbers, ``global_index``, from
before), an assignment ``x'=x`` too, and a module's variable that no command assigns
becomes a constant of its initial value; then the constants given are substituted and
every expression simplified again.  Action indices are Storm's: the plain modules'
actions in the order they first appear, then each renamed module's new ones.

Whatever Storm would refuse or this front is not sure to read as Storm does raises
:class:`Declined`: a type error, an unknown or twice declared name, an assignment to
another module's variable, a global variable assigned by a command with an action, an
action that no command keeps; the load then leaves the file to Storm, which words the
error or builds it.
"""

from __future__ import annotations

from collections.abc import Mapping
from fractions import Fraction
from typing import Any

from mitld_lp.worlds.prism_expr import (
    BOOL,
    DOUBLE,
    INT,
    Expr,
    PrismTypeError,
    literal,
    node,
    simplify,
    substitute,
    variable,
)
from mitld_lp.worlds.prism_parse import Module, Parsed

__all__ = ["Declined", "Program", "front_program", "resolve"]

_OPS = {"EQ": "EQUAL", "NEQ": "NOT_EQUAL"}


class Declined(Exception):
    """The front leaves this program to Storm (the message says why)."""


class _Var:
    def __init__(self, name: str, low: Expr | None, high: Expr | None, init: Expr) -> None:
        self.name = name
        self.lower_bound_expression, self.upper_bound_expression = low, high
        self.initial_value_expression = init


class _Assignment:
    def __init__(self, name: str, expression: Expr) -> None:
        self.variable = type("Variable", (), {"name": name})()
        self.expression = expression


class _Update:
    def __init__(self, probability: Expr, assignments: list[_Assignment]) -> None:
        self.probability_expression, self.assignments = probability, assignments


class _Command:
    def __init__(self, action: str, index: int, guard: Expr, updates: list[_Update],
                 global_index: int) -> None:
        self.action_name, self.action_index, self.is_labeled = action, index, bool(action)
        self.guard_expression, self.updates, self.global_index = guard, updates, global_index

    def __str__(self) -> str:
        ups = " + ".join(f"{u.probability_expression} : " + (" & ".join(
            f"({a.variable.name}' = {a.expression})" for a in u.assignments) or "true")
            for u in self.updates)
        return f"[{self.action_name}] {self.guard_expression} -> {ups}"


class _Module:
    def __init__(self, name: str) -> None:
        self.name = name
        self.boolean_variables: list[_Var] = []
        self.integer_variables: list[_Var] = []
        self.commands: list[_Command] = []


class _Label:
    def __init__(self, name: str, expression: Expr) -> None:
        self.name, self.expression = name, expression


class Program:
    """A program as stormpy presents one with its constants substituted (module doc)."""

    model_type = "ModelType.MDP"
    has_initial_states_expression = False
    has_undefined_constants = False

    def __init__(self) -> None:
        self.global_boolean_variables: list[_Var] = []
        self.global_integer_variables: list[_Var] = []
        self.modules: list[_Module] = []
        self.labels: list[_Label] = []
        self.actions: list[str] = [""]
        self.scope: dict[str, Expr] = {}  # name -> its expression, for a later condition

    def get_action_name(self, index: int) -> str:
        return self.actions[index]

    def substitute_formulas(self) -> Program:
        return self  # substituted already

    def expressions(self) -> list[tuple[Any, str]]:
        """``(holder, attribute)`` of every expression the simplification rewrites."""
        out: list[tuple[Any, str]] = [(lab, "expression") for lab in self.labels]
        for m in self.modules:
            for c in m.commands:
                out.append((c, "guard_expression"))
                for u in c.updates:
                    out.append((u, "probability_expression"))
                    out.extend((a, "expression") for a in u.assignments)
        return out


def resolve(raw: Any, scope: Mapping[str, Expr]) -> Expr:
    """The raw tree ``raw`` (:mod:`mitld_lp.worlds.prism_parse`) as a typed expression,
    each name from ``scope`` (:class:`Declined` for a name not there or a type error)."""
    kind = raw[0]
    if kind == "num":
        text = raw[1]
        if any(c in text for c in ".eE"):
            return literal(Fraction(text))
        return literal(int(text))
    if kind == "bool":
        return literal(raw[1])
    if kind == "id":
        if raw[1] not in scope:
            raise Declined(f"unknown name {raw[1]!r}")
        return scope[raw[1]]
    args = [resolve(a, scope) for a in raw[1:]]
    try:
        if kind in ("EQ", "NEQ") and args[0].type == BOOL and args[1].type == BOOL:
            return node("IFF" if kind == "EQ" else "XOR", *args)
        if kind == "MODULO":  # Storm's: (a >= 0) ? a % b : (a % b) + b
            a, b = args
            rest = node("MODULO", a, b)
            return node("ITE", node("GREATER_OR_EQUAL", a, literal(0)), rest,
                        node("PLUS", rest, b))
        return node(_OPS.get(kind, kind), *args)
    except PrismTypeError as exc:
        raise Declined(str(exc)) from None


def _typed(e: Expr, want: str, what: str) -> Expr:
    ok = e.type == want or (want == DOUBLE and e.type == INT)
    if not ok:
        raise Declined(f"{what}: {e} is not of type {want}")
    return e


def front_program(parsed: Parsed, given: Mapping[str, Any],
                  labels: Mapping[str, Any]) -> Program:
    """The :class:`Program` of ``parsed`` with the ``given`` constants' values and, after
    the file's labels, its Boolean formulas that no label shadows as labels of their
    name, then the raw ``labels`` (``name -> tree``) (module docstring)."""
    if parsed.model_type not in ("mdp", "nondeterministic"):
        raise Declined(f"a {parsed.model_type or 'untyped'} model, not an mdp")
    scope: dict[str, Expr] = {}
    open_: dict[str, Expr] = {}  # the given constants' values
    for name, kind, raw in parsed.constants:
        if name in scope:
            raise Declined(f"constant {name} declared twice")
        want = {"int": INT, "double": DOUBLE, "bool": BOOL}[kind]
        if raw is None:
            if name not in given:
                raise Declined(f"constant {name} has no value")
            value = given[name]
            if want == BOOL:
                ok = isinstance(value, bool)
            elif want == INT:
                ok = isinstance(value, int) and not isinstance(value, bool)
            else:
                ok = isinstance(value, int | float) and not isinstance(value, bool)
            if not ok:
                raise Declined(f"constant {name}: {value!r}")
            open_[name] = literal(Fraction(repr(value)) if isinstance(value, float) else value)
            scope[name] = variable(name, want)
        else:
            scope[name] = simplify(_typed(resolve(raw, scope), want, f"constant {name}"))
    if set(given) - {n for n, _, raw in parsed.constants if raw is None}:
        raise Declined("a value for a constant the file does not leave open")
    declared = list(parsed.globals) + [v for m in parsed.modules for v in m.variables]
    owner: dict[str, int] = {v[0]: -1 for v in parsed.globals}
    for j, m in enumerate(parsed.modules):
        owner.update({v[0]: j for v in m.variables})
    if len(owner) != len(declared) or set(owner) & set(scope):
        raise Declined("a variable declared twice or named as a constant")
    for name, bounds, _ in declared:
        scope[name] = variable(name, BOOL if bounds is None else INT)
    for name, raw in parsed.formulas:
        if name in scope:
            raise Declined(f"formula {name}: the name is taken")
        scope[name] = simplify(resolve(raw, scope))
    program = Program()
    program.scope = dict(scope)
    _declare(program, parsed, scope)
    _commands(program, parsed, scope, owner)
    shadowed = {name for name, _ in parsed.labels}
    formulas = [(name, ("id", name, 0)) for name, _ in parsed.formulas
                if name not in shadowed and scope[name].type == BOOL]
    for name, raw in list(parsed.labels) + formulas + list(labels.items()):
        if name in {lab.name for lab in program.labels} or name in ("init", "deadlock"):
            raise Declined(f"label {name!r} defined twice")
        e = _typed(simplify(resolve(raw, scope)), BOOL, f"label {name}")
        program.labels.append(_Label(name, e))
    _constants_of_unassigned(program)
    if open_:
        for holder, attribute in program.expressions():
            setattr(holder, attribute, simplify(substitute(getattr(holder, attribute), open_)))
        for var in _all_variables(program):
            for attribute in ("lower_bound_expression", "upper_bound_expression",
                              "initial_value_expression"):
                e = getattr(var, attribute)
                if e is not None:
                    setattr(var, attribute, substitute(e, open_))
        program.scope = {k: substitute(v, open_) for k, v in program.scope.items()}
    return program


def _all_variables(program: Program) -> list[_Var]:
    out = program.global_boolean_variables + program.global_integer_variables
    for m in program.modules:
        out = out + m.boolean_variables + m.integer_variables
    return out


def module_scope(parsed: Parsed, m: Module, scope: dict[str, Expr]) -> dict[str, Expr]:
    """The names as module ``m`` reads them: a renamed module's base's names renamed, and
    the formulas expanded under the renaming (``lfree`` of ``phil2`` reads ``p3``)."""
    if not m.renamed:
        return scope
    inner = dict(scope)
    for old, new in m.renaming.items():
        if new in scope:
            inner[old] = scope[new]
    for name, raw in parsed.formulas:
        if name not in m.renaming:
            inner[name] = simplify(resolve(raw, inner))
    return inner


def _declare(program: Program, parsed: Parsed, scope: dict[str, Expr]) -> None:
    def made(name: str, bounds: Any, raw_init: Any) -> tuple[_Var, bool]:
        if bounds is None:
            init = literal(False) if raw_init is None else _typed(
                resolve(raw_init, scope), BOOL, f"the initial value of {name}")
            return _Var(name, None, None, simplify(init)), True
        low = _typed(resolve(bounds[0], scope), INT, f"the bounds of {name}")
        high = _typed(resolve(bounds[1], scope), INT, f"the bounds of {name}")
        init = low if raw_init is None else _typed(resolve(raw_init, scope), INT,
                                                   f"the initial value of {name}")
        return _Var(name, low, high, simplify(init)), False

    for name, bounds, init in parsed.globals:
        var, boolean = made(name, bounds, init)
        (program.global_boolean_variables if boolean else
         program.global_integer_variables).append(var)
    outer = scope
    for m in parsed.modules:
        module = _Module(m.name)
        scope = module_scope(parsed, m, outer)
        for name, bounds, init in m.variables:
            var, boolean = made(name, bounds, init)
            (module.boolean_variables if boolean else module.integer_variables).append(var)
        program.modules.append(module)


def _commands(program: Program, parsed: Parsed, scope: dict[str, Expr],
              owner: dict[str, int]) -> None:
    index: dict[str, int] = {"": 0}
    for m in parsed.modules:
        if not m.renamed:
            for action, _, _ in m.commands:
                index.setdefault(action, len(index))
    for m in parsed.modules:
        if m.renamed:
            new = [a for a in dict.fromkeys(a for a, _, _ in m.commands) if a not in index]
            if len(new) > 1:
                _check_renamed_order(parsed, m, index)
            for action in new:
                index[action] = len(index)
    program.actions = list(index)
    kept: set[str] = set()
    k = 0
    outer = scope
    for j, (m, module) in enumerate(zip(parsed.modules, program.modules, strict=True)):
        scope = module_scope(parsed, m, outer)
        for action, raw_guard, raw_updates in m.commands:
            k += 1
            guard = simplify(_typed(resolve(raw_guard, scope), BOOL, "a guard"))
            updates = []
            for raw_p, raw_assignments in raw_updates:
                p = literal(1) if raw_p is None else simplify(
                    _typed(resolve(raw_p, scope), DOUBLE, "a probability"))
                seen: set[str] = set()
                assignments = []
                for name, raw in raw_assignments:
                    if owner.get(name, -2) not in (j, -1) or name in seen:
                        raise Declined(f"an assignment to {name} in module {m.name}")
                    if owner[name] == -1 and action:
                        raise Declined(f"global {name} assigned by a command with an action")
                    seen.add(name)
                    e = simplify(_typed(resolve(raw, scope), outer[name].type,
                                        f"an assignment to {name}"))
                    if not (e.op == "VAR" and e.value == name):  # Storm drops x'=x
                        assignments.append(_Assignment(name, e))
                updates.append(_Update(p, assignments))
            if guard.op == "LIT" and guard.value is False:
                continue  # Storm's parser drops the command (its number stays used)
            kept.add(action)
            module.commands.append(_Command(action, index[action], guard, updates, k - 1))
    if set(index) - kept - {""}:
        raise Declined("an action whose commands are all dropped")


def _check_renamed_order(parsed: Parsed, m: Any, index: dict[str, int]) -> None:
    """Refuse where Storm could number the renamed module ``m``'s new actions otherwise:
    its base's actions not numbered in the order the base's commands first show them."""
    base = next(b for b in parsed.modules if b.name == m.base)
    first = [a for a in dict.fromkeys(a for a, _, _ in base.commands) if a]
    if [index[a] for a in first] != sorted(index[a] for a in first):
        raise Declined(f"module {m.name}: its base's actions are numbered out of order")


def _constants_of_unassigned(program: Program) -> None:
    """A module variable no command assigns becomes a constant of its initial value."""
    values: dict[str, Expr] = {}
    for m in program.modules:
        written = {a.variable.name for c in m.commands for u in c.updates
                   for a in u.assignments}
        for attribute in ("boolean_variables", "integer_variables"):
            kept = []
            for var in getattr(m, attribute):
                if var.name in written:
                    kept.append(var)
                else:
                    values[var.name] = var.initial_value_expression
            setattr(m, attribute, kept)
    if not values:
        return
    for holder, attribute in program.expressions():
        setattr(holder, attribute, simplify(substitute(getattr(holder, attribute), values)))
    program.scope = {k: substitute(v, values) for k, v in program.scope.items()}
