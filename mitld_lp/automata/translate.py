"""MITL (discrete time; co-safe, safety and obligation formulas) to a minimal DTA, by
formula progression.

A state is an *obligation*: a formula in negation normal form that the rest of the
trace must satisfy.  Reading a letter ``sigma`` (the propositions true at this step)
progresses it, with the strict-past semantics (``a U[l,u] b`` needs ``a`` on the steps before the
witness of ``b``, not at it):

* ``p`` becomes ``true`` or ``false``;
* ``a U[0,u] b  ->  prog(b) | (prog(a) & a U[0,u-1] b)``  (the second disjunct only if u > 0);
* ``a U[l,u] b  ->  prog(a) & a U[l-1,u-1] b``  for l > 0;
* ``a R[0,u] b  ->  prog(b) & (prog(a) | a R[0,u-1] b)``,
  ``a R[l,u] b  ->  prog(a) | a R[l-1,u-1] b``  (the duals; ``G[l,u] p == false R[l,u] p``);
* unbounded ``U``/``R`` unfold the same way and stay unbounded; ``X a -> a``.

The result is put in the canonical normal form of :mod:`mitld_lp.logic.normal`
(flatten, absorb ``true``/``false``, sort, drop an obligation implied by another one:
``F[0,3] p | F[0,2] p == F[0,3] p``, and join intervals that overlap:
``a U[0,2] b | a U[2,5] b == a U[0,5] b``).  Every rule used preserves the
strong Kleene reading on finite prefixes, so the automaton accepts a finite trace
exactly when :func:`mitld_lp.logic.semantics.holds` says TRUE.  The accepting state is
``true``; reaching it is the acceptance condition of a co-safe formula.

A safety or obligation formula is also satisfied by runs that never reach ``true``
(``G !h``): each strongly connected component of the automaton is marked *safe* when a
run that stays in it forever satisfies the formula, which one cycle of the component
decides (:func:`_safe_states`).  An infinite run is accepted when it reaches ``true`` or
stays, from some step on, in safe states (see :mod:`mitld_lp.automata.dta`).

The letter is never enumerated: one step of a state is unfolded symbolically into a
boolean combination of current-step literals and next-step obligations, and Shannon
expansion over the literals (in sorted order) yields a reduced ordered decision
diagram whose leaves are the successor obligations.  The reachable automaton is then
minimised by partition refinement on those diagrams (ordered and reduced, they are
canonical, so equal signatures mean equal transition functions; a round recomputes only
the states whose successors changed block), which makes its size independent of how an
equivalent formula was written, as far as the obligations' languages coincide.  Each
call of :func:`to_dta` owns its memo tables (a :class:`_Translation`), so nothing is
kept between calls.
"""

from __future__ import annotations

import itertools
import logging
from collections import deque
from collections.abc import Callable, Iterable
from typing import Any

from mitld_lp import defaults
from mitld_lp.automata.dta import ACCEPT, DTA, OPEN, REJECT, SAFE, Diagram
from mitld_lp.logic.fragment import CO_SAFE, SUPPORTED, FragmentReport, classify, nnf
from mitld_lp.logic.normal import c_and, c_next, c_or, c_release, c_until, canonical, normal_form
from mitld_lp.logic.semantics import holds_lasso
from mitld_lp.logic.syntax import (
    FALSE,
    TRUE,
    And,
    Const,
    Formula,
    Interval,
    Next,
    Not,
    Or,
    Prop,
    Release,
    Until,
)

__all__ = ["to_dta", "progress", "TranslationError", "AutomatonTooLarge"]

log = logging.getLogger(__name__)

_Op = Callable[[Iterable[Formula]], Formula]
# A decision diagram whose leaves are still obligations (formulas), not state indices.
_RawDiagram = Any


class TranslationError(ValueError):
    """The formula is outside what the translation accepts (names the subformula), or
    its automaton exceeds the state budget."""


class AutomatonTooLarge(TranslationError):
    """The automaton would exceed its state budget (``max_states``); raised before the
    work that would exceed it."""


# --------------------------------------------------------------------------- progression


