"""The discrete-time deterministic timed automaton (DTA) of an MITL obligation formula.

In discrete time the reachable (location, clock valuation) pairs of a DTA form a finite
automaton; this module stores that automaton directly.  State ``i`` *is* an obligation
(a formula still to be satisfied from the next step on, ``states[i]``); its *location*
is the obligation with every interval replaced by the interval it had in the source
formula, and its *clock valuation* is how far each bounded operator has progressed
(see :meth:`DTA.location`, which returns a :class:`Location`, and :meth:`DTA.clocks`),
so the automaton reads like the paper's Fig. 1.

Transitions are stored per state as a reduced ordered decision diagram over the
formula's propositions (tested in sorted order): ``step`` walks it, so a letter is read
in time linear in the number of propositions and the alphabet ``2^AP`` is never
enumerated.  Results are cached per (state, letter).

Each state has a *kind* (:data:`ACCEPT`, :data:`REJECT`, :data:`SAFE`, :data:`OPEN`)
that says how it counts for acceptance: an infinite run is accepted when it reaches the
accepting state (``true``), or when it stays forever, from some step on, in
:data:`SAFE` states (a safety obligation kept for ever, ``G !h``, or kept while a
guarantee is still pending, ``G !h | F goal`` never reaching ``goal``).  A finite prefix
is a good prefix when it reaches the accepting state and a bad one when it reaches the
rejecting state.  For a co-safe formula no state is :data:`SAFE` and acceptance is
reaching ``true``, as before.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import TypeAlias

from mitld_lp.logic.syntax import And, Formula, Interval, Or, Release, Until, show, subformulas

__all__ = ["DTA", "Diagram", "Location", "ACCEPT", "REJECT", "SAFE", "OPEN", "KINDS"]

#: The accepting state ``true``: absorbing, every run through it is accepted.
ACCEPT = "accept"
#: The rejecting state ``false``: absorbing, no run through it is accepted.
REJECT = "reject"
#: A state on a cycle whose runs are accepted if they stay on its strongly connected
#: component forever: the obligation left there holds on every such run (it is a safety
#: obligation still kept, possibly beside guarantees that are still pending).
SAFE = "safe"
#: Any other state: a run must leave it (towards ``true`` or into safe states) to be
#: accepted.
OPEN = "open"
KINDS = (ACCEPT, REJECT, SAFE, OPEN)

Diagram: TypeAlias = "int | tuple[str, Diagram, Diagram]"
"""A leaf is a successor state index; a node ``(p, low, high)`` tests proposition ``p``
(``high`` when ``p`` is in the letter)."""


@dataclass(frozen=True, slots=True)
class Location:
    """A state of the automaton as the paper draws it: a location and a clock valuation.

    Attributes:
        obligation: the state's obligation with every interval shown as in the source
            formula (``F[0,3] A`` for ``F[0,1] A`` two steps in): states that differ only
            in their clocks have the same text.
        clocks: for each bounded operator in progress, ``(clock name, elapsed steps)``;
            the clock is named after the operator in the source formula.
        label: the obligation with each running operator followed by its clock value,
            ``F[0,3] A {x=2}``; also ``str(location)``.
    """

    obligation: str
    clocks: tuple[tuple[str, int], ...]
    label: str

    def __str__(self) -> str:
        return self.label


def _walk(d: Diagram, letter: frozenset[str] | set[str]) -> int:
    while not isinstance(d, int):
        p, low, high = d
        d = high if p in letter else low
    return d


@dataclass(frozen=True, slots=True, eq=False)
class DTA:
    """A minimal complete deterministic automaton over letters ``2^AP``.

    Attributes:
        formula: the MITL formula it accepts (distribution eventualities read as ``F``).
        atoms: the propositions the automaton reads, sorted.
        states: the obligation each state stands for (``true`` for the accepting state,
            ``false`` for the rejecting one).
        initial: the state before any letter is read.
        accepting: index of the accepting state (absorbing), ``None`` if unreachable.
        rejecting: index of the rejecting state (absorbing; from it no word is
            accepted), ``None`` if unreachable.
        delta: per state, the decision diagram of its transition function.
        kinds: per state, one of :data:`KINDS`.  No two states of different kinds are
            merged by minimisation, and every strongly connected component is all
            :data:`SAFE` or has no :data:`SAFE` state.
        fragment: the class of the formula (:func:`mitld_lp.logic.fragment.classify`):
            ``"co-safe"``, ``"safety"`` or ``"obligation"``, for which the acceptance
            above is exact; for any other class no state is :data:`SAFE` and only good
            prefixes are accepted.
    """

    formula: Formula
    atoms: tuple[str, ...]
    states: tuple[Formula, ...]
    initial: int
    accepting: int | None
    rejecting: int | None
    delta: tuple[Diagram, ...]
    kinds: tuple[str, ...]
    fragment: str
    _cache: dict[tuple[int, frozenset[str]], int] = field(default_factory=dict, repr=False)

    @property
    def n_states(self) -> int:
        """Number of reachable states (after minimisation)."""
        return len(self.states)

    def step(self, state: int, letter: Iterable[str]) -> int:
        """The state reached from ``state`` by reading ``letter`` (a set of proposition
        names that hold at this step; names the formula does not mention are ignored)."""
        key = (state, letter if isinstance(letter, frozenset) else frozenset(letter))
        nxt = self._cache.get(key)
        if nxt is None:
            nxt = self._cache[key] = _walk(self.delta[state], key[1])
        return nxt

    def is_accepting(self, state: int) -> bool:
        return state == self.accepting

    def is_rejecting(self, state: int) -> bool:
        return state == self.rejecting

    def kind(self, state: int) -> str:
        """The kind of ``state``: one of :data:`KINDS`."""
        return self.kinds[state]

    def is_safe(self, state: int) -> bool:
        """Whether ``state`` is :data:`SAFE`: a run staying on its component forever is
        accepted."""
        return self.kinds[state] == SAFE

    @property
    def persistent(self) -> frozenset[int]:
        """The states in which staying forever is acceptance: the :data:`SAFE` ones and
        the accepting one.  A run is accepted exactly when from some step on it never
        leaves this set; so the best probability of the formula in a product is the best
        probability of reaching an end component that keeps within it."""
        return frozenset(i for i, k in enumerate(self.kinds) if k in (SAFE, ACCEPT))

    def complement(self) -> DTA:
        """The automaton of ``not formula``: the same states and transitions with the
        acceptance swapped.  A run's acceptance is decided by the strongly connected
        component it ends in (each is all :data:`SAFE` or has no :data:`SAFE` state; the
        accepting and rejecting states are absorbing), so the complement accepts exactly
        the runs this one rejects: ``ACCEPT <-> REJECT``, ``SAFE <-> OPEN``.  An
        ``OPEN`` state on no cycle becomes ``SAFE``, which no run can stay in.  The
        classes swap (co-safe <-> safety; obligation stays obligation); exact for the
        classes whose acceptance is exact (:attr:`fragment`)."""
        from mitld_lp.logic.syntax import Not

        swap = {ACCEPT: REJECT, REJECT: ACCEPT, SAFE: OPEN, OPEN: SAFE}
        fragment = {"co-safe": "safety", "safety": "co-safe"}.get(self.fragment,
                                                                  self.fragment)
        return DTA(formula=Not(self.formula), atoms=self.atoms, states=self.states,
                   initial=self.initial, accepting=self.rejecting, rejecting=self.accepting,
                   delta=self.delta, kinds=tuple(swap[k] for k in self.kinds),
                   fragment=fragment)

    def accepts_lasso(self, prefix: Iterable[Iterable[str]], loop: Iterable[Iterable[str]]) -> bool:
        """Whether the infinite word ``prefix loop loop ...`` is accepted: its run ends in
        a cycle of :attr:`persistent` states (``loop`` must not be empty)."""
        word = [frozenset(letter) for letter in loop]
        if not word:
            raise ValueError("the loop of a lasso must have at least one letter")
        s = self.initial
        for letter in prefix:
            s = self.step(s, letter)
        seen: dict[int, int] = {}  # state at the start of a loop pass -> pass number
        starts: list[int] = []
        while s not in seen:
            seen[s] = len(starts)
            starts.append(s)
            for letter in word:
                s = self.step(s, letter)
        # The passes from the first visit of ``s`` on repeat for ever: every state they
        # visit is visited infinitely often.
        keep = self.persistent
        for start in starts[seen[s]:]:
            t = start
            for letter in word:
                if t not in keep:
                    return False
                t = self.step(t, letter)
        return True

    def run(self, trace: Iterable[Iterable[str]]) -> bool:
        """True when the run on the finite ``trace`` reaches the accepting state."""
        s = self.initial
        if s == self.accepting:
            return True
        for letter in trace:
            s = self.step(s, letter)
            if s == self.accepting:
                return True
            if s == self.rejecting:
                return False
        return False

    def successors(self, state: int) -> frozenset[int]:
        """The states reachable from ``state`` in one step (for some letter)."""
        out: set[int] = set()
        stack: list[Diagram] = [self.delta[state]]
        while stack:
            d = stack.pop()
            if isinstance(d, int):
                out.add(d)
            else:
                stack.extend((d[1], d[2]))
        return frozenset(out)

    # ----------------------------------------------------------------- presentation

    def _source_intervals(self) -> dict[tuple[type, Formula, Formula], list[Interval]]:
        table: dict[tuple[type, Formula, Formula], list[Interval]] = {}
        for g in subformulas(self.formula):
            if isinstance(g, Until | Release) and g.interval is not None:
                table.setdefault((type(g), g.left, g.right), []).append(g.interval)
        return table

    def clocks(self, state: int) -> tuple[tuple[str, int], ...]:
        """The clock valuation of ``state``: for each bounded operator of the source
        formula that is in progress, ``(name, elapsed steps)``; the clock of the operator
        ``U[l,u]`` is named after it, e.g. ``"F[0,3] A"``."""
        return tuple((name, v) for name, v, _ in self._clock_view(state))

    def location(self, state: int) -> Location:
        """The location and clock valuation of ``state`` (see :class:`Location`):
        ``F[0,3] A {x=1}`` reads "F[0,3] A, one step in"."""
        view = self._clock_view(state)
        plain = {current: str(source) for _, _, (current, source) in view}
        timed = {current: f"{source} {{x={v}}}" for _, v, (current, source) in view}
        text, label = self._located(self.states[state], plain, timed)
        return Location(text, tuple((name, v) for name, v, _ in view), label)

    def _located(
        self, f: Formula, plain: dict[Formula, str], timed: dict[Formula, str]
    ) -> tuple[str, str]:
        # Operands are sorted by their text *without* clock values, so two states of the
        # same location print it the same way whatever their clocks.
        if isinstance(f, And | Or):
            parts = []
            for a in f.args:
                text, label = self._located(a, plain, timed)
                if isinstance(f, And) and isinstance(a, Or):
                    text, label = f"({text})", f"({label})"
                parts.append((text, label))
            parts.sort()
            sep = " & " if isinstance(f, And) else " | "
            return sep.join(t for t, _ in parts), sep.join(lab for _, lab in parts)
        return show(f, plain), show(f, timed)

    def guards(self, state: int) -> dict[int, str]:
        """For each successor of ``state``, the letters that lead to it, as a guard over
        the atoms in disjunctive form (``"p & !q | !p"``; ``"true"`` for every letter)."""
        return _guards(self.delta[state])

    def _clock_view(self, state: int):
        table = self._source_intervals()
        seen: set[Formula] = set()
        out = []
        for g in subformulas(self.states[state]):
            if not isinstance(g, Until | Release) or g.interval is None or g in seen:
                continue
            seen.add(g)
            iv = g.interval
            for src in table.get((type(g), g.left, g.right), ()):
                shift = src.hi - iv.hi
                if shift >= 0 and (src.lo - iv.lo == shift or iv.lo == 0 and src.lo <= shift):
                    source = type(g)(g.left, g.right, src)
                    if shift > 0:
                        out.append((str(source), shift, (g, source)))
                    break
        return out

    def to_dot(self) -> str:
        """Graphviz DOT text: one node per state labelled by location and clocks, one edge
        per (state, successor) labelled by the letters that take it (as a guard over the
        atoms, in disjunctive form)."""
        lines = [
            "digraph DTA {",
            "  rankdir=LR;",
            '  node [shape=box, style=rounded, fontname="Helvetica"];',
            '  __init [shape=point, label=""];',
        ]
        for i in range(self.n_states):
            label = _dot_escape(self.location(i).label if i != self.accepting else "accept")
            if i == self.rejecting:
                label = "reject"
            if self.is_safe(i):
                label += " (safe)"
            shape = ', peripheries=2' if i == self.accepting else ""
            lines.append(f'  s{i} [label="{i}: {label}"{shape}];')
        lines.append(f"  __init -> s{self.initial};")
        for i in range(self.n_states):
            for target, guard in sorted(self.guards(i).items()):
                lines.append(f'  s{i} -> s{target} [label="{_dot_escape(guard)}"];')
        lines.append("}")
        return "\n".join(lines) + "\n"


def _dot_escape(text: str) -> str:
    return text.replace("\\", "\\\\").replace('"', '\\"')


def _guards(d: Diagram) -> dict[int, str]:
    """For each leaf of ``d``, the disjunction of the paths' conjunctions leading to it."""
    paths: dict[int, list[str]] = {}

    def go(node: Diagram, lits: tuple[str, ...]) -> None:
        if isinstance(node, int):
            paths.setdefault(node, []).append(" & ".join(lits) if lits else "true")
            return
        p, low, high = node
        go(high, (*lits, p))
        go(low, (*lits, f"!{p}"))

    go(d, ())
    return {t: " | ".join(ps) for t, ps in paths.items()}
