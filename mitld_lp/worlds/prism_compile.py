"""A PRISM MDP compiled to flat arrays for the own explorer (:mod:`mitld_lp.worlds.prism_explore`).

:func:`compile_program` reads a stormpy ``Program`` whose constants are given (the load's
``program.substitute_constants()``; its formulas are substituted here) and gives a
:class:`Compiled`: the state variables (Booleans and bounded integers, global first, then
each module's, Booleans before integers as Storm's ``VariableInformation`` orders them)
with their ranges and initial values, every command's guard, its updates' probabilities
and assignments, each label's expression and the decided-states condition, each
expression as bytecode for a stack machine over float64 (:data:`OPS`; an integer value
is exact in a double up to 2^53, and Storm's own evaluator of a double model computes in
doubles as well).  Anything outside that fragment raises :class:`Unsupported` with the
reason (an operator not compiled, an unbounded or too wide variable, an ``init ...
endinit`` block, a model that is no MDP): the
load then builds with Storm.

The choices are listed in Storm's order (``PrismNextStateGenerator``): first the
*asynchronous* commands -- without an action, or of an action only one module has -- in
module and command order; then each action that several modules have, by its index in
the program, one choice per combination of enabled commands (one from each module that
has the action, the last module's command varying fastest)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Any

import numpy as np

__all__ = ["Unsupported", "Compiled", "compile_program", "compile_expression", "OPS"]

OPS = {name: k for k, name in enumerate((
    "CONST", "LOAD", "NOT", "NEG", "AND", "OR", "XOR", "IMPLIES", "IFF", "PLUS", "MINUS",
    "TIMES", "DIVIDE", "EQUAL", "NOT_EQUAL", "LESS", "LESS_OR_EQUAL", "GREATER",
    "GREATER_OR_EQUAL", "MIN", "MAX", "FLOOR", "CEIL", "POWER", "MODULO", "ITE",
    "COMPARE"))}
"""The stack machine's operations: ``CONST k`` pushes constant ``k``, ``LOAD v`` variable
``v``'s value; the others pop their operands and push the result (a truth value as 1.0 or
0.0; ``MODULO`` as C's ``fmod``, ``DIVIDE`` in doubles); ``COMPARE v k r`` is ``LOAD v,
CONST k`` and the comparison ``r`` (``EQUAL`` ... ``GREATER_OR_EQUAL``) in one step."""

MAX_BITS = 62
"""The widest integer variable compiled (a state is packed in 64-bit words)."""


class Unsupported(Exception):
    """The program is outside the own explorer's fragment (the message says why)."""