def _unfold1(f: Formula, unfold: Callable[[Formula], Formula]) -> Formula:
    """One step of ``f``: current-step literals combined with ``Next`` obligations
    (``unfold`` is the memoised recursion)."""
    match f:
        case Const() | Prop() | Not():
            return f
        case Next(a):
            return f
        case And(args):
            return c_and([unfold(a) for a in args])
        case Or(args):
            return c_or([unfold(a) for a in args])
        case Until(a, b, None):
            return c_or([unfold(b), c_and([unfold(a), c_next(f)])])
        case Until(a, b, Interval(0, 0)):
            return unfold(b)
        case Until(a, b, Interval(0, u)):
            later = c_next(c_until(a, b, Interval(0, u - 1)))
            return c_or([unfold(b), c_and([unfold(a), later])])
        case Until(a, b, Interval(lo, u)):
            return c_and([unfold(a), c_next(c_until(a, b, Interval(lo - 1, u - 1)))])
        case Release(a, b, None):
            return c_and([unfold(b), c_or([unfold(a), c_next(f)])])
        case Release(a, b, Interval(0, 0)):
            return unfold(b)
        case Release(a, b, Interval(0, u)):
            later = c_next(c_release(a, b, Interval(0, u - 1)))
            return c_and([unfold(b), c_or([unfold(a), later])])
        case Release(a, b, Interval(lo, u)):
            return c_or([unfold(a), c_next(c_release(a, b, Interval(lo - 1, u - 1)))])
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
            return c_and(new) if isinstance(f, And) else c_or(new)
    return f


def _strip(f: Formula) -> Formula:
    """The next-step obligation of a literal-free unfolded formula."""
    match f:
        case Next(a):
            return a
        case And(args):
            return c_and([_strip(a) for a in args])
        case Or(args):
            return c_or([_strip(a) for a in args])
        case Const():
            return f
    raise AssertionError(f"literal left after expansion: {f}")


def _expand(f: Formula) -> _RawDiagram:
    """Shannon expansion of an unfolded formula over its current-step literals, in sorted
    order; leaves are successor obligations (formulas), not yet state indices."""
    names: set[str] = set()
    _now_atoms(f, names)
    if not names:
        return _strip(f)
    p = min(names)
    low = _expand(_cofactor(f, p, False))
    high = _expand(_cofactor(f, p, True))
    return low if low == high else (p, low, high)


class _Translation:
    """The memo tables of one translation: an obligation's one-step unfolding, its
    transition diagram and its canonical form.  Lives for one :func:`to_dta` (or
    :func:`progress`) call, so the tables never outgrow the automaton being built.

    ``max_leaves`` bounds the distinct successors of one diagram while it is combined:
    each becomes a state, so a diagram with more than the state budget is refused
    before it is finished (a conjunction of ``n`` independent obligations has ``2^n``)."""

    def __init__(self, max_leaves: int, what: object) -> None:
        self.max_leaves = max_leaves
        self.what = what
        self._unfolded: dict[Formula, Formula] = {}
        self._diagrams: dict[Formula, _RawDiagram] = {}
        self._canonical: dict[Formula, Formula] = {}

    def too_many(self) -> AutomatonTooLarge:
        return AutomatonTooLarge(
            f"{self.what}: more than {self.max_leaves:,} automaton states; the formula's "
            "bounds are too large for an explicit automaton (raise max_states, or "
            "shorten the bounds)"
        )

    def unfold(self, f: Formula) -> Formula:
        r = self._unfolded.get(f)
        if r is None:
            r = self._unfolded[f] = _unfold1(f, self.unfold)
        return r

    def canonical(self, f: Formula) -> Formula:
        r = self._canonical.get(f)
        if r is None:
            r = self._canonical[f] = canonical(f)
        return r

    def diagram(self, f: Formula) -> _RawDiagram:
        """The transition diagram of obligation ``f`` (leaves: successor obligations).

        Progression distributes over ``&`` and ``|``, so the diagram of a conjunction is
        the conjunction of its operands' diagrams (the BDD *apply* operation).  Operands
        recur across many states, so their diagrams are memoised; only atomic obligations
        are expanded from scratch."""
        d = self._diagrams.get(f)
        if d is not None:
            return d
        if isinstance(f, And | Or):
            op = c_and if isinstance(f, And) else c_or
            parts = [self.diagram(a) for a in f.args]
            d = parts[0]
            for part in parts[1:]:
                d = self._apply(op, d, part, {}, set())
        else:
            d = _expand(self.unfold(f))
        self._diagrams[f] = d
        return d

    def _apply(self, op: _Op, a: Any, b: Any, memo: dict, leaves: set) -> Any:
        """Combine two ordered diagrams leaf-wise with ``op`` (variables in sorted
        order); ``leaves`` collects the distinct leaves made, against the budget."""
        key = (id(a), id(b))
        hit = memo.get(key)
        if hit is not None:
            return hit[0]
        ta, tb = isinstance(a, tuple), isinstance(b, tuple)
        if not ta and not tb:
            r = op([a, b])
            if r not in leaves:
                leaves.add(r)
                if len(leaves) > self.max_leaves:
                    raise self.too_many()
        else:
            va = a[0] if ta else None
            vb = b[0] if tb else None
            v = min(x for x in (va, vb) if x is not None)
            a0, a1 = (a[1], a[2]) if va == v else (a, a)
            b0, b1 = (b[1], b[2]) if vb == v else (b, b)
            low, high = self._apply(op, a0, b0, memo, leaves), self._apply(op, a1, b1, memo, leaves)
            r = low if low == high else (v, low, high)
        memo[key] = (r, a, b)  # keep a and b alive so their ids stay theirs
        return r

    def successor(self, obligation: Formula, letter: frozenset[str] | set[str]) -> Formula:
        node = self.diagram(obligation)
        while isinstance(node, tuple):
            p, low, high = node
            node = high if p in letter else low
        return self.canonical(node)


