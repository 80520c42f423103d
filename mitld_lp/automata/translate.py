"""MITL (discrete time, co-safe fragment) to a minimal DTA, by formula progression.

A state is an *obligation*: a formula in negation normal form that the rest of the
trace must satisfy.  Reading a letter ``sigma`` (the propositions true at this step)
progresses it, with the strict-past semantics of DESIGN.md:

* ``p`` becomes ``true`` or ``false``;
* ``a U[0,u] b  ->  prog(b) | (prog(a) & a U[0,u-1] b)``  (the second disjunct only if u > 0);
* ``a U[l,u] b  ->  prog(a) & a U[l-1,u-1] b``  for l > 0;
* ``a R[0,u] b  ->  prog(b) & (prog(a) | a R[0,u-1] b)``,
  ``a R[l,u] b  ->  prog(a) | a R[l-1,u-1] b``  (the duals; ``G[l,u] p == false R[l,u] p``);
* unbounded ``U``/``R`` unfold the same way and stay unbounded; ``X a -> a``.

The result is normalised (flatten, absorb ``true``/``false``, sort, drop an obligation
implied by another one: ``F[0,3] p | F[0,2] p == F[0,3] p``, and join intervals that
overlap: ``a U[0,2] b | a U[2,5] b == a U[0,5] b``).  Every rule used preserves the
strong Kleene reading on finite prefixes, so the automaton accepts a finite trace
exactly when :func:`mitld_lp.logic.semantics.holds` says TRUE.  The accepting state is
``true``; reaching it is the acceptance condition.

The letter is never enumerated: one step of a state is unfolded symbolically into a
boolean combination of current-step literals and next-step obligations, and Shannon
expansion over the literals (in sorted order) yields a reduced ordered decision
diagram whose leaves are the successor obligations.  The reachable automaton is then
minimised by partition refinement on those diagrams (ordered and reduced, they are
canonical, so equal signatures mean equal transition functions), which makes its size
independent of how an equivalent formula was written, as far as the obligations'
languages coincide.
"""

from __future__ import annotations

import logging
from collections import deque
from typing import Any

from mitld_lp.automata.dta import DTA, Diagram
from mitld_lp.logic.fragment import nnf
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
)

__all__ = ["to_dta", "progress", "TranslationError"]

log = logging.getLogger(__name__)


class TranslationError(ValueError):
    """The formula is outside what the translation accepts (names the subformula)."""


# --------------------------------------------------------------------------- preparation


def _prepare(f: Formula) -> Formula:
    """Negation normal form (:func:`mitld_lp.logic.fragment.nnf`), rebuilt with the
    canonical constructors below; distribution eventualities read as ``F``."""
    return _rebuild(nnf(f))


def _rebuild(f: Formula) -> Formula:
    match f:
        case Const() | Prop() | Not(Prop()):
            return f
        case And(args):
            return _and([_rebuild(a) for a in args])
        case Or(args):
            return _or([_rebuild(a) for a in args])
        case Next(a):
            return _next(_rebuild(a))
        case Dist(_, a):
            return _until(TRUE, _rebuild(a), None)
        case Until(a, b, iv):
            return _until(_rebuild(a), _rebuild(b), iv)
        case Release(a, b, iv):
            return _release(_rebuild(a), _rebuild(b), iv)
    raise TypeError(f"not a formula in negation normal form: {f!r}")


# --------------------------------------------------------------------------- canonical form

_KEYS: dict[Formula, str] = {}


def _key(f: Formula) -> str:
    k = _KEYS.get(f)
    if k is None:
        if len(_KEYS) > 1_000_000:
            _KEYS.clear()
        k = _KEYS[f] = str(f)
    return k