@dataclass
class Compiled:
    """A program as arrays (see the module docstring).

    ``code``/``consts`` hold every expression, expression ``e`` being
    ``code[starts[e]:starts[e + 1]]``; a command's guard, an update's probability and an
    assignment's value are expression numbers.  Variable ``v`` is stored in bits
    ``shift[v]`` upward of word ``word[v]`` of a packed state, as its value minus
    ``low[v]`` (``width[v]`` bits)."""

    names: list[str] = field(default_factory=list)
    booleans: list[int] = field(default_factory=list)
    low: list[int] = field(default_factory=list)
    high: list[int] = field(default_factory=list)
    initial: list[int] = field(default_factory=list)
    code: list[int] = field(default_factory=list)
    consts: list[float] = field(default_factory=list)
    starts: list[int] = field(default_factory=lambda: [0])
    # commands (in the order the choices list them, see the module docstring)
    cmd_guard: list[int] = field(default_factory=lambda: [0])  # offsets into conj
    conj: list[int] = field(default_factory=list)  # the guards' conjuncts
    cmd_name: list[str] = field(default_factory=list)  # action, or <module>_cmd<k>
    cmd_labelled: list[bool] = field(default_factory=list)
    cmd_global: list[int] = field(default_factory=list)  # Storm's global command index
    cmd_text: list[str] = field(default_factory=list)  # <module>_cmd<k>
    cmd_k: list[int] = field(default_factory=list)  # the commands a choice of it joins
    cmd_updates: list[int] = field(default_factory=lambda: [0])  # offsets into upd_*
    upd_prob: list[int] = field(default_factory=list)
    upd_assign: list[int] = field(default_factory=lambda: [0])  # offsets into asg_*
    asg_var: list[int] = field(default_factory=list)
    asg_expr: list[int] = field(default_factory=list)
    n_async: int = 0  # commands [0, n_async) are asynchronous
    # synchronised actions: action a's modules are sync_mod[sync_start[a]:...]; module
    # slot j's commands are sync_cmd[mod_start[j]:mod_start[j + 1]]
    sync_start: list[int] = field(default_factory=lambda: [0])
    mod_start: list[int] = field(default_factory=lambda: [0])
    sync_cmd: list[int] = field(default_factory=list)
    labels: list[str] = field(default_factory=list)
    label_expr: list[int] = field(default_factory=list)
    terminal: int = -1  # the decided-states condition's expression, -1: none
    action_names: list[str] = field(default_factory=list)  # of the synchronised actions

    def arrays(self) -> dict[str, np.ndarray]:
        """The kernel's inputs as numpy arrays (:mod:`mitld_lp.worlds.prism_explore`)."""
        word, shift, width, bit = [], [], [], 0
        for lo, hi in zip(self.low, self.high, strict=True):
            w = max(1, int(hi - lo).bit_length())
            if bit // 64 != (bit + w - 1) // 64:  # no field across two words
                bit = (bit // 64 + 1) * 64
            word.append(bit // 64)
            shift.append(bit % 64)
            width.append(w)
            bit += w
        out = {name: np.asarray(getattr(self, name), dtype=np.int64) for name in (
            "code", "starts", "low", "high", "initial", "cmd_guard", "conj", "cmd_updates",
            "upd_prob", "upd_assign", "asg_var", "asg_expr", "sync_start", "mod_start",
            "sync_cmd", "label_expr")}
        out.update(consts=np.asarray(self.consts, dtype=float),
                   word=np.asarray(word, dtype=np.int64), shift=np.asarray(shift, dtype=np.int64),
                   width=np.asarray(width, dtype=np.int64),
                   words=np.int64(max(1, (bit + 63) // 64)))
        return out


_UNARY = {"NOT", "FLOOR", "CEIL"}
_BINARY = {"AND", "OR", "XOR", "IMPLIES", "IFF", "PLUS", "MINUS", "TIMES", "DIVIDE",
           "EQUAL", "NOT_EQUAL", "LESS", "LESS_OR_EQUAL", "GREATER", "GREATER_OR_EQUAL",
           "MIN", "MAX", "POWER", "MODULO"}


_COMPARE = {"EQUAL", "NOT_EQUAL", "LESS", "LESS_OR_EQUAL", "GREATER", "GREATER_OR_EQUAL"}


def _literal(e: Any) -> float:
    """A literal's value as Storm's build evaluates it in doubles: a rational is handed
    to its expression evaluator (exprtk) as text, its double (GMP's, truncated) written
    with 17 digits (``ToExprtkStringVisitor``), which exprtk reads back with its own
    arithmetic (:func:`exprtk_number`): ``4/5`` is 0.7999999999999999 there, ``1/5`` 0.2
    and ``9/10`` 0.9."""
    if e.has_boolean_type():
        return float(e.evaluate_as_bool())
    if e.has_integer_type():
        return float(e.evaluate_as_int())
    r = e.evaluate_as_rational()
    exact = Fraction(int(str(r.numerator)), int(str(r.denominator)))
    value = float(exact)  # nearest; GMP's mpq_get_d truncates toward zero
    if abs(Fraction(value)) > abs(exact):
        value = math.nextafter(value, 0.0)
    return exprtk_number(f"{value:.17e}")


def exprtk_number(text: str) -> float:
    """``text`` (``-d.ddde+XX``) read as exprtk's ``string_to_real`` reads a number: the
    digits before and after the point accumulated in doubles, the fraction divided by
    its power of ten, then the exponent applied by one multiplication or division by a
    power of ten (two below 1e-307)."""
    negative = text.startswith("-")
    mantissa, _, exponent = text.lstrip("+-").partition("e")
    whole, _, fraction = mantissa.partition(".")
    d = 0.0
    for ch in whole.lstrip("0"):
        d = d * 10.0 + int(ch)
    if fraction:
        t = 0.0
        for ch in fraction:
            t = t * 10.0 + int(ch)
        d += t / float(10 ** len(fraction))
    k = int(exponent) if exponent else 0
    if k >= 0:
        d = d * float(10 ** k) if k else d
    elif k >= -307:
        d = d / float(10 ** -k)
    else:
        d = d / float(10 ** 307) / float(10 ** (-k - 307))
    return -d if negative else d


def conjuncts(expr: Any) -> list[Any]:
    """The operands of ``expr``'s top-level conjunctions, left to right."""
    if not (expr.is_literal() or expr.is_variable()) and expr.arity == 2 and \
            str(expr.operator).rsplit(".", 1)[-1] == "AND":
        return conjuncts(expr.get_operand(0)) + conjuncts(expr.get_operand(1))
    return [expr]


def compile_expression(expr: Any, index: dict[str, int], out: Compiled) -> int:
    """Append ``expr``'s bytecode to ``out`` as a new expression; its number."""
    code = out.code

    def emit(e: Any) -> None:
        if e.is_literal():
            value = _literal(e)
            code.extend((OPS["CONST"], len(out.consts)))
            out.consts.append(float(value))
            return
        if e.is_variable():
            name = e.get_identifier()
            if name not in index:
                raise Unsupported(f"expression {e}: {name!r} is not a state variable")
            code.extend((OPS["LOAD"], index[name]))
            return
        try:
            op = str(e.operator).rsplit(".", 1)[-1]
        except Exception as exc:  # noqa: BLE001 - stormpy's own, for another expression
            raise Unsupported(f"expression {e}: not an operator ({exc})") from None
        arity = e.arity
        if op == "MINUS" and arity == 1:
            emit(e.get_operand(0))
            code.append(OPS["NEG"])
            return
        if op in _COMPARE and arity == 2 and e.get_operand(0).is_variable() and \
                e.get_operand(1).is_literal() and e.get_operand(0).get_identifier() in index:
            right = e.get_operand(1)  # a variable against a number: one step
            value = _literal(right)
            code.extend((OPS["COMPARE"], index[e.get_operand(0).get_identifier()],
                         len(out.consts), OPS[op]))
            out.consts.append(float(value))
            return
        if (op in _UNARY and arity == 1) or (op in _BINARY and arity == 2) or (
                op == "ITE" and arity == 3):
            for i in range(arity):
                emit(e.get_operand(i))
            code.append(OPS[op])
            return
        raise Unsupported(f"expression {e}: operator {op} of {arity} operands")

    emit(expr)
    out.starts.append(len(code))
    return len(out.starts) - 2


def _variables(program: Any, out: Compiled) -> dict[str, int]:
    """The state variables in Storm's order, into ``out``; name -> number."""
    def add(var: Any, boolean: bool) -> None:
        if boolean:
            lo, hi = 0, 1
        else:
            if var.lower_bound_expression is None or var.upper_bound_expression is None:
                raise Unsupported(f"variable {var.name}: unbounded")
            lo = var.lower_bound_expression.evaluate_as_int()
            hi = var.upper_bound_expression.evaluate_as_int()
            if hi < lo or (hi - lo).bit_length() > MAX_BITS:
                raise Unsupported(f"variable {var.name}: range {lo}..{hi}")
        init = var.initial_value_expression
        if init is None:
            raise Unsupported(f"variable {var.name}: no initial value")
        value = int(init.evaluate_as_bool()) if boolean else init.evaluate_as_int()
        out.names.append(var.name)
        if boolean:
            out.booleans.append(len(out.names) - 1)
        out.low.append(lo)
        out.high.append(hi)
        out.initial.append(value)

    for var in program.global_boolean_variables:
        add(var, True)
    for var in program.global_integer_variables:
        add(var, False)
    for module in program.modules:
        for var in module.boolean_variables:
            add(var, True)
        for var in module.integer_variables:
            add(var, False)
    return {name: k for k, name in enumerate(out.names)}


def _command(cmd: Any, name: str, index: dict[str, int], out: Compiled, text: str,
             k: int = 1) -> None:
    for part in conjuncts(cmd.guard_expression):  # tried in turn, the first false ends it
        out.conj.append(compile_expression(part, index, out))
    out.cmd_guard.append(len(out.conj))
    out.cmd_name.append(name)
    out.cmd_text.append(text)
    out.cmd_k.append(k)
    out.cmd_labelled.append(bool(cmd.is_labeled))
    out.cmd_global.append(int(cmd.global_index))
    for update in cmd.updates:
        out.upd_prob.append(compile_expression(update.probability_expression, index, out))
        for a in update.assignments:
            out.asg_var.append(index[a.variable.name])
            out.asg_expr.append(compile_expression(a.expression, index, out))
        out.upd_assign.append(len(out.asg_var))
    out.cmd_updates.append(len(out.upd_prob))


def compile_program(program: Any, terminal: Any = None) -> Compiled:
    """``program`` (its constants given) as a :class:`Compiled`; ``terminal``: the
    decided-states condition as a stormpy ``Expression`` over the state variables (None:
    every state expanded).  :class:`Unsupported` outside the fragment."""
    kind = str(program.model_type).rsplit(".", 1)[-1]
    if kind != "MDP":
        raise Unsupported(f"a {kind}, not an MDP")
    if program.has_initial_states_expression:
        raise Unsupported("an init ... endinit block")
    program = program.substitute_formulas()
    if program.has_undefined_constants:
        raise Unsupported("undefined constants")
    out = Compiled()
    index = _variables(program, out)
    modules = list(program.modules)
    owners: dict[int, list[int]] = {}  # action index -> modules with it
    for j, module in enumerate(modules):
        for a in sorted({c.action_index for c in module.commands if c.is_labeled}):
            owners.setdefault(a, []).append(j)
    names = {f"{m.name}_cmd{k}" for m in modules for k, c in enumerate(m.commands, 1)
             if not c.is_labeled}
    if names & {c.action_name for m in modules for c in m.commands if c.is_labeled}:
        raise Unsupported("an action named as a command without one")
    for module in modules:  # asynchronous commands first, in module and command order
        for k, cmd in enumerate(module.commands, start=1):
            if not cmd.is_labeled or len(owners[cmd.action_index]) == 1:
                _command(cmd, cmd.action_name if cmd.is_labeled else f"{module.name}_cmd{k}",
                         index, out, f"{module.name}_cmd{k}")
    out.n_async = len(out.cmd_name)
    for a in sorted(a for a, mods in owners.items() if len(mods) > 1):
        for j in owners[a]:
            for k, cmd in enumerate(modules[j].commands, start=1):
                if cmd.is_labeled and cmd.action_index == a:
                    out.sync_cmd.append(len(out.cmd_name))
                    _command(cmd, cmd.action_name, index, out, f"{modules[j].name}_cmd{k}",
                             len(owners[a]))
            out.mod_start.append(len(out.sync_cmd))
        out.sync_start.append(len(out.mod_start) - 1)
        out.action_names.append(program.get_action_name(a))
    for label in program.labels:
        out.labels.append(label.name)
        out.label_expr.append(compile_expression(label.expression, index, out))
    if terminal is not None:
        out.terminal = compile_expression(terminal, index, out)
    return out