def progress(obligation: Formula, letter: frozenset[str] | set[str]) -> Formula:
    """The obligation left after reading ``letter`` (for tests and for people)."""
    return _Translation(2**62, obligation).successor(obligation, letter)


# --------------------------------------------------------------------------- construction


def to_dta(
    spec: Formula | FragmentReport, *, max_states: int = defaults.MAX_AUTOMATON_STATES
) -> DTA:
    """The minimal DTA of the formula: its accepting state is reached by the finite
    prefixes that decide the formula true, and its safe states (``DTA.kinds``) are those
    where staying forever satisfies it.

    ``spec`` is a formula, or the :class:`~mitld_lp.logic.fragment.FragmentReport` that
    :func:`~mitld_lp.logic.fragment.check` made of it (its negation normal form and
    class are used as they are, not computed again).  The formula may use any operator;
    distribution eventualities read as ``F``.  The automaton is exact for co-safe, safety
    and obligation formulas: an infinite run satisfies the formula exactly when it
    reaches the accepting state or stays in safe states from some step on (for a co-safe
    formula no state is safe).  For other classes (``G F p``) no state is marked safe and
    only the good prefixes are accepted.

    Raises :class:`TranslationError` as soon as more than ``max_states`` obligations
    are found, or one state's transition diagram has more than ``max_states``
    successors, before the rest is built.
    """
    if isinstance(max_states, bool) or not isinstance(max_states, int) or max_states < 1:
        raise TranslationError(f"max_states must be a positive integer, got {max_states!r}")
    if isinstance(spec, FragmentReport):
        formula, in_nnf = spec.formula, spec.nnf
    else:
        formula, in_nnf = spec, nnf(spec)
    tr = _Translation(max_states, formula)
    start = tr.canonical(normal_form(in_nnf))
    index: dict[Formula, int] = {start: 0}
    obligations: list[Formula] = [start]
    succ: list[Diagram] = []
    queue = deque([start])

    def number(node: _RawDiagram, seen: dict[int, Diagram]) -> Diagram:
        # The diagram with its leaves replaced by state indices (new obligations are
        # queued); leaves that canonicalise to one state may make two branches equal.
        hit = seen.get(id(node))
        if hit is not None:
            return hit
        if isinstance(node, tuple):
            # high branch first: the numbering of states is part of the output (DOT, CLI)
            high = number(node[2], seen)
            low = number(node[1], seen)
            out: Diagram = low if low == high else (node[0], low, high)
        else:
            g = tr.canonical(node)
            out = index.get(g, -1)
            if out < 0:
                out = index[g] = len(obligations)
                obligations.append(g)
                queue.append(g)
                if len(obligations) > max_states:
                    raise tr.too_many()
        seen[id(node)] = out
        return out

    while queue:
        f = queue.popleft()
        d = tr.diagram(f)
        succ.append(number(d, {}))

    n = len(obligations)
    accepting_raw = index.get(TRUE)
    fragment = spec.fragment if isinstance(spec, FragmentReport) else classify(formula)
    safe_raw = _safe_states(obligations, succ, accepting_raw, fragment)
    label = [1 if i == accepting_raw else 2 if safe_raw[i] else 0 for i in range(n)]
    block = _coarsest_partition(succ, label)

    # Number the blocks in discovery order and keep the first obligation of each as its
    # representative, so printing is deterministic.
    order: dict[int, int] = {}
    first: list[int] = []
    for i, b in enumerate(block):
        if b not in order:
            order[b] = len(order)
            first.append(i)
    final = [order[b] for b in block]
    reps: list[Formula] = [obligations[i] for i in first]
    delta: list[Diagram] = [_relabel(succ[i], final) for i in first]
    kinds = [SAFE if safe_raw[i] else OPEN for i in first]

    accepting = final[accepting_raw] if accepting_raw is not None else None
    rejecting = None
    for s in range(len(order)):
        if s != accepting and kinds[s] == OPEN and all(t == s for t in _leaves(delta[s])):
            rejecting = s  # absorbing and not accepting: nothing is accepted from it
            reps[s] = FALSE
            kinds[s] = REJECT
    if accepting is not None:
        reps[accepting] = TRUE
        kinds[accepting] = ACCEPT
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
        kinds=tuple(kinds),
        fragment=fragment,
    )


