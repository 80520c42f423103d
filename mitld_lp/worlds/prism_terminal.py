"""Where a task is decided whatever happens next: the world states Storm need not expand.

Storm, given a property such as ``Pmax=? [F "goal"]``, does not explore past a goal
state: the answer no longer depends on what follows.  :func:`decided` computes the same
for an MITLD task: a condition on a world state's labels such that, at any step whose
world state satisfies it, the truth of the formula at step 0 is already fixed by the
steps so far (docs/semantics.md: step 0 is the initial state, every later step one
move).  Making such states absorbing (Storm's *terminal states*) changes no answer.

The condition is computed from three sound under-approximations, for a subformula ``f``
read at the current step ``i`` (``p`` a label of the world, ``e`` an event):

* ``T(f)``: the state's labels make ``f`` true at step ``i`` (``T(p) = p``, ``T(e) =
  false``: an event is not a property of the state);
* ``N(f)``: they make ``f`` false at step ``i``;
* ``C(f)``: ``f`` is decided at every step ``j <= i``.  ``C(p) = C(e) = true`` (the
  letters of steps ``<= i`` are known); ``C`` of a conjunction or disjunction is the
  conjunction of its parts' ``C``; ``C(a U[0,u] b) = C(a) & C(b) & (T(b) | N(a))`` (at
  every earlier ``j`` the until is either decided before ``i`` or decided at ``i``: by
  ``b``, or by ``!a & !b``; a window ending before ``i`` is decided by the prefix);
  ``a R b`` is ``!(!a U !b)``; a window that opens later than ``i`` (``U[l,u]`` with
  ``l > 0``), ``X`` and ``D[mu] a`` give ``false`` (no state is decided by them).

The task's condition is ``C(formula)``; ``false`` means every state is expanded.  For
``F goal`` it is ``goal``; for ``!crash U goal`` it is ``goal | crash``; for
``G !cliff`` it is ``cliff``; for ``F goal & D[mu] bus`` it is ``false``.
"""

from __future__ import annotations

from collections.abc import Mapping

from mitld_lp.logic.syntax import And, Const, Dist, Formula, Next, Not, Or, Prop, Release, Until

__all__ = ["Condition", "decided", "render"]

Condition = bool | str | tuple
"""``True``, ``False``, a label name, ``("not", c)``, ``("and", c, d)``, ``("or", c, d)``."""


def _not(c: Condition) -> Condition:
    if isinstance(c, bool):
        return not c
    if isinstance(c, tuple) and c[0] == "not":
        return c[1]
    return ("not", c)


def _and(c: Condition, d: Condition) -> Condition:
    if c is False or d is False:
        return False
    if c is True:
        return d
    if d is True or c == d:
        return c
    return ("and", c, d)


def _or(c: Condition, d: Condition) -> Condition:
    if c is True or d is True:
        return True
    if c is False:
        return d
    if d is False or c == d:
        return c
    return ("or", c, d)


def _fold(op: str, parts: list[Condition]) -> Condition:
    out: Condition = op == "and"
    for part in parts:
        out = _and(out, part) if op == "and" else _or(out, part)
    return out


def decided(formula: Formula, labels: frozenset[str]) -> Condition:
    """The condition on a state's ``labels`` (the world's propositions; every other
    proposition is an event) under which ``formula`` is decided (module docstring)."""

    def true_(f: Formula) -> Condition:
        match f:
            case Const(value=v):
                return v
            case Prop(name=n):
                return n if n in labels else False
            case Not(arg=a):
                return false_(a)
            case And(args=args):
                return _fold("and", [true_(a) for a in args])
            case Or(args=args):
                return _fold("or", [true_(a) for a in args])
            case Until(left=_, right=b, interval=iv) if iv is None or iv.lo == 0:
                return true_(b)
            case Release(left=a, right=b, interval=iv) if iv is None or iv.lo == 0:
                return _and(true_(a), true_(b))
        return False

    def false_(f: Formula) -> Condition:
        match f:
            case Const(value=v):
                return not v
            case Prop(name=n):
                return _not(n) if n in labels else False
            case Not(arg=a):
                return true_(a)
            case And(args=args):
                return _fold("or", [false_(a) for a in args])
            case Or(args=args):
                return _fold("and", [false_(a) for a in args])
            case Until(left=a, right=b, interval=iv):
                if iv is None or iv.lo == 0:
                    return _and(false_(a), false_(b))
                return false_(a)  # the window opens later: a must hold now
            case Release(left=_, right=b, interval=iv) if iv is None or iv.lo == 0:
                return false_(b)
        return False

    def fixed(f: Formula) -> Condition:
        match f:
            case Const() | Prop():
                return True
            case Not(arg=a):
                return fixed(a)
            case And(args=args) | Or(args=args):
                return _fold("and", [fixed(a) for a in args])
            case Until(left=a, right=b, interval=iv) if iv is None or iv.lo == 0:
                return _and(_and(fixed(a), fixed(b)), _or(true_(b), false_(a)))
            case Release(left=a, right=b, interval=iv) if iv is None or iv.lo == 0:
                return _and(_and(fixed(a), fixed(b)), _or(false_(b), true_(a)))
            case Next() | Dist() | Until() | Release():
                return False
        return False

    return fixed(formula)


def render(condition: Condition, expression: Mapping[str, str]) -> str:
    """``condition`` as a PRISM expression, each label replaced by ``expression[label]``
    (its definition, parenthesised)."""
    if condition is True:
        return "true"
    if condition is False:
        return "false"
    if isinstance(condition, str):
        return f"({expression[condition]})"
    op, *parts = condition
    if op == "not":
        return f"!{render(parts[0], expression)}"
    joiner = " & " if op == "and" else " | "
    return "(" + joiner.join(render(p, expression) for p in parts) + ")"