def _absorb(items: list[Formula], kind: type) -> list[Formula]:
    """Drop operands implied by (in a disjunction) or implying (in a conjunction) another.

    Two sound, Kleene-preserving rules, each a hash lookup rather than a pairwise test:
    absorption (``a | (a & b) == a``, ``a & (a | b) == a``) and interval containment for
    the operator that ``_join`` does not merge (``F[0,1] p & F[0,3] p == F[0,1] p``,
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


def _nary(args, kind: type) -> Formula:
    unit, zero = (TRUE, FALSE) if kind is And else (FALSE, TRUE)
    flat: dict[Formula, None] = {}
    for a in args:
        for p in a.args if isinstance(a, kind) else (a,):
            if p == zero:
                return zero
            if p != unit:
                flat[p] = None
    items = list(flat)
    if len(items) > 1:
        items = _absorb(_join(items, Until if kind is Or else Release), kind)
    if not items:
        return unit
    if len(items) == 1:
        return items[0]
    return kind(tuple(sorted(items, key=_key)))


def _and(args) -> Formula:
    return _nary(args, And)


def _or(args) -> Formula:
    return _nary(args, Or)


def _next(a: Formula) -> Formula:
    return a if isinstance(a, Const) else Next(a)


def _until(a: Formula, b: Formula, iv: Interval | None) -> Formula:
    if b == FALSE or (iv is not None and a == FALSE and iv.lo > 0):
        return FALSE
    # ``a U[l,u] true`` needs ``a`` on the first l steps only: true when l == 0 or a is.
    if b == TRUE and (iv is None or iv.lo == 0 or a == TRUE):
        return TRUE
    return Until(a, b, iv)


def _release(a: Formula, b: Formula, iv: Interval | None) -> Formula:
    if b == TRUE or (iv is not None and a == TRUE and iv.lo > 0):
        return TRUE
    if b == FALSE and (iv is None or iv.lo == 0 or a == FALSE):
        return FALSE
    return Release(a, b, iv)


# --------------------------------------------------------------------------- progression


_UNFOLD: dict[Formula, Formula] = {}


def _unfold(f: Formula) -> Formula:
    """One step of ``f``: current-step literals combined with ``Next`` obligations."""
    r = _UNFOLD.get(f)
    if r is None:
        if len(_UNFOLD) > 1_000_000:
            _UNFOLD.clear()
        r = _UNFOLD[f] = _unfold1(f)
    return r


def _unfold1(f: Formula) -> Formula:
    match f:
        case Const() | Prop() | Not():
            return f
        case Next(a):
            return f
        case And(args):
            return _and([_unfold(a) for a in args])
        case Or(args):
            return _or([_unfold(a) for a in args])
        case Until(a, b, None):
            return _or([_unfold(b), _and([_unfold(a), _next(f)])])
        case Until(a, b, Interval(0, 0)):
            return _unfold(b)
        case Until(a, b, Interval(0, u)):
            later = _next(_until(a, b, Interval(0, u - 1)))
            return _or([_unfold(b), _and([_unfold(a), later])])
        case Until(a, b, Interval(lo, u)):
            return _and([_unfold(a), _next(_until(a, b, Interval(lo - 1, u - 1)))])
        case Release(a, b, None):
            return _and([_unfold(b), _or([_unfold(a), _next(f)])])
        case Release(a, b, Interval(0, 0)):
            return _unfold(b)
        case Release(a, b, Interval(0, u)):
            later = _next(_release(a, b, Interval(0, u - 1)))
            return _and([_unfold(b), _or([_unfold(a), later])])
        case Release(a, b, Interval(lo, u)):
            return _or([_unfold(a), _next(_release(a, b, Interval(lo - 1, u - 1)))])
    raise TypeError(f"unexpected node in an obligation: {f!r}")


def _now_atoms(f: Formula, out: set[str]) -> None:
    match f:
        case Prop(name) | Not(Prop(name)):
            out.add(name)
        case And(args) | Or(args):
            for a in args:
                _now_atoms(a, out)


def _cofactor(f: Formula, p: str, value: bool) -> Formula:
    """``f`` with the current-step literal ``p`` set to ``value`` (obligations under
    ``Next`` untouched); subterms without ``p`` are returned as they are, not rebuilt."""
    match f:
        case Prop(name) if name == p:
            return Const(value)
        case Not(Prop(name)) if name == p:
            return Const(not value)
        case And(args) | Or(args):
            new = [_cofactor(a, p, value) for a in args]
            if all(x is y for x, y in zip(new, args, strict=True)):
                return f
            return _and(new) if isinstance(f, And) else _or(new)
    return f


def _strip(f: Formula) -> Formula:
    """The next-step obligation of a literal-free unfolded formula."""
    match f:
        case Next(a):
            return a
        case And(args):
            return _and([_strip(a) for a in args])
        case Or(args):
            return _or([_strip(a) for a in args])
        case Const():
            return f
    raise AssertionError(f"literal left after expansion: {f}")


def _expand(f: Formula) -> Diagram | Formula:
    """Shannon expansion of an unfolded formula over its current-step literals, in sorted
    order; leaves are successor obligations (formulas), not yet state indices."""
    names: set[str] = set()
    _now_atoms(f, names)
    if not names:
        return _strip(f)
    p = min(names)
    low = _expand(_cofactor(f, p, False))
    high = _expand(_cofactor(f, p, True))
    return low if low == high else (p, low, high)  # type: ignore[return-value]


_DIAGRAMS: dict[Formula, Diagram | Formula] = {}


def _diagram(f: Formula) -> Diagram | Formula:
    """The transition diagram of obligation ``f`` (leaves: successor obligations).

    Progression distributes over ``&`` and ``|``, so the diagram of a conjunction is the
    conjunction of its operands' diagrams (the BDD *apply* operation).  Operands recur
    across many states, so their diagrams are memoised; only atomic obligations are
    expanded from scratch."""
    d = _DIAGRAMS.get(f)
    if d is not None:
        return d
    if isinstance(f, And | Or):
        op = _and if isinstance(f, And) else _or
        parts = [_diagram(a) for a in f.args]
        d = parts[0]
        for part in parts[1:]:
            d = _apply(op, d, part, {})
    else:
        d = _expand(_unfold(f))
    if len(_DIAGRAMS) > 500_000:
        _DIAGRAMS.clear()
    _DIAGRAMS[f] = d
    return d


def _apply(op, a, b, memo: dict) -> Any:
    """Combine two ordered diagrams leaf-wise with ``op`` (variables in sorted order)."""
    key = (id(a), id(b))
    hit = memo.get(key)
    if hit is not None:
        return hit[0]
    ta, tb = isinstance(a, tuple), isinstance(b, tuple)
    if not ta and not tb:
        r = op([a, b])
    else:
        va = a[0] if ta else None
        vb = b[0] if tb else None
        v = min(x for x in (va, vb) if x is not None)
        a0, a1 = (a[1], a[2]) if va == v else (a, a)
        b0, b1 = (b[1], b[2]) if vb == v else (b, b)
        low, high = _apply(op, a0, b0, memo), _apply(op, a1, b1, memo)
        r = low if low == high else (v, low, high)
    memo[key] = (r, a, b)  # keep a and b alive so their ids stay theirs
    return r


_MAX_BOOL_DEPTH = 4


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


_CANON: dict[Formula, Formula] = {}


def _canonical(f: Formula) -> Formula:
    """``f`` itself, or its DNF when its ``&``/``|`` nesting is deep.

    Progression of an unbounded ``U``/``R`` nests a new copy of its residual inside the
    previous one at every step (``b | (a & (b' | (a' & ...))))``); flattening and
    absorption do not undo that, so the obligations would grow without bound although
    only finitely many are different.  Obligations are boolean combinations of finitely
    many temporal atoms, so the DNF (a set of sets of atoms) bounds them; it is used
    only past a small depth because it can be exponentially larger."""
    r = _CANON.get(f)
    if r is None:
        if _bool_depth(f) > _MAX_BOOL_DEPTH:
            r = _or([_and(list(t)) for t in _dnf(f)])
        else:
            r = f
        if len(_CANON) > 1_000_000:
            _CANON.clear()
        _CANON[f] = r
    return r


def progress(obligation: Formula, letter: frozenset[str] | set[str]) -> Formula:
    """The obligation left after reading ``letter`` (for tests and for people)."""
    node = _diagram(obligation)
    while isinstance(node, tuple):
        p, low, high = node
        node = high if p in letter else low
    return _canonical(node)  # type: ignore[arg-type]


# --------------------------------------------------------------------------- construction


def to_dta(formula: Formula, *, max_states: int = 200_000, minimise: bool = True) -> DTA:
    """The minimal DTA accepting the finite prefixes that decide ``formula`` true.

    ``formula`` may use any operator; distribution eventualities read as ``F``.  The
    automaton is exact for the whole co-safe fragment (every obligation is decided on a
    finite prefix); for other formulas it accepts the good prefixes.
    """
    start = _canonical(_prepare(formula))
    index: dict[Formula, int] = {start: 0}
    obligations: list[Formula] = [start]
    raw: list[Diagram | Formula] = []
    queue = deque([start])
    while queue:
        f = queue.popleft()
        d = _diagram(f)
        raw.append(d)
        stack = [d]
        while stack:
            node = stack.pop()
            if isinstance(node, tuple):
                stack.extend((node[1], node[2]))
                continue
            node = _canonical(node)  # type: ignore[arg-type]
            if node not in index:
                index[node] = len(obligations)
                obligations.append(node)
                queue.append(node)
                if len(obligations) > max_states:
                    raise TranslationError(
                        f"{formula}: more than {max_states} automaton states; the formula's "
                        "bounds are too large for an explicit automaton"
                    )

    def relabel(node, label) -> Diagram:
        if isinstance(node, tuple):
            low, high = relabel(node[1], label), relabel(node[2], label)
            return low if low == high else (node[0], low, high)
        return label[index[_canonical(node)]]

    n = len(obligations)
    block = [1 if obligations[i] == TRUE else 0 for i in range(n)]
    if minimise:
        while True:
            sigs: dict[tuple, int] = {}
            new = [sigs.setdefault((block[i], relabel(raw[i], block)), len(sigs)) for i in range(n)]
            stable = len(sigs) == len(set(block))
            block = new
            if stable:
                break
    else:
        block = list(range(n))

    # Number the blocks in discovery order and keep the first obligation of each as its
    # representative, so printing is deterministic.
    order: dict[int, int] = {}
    for b in block:
        order.setdefault(b, len(order))
    reps: list[Formula] = [FALSE] * len(order)
    for i in reversed(range(n)):
        reps[order[block[i]]] = obligations[i]
    final = [order[b] for b in block]
    delta: list[Diagram] = [0] * len(order)
    for i in range(n):
        delta[final[i]] = relabel(raw[i], final)

    accepting = final[index[TRUE]] if TRUE in index else None
    rejecting = None
    for s in range(len(order)):
        if s != accepting and all(t == s for t in _leaves(delta[s])):
            rejecting = s  # absorbing and not accepting: nothing is accepted from it
            reps[s] = FALSE
    if accepting is not None:
        reps[accepting] = TRUE
    atoms = tuple(sorted({a for d in delta for a in _tests(d)}))
    log.debug("DTA for %s: %d obligations, %d states after minimisation", formula, n, len(order))
    return DTA(
        formula=start,
        atoms=atoms,
        states=tuple(reps),
        initial=final[0],
        accepting=accepting,
        rejecting=rejecting,
        delta=tuple(delta),
    )


def _leaves(d: Diagram):
    if isinstance(d, int):
        yield d
    else:
        yield from _leaves(d[1])
        yield from _leaves(d[2])


def _tests(d: Diagram):
    if not isinstance(d, int):
        yield d[0]
        yield from _tests(d[1])
        yield from _tests(d[2])