# --------------------------------------------------------------------------- safe states


def _safe_states(
    obligations: list[Formula], succ: list[Diagram], accepting: int | None, fragment: str
) -> list[bool]:
    """For each state, whether a run that stays in its strongly connected component
    forever satisfies the obligation (and the component is a cycle, not a state the
    run passes once).  The accepting state is not counted (it is its own kind).

    For a safety or obligation formula every run that stays in one component has the
    same verdict (the language is recognised by a weak automaton: were one cycle of a
    component accepting and another rejecting, the word that alternates ever longer
    blocks of the two would be accepted by no weak automaton and rejected by none), so
    one cycle decides the component: the obligation of one of its states must hold on
    the infinite word that repeats the cycle's letters (:func:`holds_lasso`).  A
    co-safe formula has none (a co-safe obligation that holds is decided true after
    finitely many steps, i.e. the run reaches ``true``); nor does a formula outside the
    supported classes get any (its automaton accepts good prefixes only)."""
    n = len(obligations)
    safe = [False] * n
    if fragment == CO_SAFE or fragment not in SUPPORTED:
        return safe
    graph = [sorted(set(_leaves(d))) for d in succ]
    for component in _components(graph):
        rep = component[0]
        if rep == accepting or (len(component) == 1 and rep not in graph[rep]):
            continue
        loop = _cycle(rep, set(component), graph, succ)
        if holds_lasso(obligations[rep], (), loop):
            for s in component:
                safe[s] = True
    return safe


def _components(graph: list[list[int]]) -> list[list[int]]:
    """The strongly connected components of ``graph`` (Tarjan's algorithm, iterative)."""
    n = len(graph)
    index = [-1] * n
    low = [0] * n
    on_stack = [False] * n
    stack: list[int] = []
    out: list[list[int]] = []
    counter = 0
    for root in range(n):
        if index[root] >= 0:
            continue
        work = [(root, 0)]
        while work:
            v, i = work.pop()
            if i == 0:
                index[v] = low[v] = counter
                counter += 1
                stack.append(v)
                on_stack[v] = True
            if i < len(graph[v]):
                work.append((v, i + 1))
                w = graph[v][i]
                if index[w] < 0:
                    work.append((w, 0))
                elif on_stack[w]:
                    low[v] = min(low[v], index[w])
                continue
            if low[v] == index[v]:
                component = []
                while True:
                    w = stack.pop()
                    on_stack[w] = False
                    component.append(w)
                    if w == v:
                        break
                out.append(sorted(component))
            if work:
                parent = work[-1][0]
                low[parent] = min(low[parent], low[v])
    return out


