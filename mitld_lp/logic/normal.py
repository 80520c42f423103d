"""The canonical normal form of obligations (what the automaton's states are).

The smart constructors of :mod:`mitld_lp.logic.syntax` keep a formula as the user wrote
it, up to laws that hold in the strong Kleene reading of finite traces (so that
:func:`mitld_lp.logic.semantics.holds` is unchanged by them).  The automaton needs more:
two obligations with the same language should be the same formula as often as cheaply
possible, since each distinct obligation is a state before minimisation.  The canonical
constructors here start from the same flattening (:func:`mitld_lp.logic.syntax.flatten`)
and add, for infinite continuations of a prefix (the good-prefix reading of the
automaton):

* ``a U[l,u] true == true`` also when ``a == true`` (``F[l,u] true``: every step has a
  successor) and ``false U[l,u] b == false`` for ``l > 0``; dually
  ``a R[l,u] false == false`` when ``a == false`` and ``true R[l,u] b == true`` for
  ``l > 0``;
* operands are sorted by their text, so ``p & q`` and ``q & p`` are one formula;
* an operand implied by another is dropped (absorption ``a | (a & b) == a`` and interval
  containment ``F[0,1] p & F[0,3] p == F[0,1] p``, ``G[0,3] p | G[0,1] p == G[0,1] p``);
* ``U`` obligations of a disjunction (``R`` of a conjunction) with the same operands and
  overlapping or touching intervals are joined: ``a U[0,2] b | a U[2,5] b == a U[0,5] b``;
* a boolean combination nested deeper than :data:`MAX_BOOL_DEPTH` is put in disjunctive
  normal form over its temporal atoms (:func:`canonical`).

:func:`normal_form` maps a formula in negation normal form to this form, reading a
distribution eventuality ``D[mu] a`` as ``F a``.
"""

from __future__ import annotations

from collections.abc import Iterable
from functools import lru_cache

from mitld_lp.logic.syntax import (
    FALSE,
    TRUE,
    And,
    Const,
    Dist,
    Formula,
    Interval,
    Next,
    Not,
    Or,
    Prop,
    Release,
    Until,
    flatten,
)

__all__ = [
    "MAX_BOOL_DEPTH",
    "c_and",
    "c_or",
    "c_next",
    "c_until",
    "c_release",
    "canonical",
    "normal_form",
]

#: Past this ``&``/``|`` nesting depth an obligation is put in disjunctive normal form.
MAX_BOOL_DEPTH = 4


@lru_cache(maxsize=1 << 16)
def _key(f: Formula) -> str:
    # The sort key of operands; formulas are hashed once (their hash is cached), the text
    # is what makes the order independent of how the formula was built.
    return str(f)


def _absorb(items: list[Formula], kind: type) -> list[Formula]:
    """Drop operands implied by (in a disjunction) or implying (in a conjunction) another.

    Two sound rules, each a hash lookup rather than a pairwise test: absorption
    (``a | (a & b) == a``, ``a & (a | b) == a``) and interval containment for the operator
    that :func:`_join` does not merge (``F[0,1] p & F[0,3] p == F[0,1] p``,
    ``G[0,3] p | G[0,1] p == G[0,1] p``)."""
    present = set(items)
    inner = And if kind is Or else Or
    nested = Release if kind is Or else Until
    tightest: dict[tuple[Formula, Formula], list[tuple[int, int]]] = {}
    for f in items:
        if isinstance(f, nested) and f.interval is not None:  # type: ignore[attr-defined]
            iv = f.interval  # type: ignore[attr-defined]
            tightest.setdefault((f.left, f.right), []).append((iv.lo, iv.hi))  # type: ignore[attr-defined]
    out = []
    for f in items:
        if isinstance(f, inner) and any(a in present for a in f.args):  # type: ignore[attr-defined]
            continue
        if isinstance(f, nested) and f.interval is not None:  # type: ignore[attr-defined]
            lo, hi = f.interval.lo, f.interval.hi  # type: ignore[attr-defined]
            spans = tightest[(f.left, f.right)]  # type: ignore[attr-defined]
            if any(lo <= l2 and h2 <= hi and (l2, h2) != (lo, hi) for l2, h2 in spans):
                continue
        out.append(f)
    return out


def _join(items: list[Formula], kind: type) -> list[Formula]:
    """Join ``kind`` (Until in a disjunction, Release in a conjunction) obligations with
    the same operands whose intervals overlap or touch: the union of the existence
    (resp. universal) conditions over j is the condition over the union of the spans."""
    groups: dict[tuple[Formula, Formula], list[Formula]] = {}
    rest: list[Formula] = []
    for f in items:
        if isinstance(f, kind) and f.interval is not None:  # type: ignore[attr-defined]
            groups.setdefault((f.left, f.right), []).append(f)  # type: ignore[attr-defined]
        else:
            rest.append(f)
    for (left, right), fs in groups.items():
        if len(fs) == 1:
            rest.append(fs[0])
            continue
        spans = sorted((f.interval.lo, f.interval.hi) for f in fs)  # type: ignore[attr-defined]
        lo, hi = spans[0]
        for l2, h2 in spans[1:]:
            if l2 <= hi + 1:
                hi = max(hi, h2)
            else:
                rest.append(kind(left, right, Interval(lo, hi)))
                lo, hi = l2, h2
        rest.append(kind(left, right, Interval(lo, hi)))
    return rest


def _nary(kind: type[And] | type[Or], args: Iterable[Formula]) -> Formula:
    items = flatten(kind, args)
    if isinstance(items, Const):
        return items
    if len(items) > 1:
        items = _absorb(_join(items, Until if kind is Or else Release), kind)
    if not items:
        return TRUE if kind is And else FALSE
    if len(items) == 1:
        return items[0]
    return kind(tuple(sorted(items, key=_key)))


def c_and(args: Iterable[Formula]) -> Formula:
    """Canonical conjunction (see the module docstring)."""
    return _nary(And, args)


def c_or(args: Iterable[Formula]) -> Formula:
    """Canonical disjunction (see the module docstring)."""
    return _nary(Or, args)


def c_next(a: Formula) -> Formula:
    """``X a``, with ``X true == true`` and ``X false == false``."""
    return a if isinstance(a, Const) else Next(a)


def c_until(a: Formula, b: Formula, iv: Interval | None) -> Formula:
    """``a U[iv] b`` with the constant folds of the module docstring."""
    if b == FALSE or (iv is not None and a == FALSE and iv.lo > 0):
        return FALSE
    # ``a U[l,u] true`` needs ``a`` on the first l steps only: true when l == 0 or a is.
    if b == TRUE and (iv is None or iv.lo == 0 or a == TRUE):
        return TRUE
    return Until(a, b, iv)


def c_release(a: Formula, b: Formula, iv: Interval | None) -> Formula:
    """``a R[iv] b``, the dual of :func:`c_until`."""
    if b == TRUE or (iv is not None and a == TRUE and iv.lo > 0):
        return TRUE
    if b == FALSE and (iv is None or iv.lo == 0 or a == FALSE):
        return FALSE
    return Release(a, b, iv)


def normal_form(f: Formula) -> Formula:
    """The canonical form of ``f``, which must be in negation normal form (as
    :func:`mitld_lp.logic.fragment.nnf` and ``FragmentReport.nnf`` give it); ``D[mu] a``
    reads as ``F a``.  The result is :func:`canonical`."""
    return canonical(_rebuild(f))


def _rebuild(f: Formula) -> Formula:
    match f:
        case Const() | Prop() | Not(Prop()):
            return f
        case And(args):
            return c_and([_rebuild(a) for a in args])
        case Or(args):
            return c_or([_rebuild(a) for a in args])
        case Next(a):
            return c_next(_rebuild(a))
        case Dist(_, a):
            return c_until(TRUE, _rebuild(a), None)
        case Until(a, b, iv):
            return c_until(_rebuild(a), _rebuild(b), iv)
        case Release(a, b, iv):
            return c_release(_rebuild(a), _rebuild(b), iv)
    raise TypeError(f"not a formula in negation normal form: {f!r}")


def _bool_depth(f: Formula) -> int:
    if isinstance(f, And | Or):
        return 1 + max(_bool_depth(a) for a in f.args)
    return 0


def _dnf(f: Formula) -> frozenset[frozenset[Formula]]:
    """Disjunctive normal form over temporal atoms, with absorption (no term contains
    another)."""
    if f == TRUE:
        return frozenset({frozenset()})
    if f == FALSE:
        return frozenset()
    if isinstance(f, Or):
        terms = set().union(*(_dnf(a) for a in f.args))
    elif isinstance(f, And):
        terms = {frozenset()}
        for a in f.args:
            terms = {t | u for t in terms for u in _dnf(a)}
    else:
        return frozenset({frozenset({f})})
    return frozenset(t for t in terms if not any(u < t for u in terms))


def canonical(f: Formula) -> Formula:
    """``f`` itself, or its DNF when its ``&``/``|`` nesting is deeper than
    :data:`MAX_BOOL_DEPTH`.

    Progression of an unbounded ``U``/``R`` nests a new copy of its residual inside the
    previous one at every step (``b | (a & (b' | (a' & ...))))``); flattening and
    absorption do not undo that, so the obligations would grow without bound although
    only finitely many are different.  Obligations are boolean combinations of finitely
    many temporal atoms, so the DNF (a set of sets of atoms) bounds them; it is used
    only past a small depth because it can be exponentially larger."""
    if _bool_depth(f) > MAX_BOOL_DEPTH:
        return c_or([c_and(list(t)) for t in _dnf(f)])
    return f