def _cycle(
    start: int, members: set[int], graph: list[list[int]], succ: list[Diagram]
) -> list[frozenset[str]]:
    """The letters of a shortest cycle from ``start`` back to it inside ``members``
    (breadth first); each letter sets exactly the propositions its diagram path tests
    true."""
    parent: dict[int, int] = {}
    queue = deque([start])
    while queue:
        v = queue.popleft()
        for w in graph[v]:
            if w not in members or w in parent:
                continue
            parent[w] = v
            if w == start:
                path = [start]
                while len(path) == 1 or path[-1] != start:
                    path.append(parent[path[-1]])
                path.reverse()
                return [_letter(succ[a], b) for a, b in itertools.pairwise(path)]
            queue.append(w)
    raise AssertionError(f"state {start} lies on no cycle of its component")


def _letter(d: Diagram, target: int) -> frozenset[str]:
    """A letter that ``d`` sends to ``target``."""
    stack: list[tuple[Diagram, frozenset[str]]] = [(d, frozenset())]
    while stack:
        node, letter = stack.pop()
        if isinstance(node, int):
            if node == target:
                return letter
            continue
        p, low, high = node
        stack.append((low, letter))
        stack.append((high, letter | {p}))
    raise AssertionError(f"no letter leads to state {target}")


def _relabel(d: Diagram, label: list[int]) -> Diagram:
    if isinstance(d, int):
        return label[d]
    low, high = _relabel(d[1], label), _relabel(d[2], label)
    return low if low == high else (d[0], low, high)


def _coarsest_partition(succ: list[Diagram], label: list[int]) -> list[int]:
    """The block of each state in the coarsest partition that separates states of
    different ``label`` (accepting, safe, other) and is stable: two states of a block
    have, for every letter, successors in the same block (the Myhill-Nerode classes of
    the labelled automaton; unique, so any refinement order gives it).  Merged states
    have the same label at every step of every word, so the quotient accepts what the
    automaton accepts, on finite prefixes and on infinite runs alike.

    Moore's rounds of signature refinement (a state's signature is its diagram with
    successors replaced by their blocks; ordered and reduced, so equal signatures mean
    equal transition functions), but a round recomputes only the states whose signature
    may have changed: the predecessors of the states that changed block in the round
    before.  The other states of a block share one signature, so one of them stands for
    all (the states that differ from it leave the block).  A chain such as ``F[0,k] p`` needs k
    rounds that each move one state: O(k) signatures instead of the O(k^2) of
    recomputing every state in every round; a shallow automaton needs few rounds over
    all states, as before."""
    n = len(succ)
    preds: list[set[int]] = [set() for _ in range(n)]
    for s, d in enumerate(succ):
        for t in _leaves(d):
            preds[t].add(s)
    block = list(label)
    members: list[set[int]] = [set() for _ in range(max(label, default=0) + 1)]
    for s, b in enumerate(block):
        members[b].add(s)
    dirty: set[int] = set(range(n))
    while dirty:
        # Invariant: in each block, the states that are not dirty share one signature.
        by_block: dict[int, dict[Diagram, list[int]]] = {}
        for s in dirty:
            sig = _relabel(succ[s], block)
            by_block.setdefault(block[s], {}).setdefault(sig, []).append(s)
        staying: dict[int, Diagram] = {}
        for b, by_sig in by_block.items():
            ref = next((r for r in members[b] if r not in dirty), None)
            staying[b] = next(iter(by_sig)) if ref is None else _relabel(succ[ref], block)
        moved: list[int] = []
        for b, by_sig in by_block.items():
            for sig, group in by_sig.items():
                if sig == staying[b]:
                    continue
                new = len(members)
                members.append(set(group))
                members[b].difference_update(group)
                for s in group:
                    block[s] = new
                moved.extend(group)
        dirty = {p for t in moved for p in preds[t]}
    return block


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
