"""When the task stops caring when the sensed events happened: the step past which no
sensor report can change what the robot should do, and the sensors whose reports all
come after it (each solved as a blind sensor, ``detect = 0``).

**The bound.**  Let ``T`` be the latest step a sensed event can happen in the model (the
largest truncation point of the sensed events: an event not happened by its point ``T_a``
goes to the truncation sink, :mod:`mitld_lp.sensing.belief`) and ``L`` the task's
*forgetting horizon* (:func:`forgetting_horizon`): for any two hypotheses that read the
same observed letters (world propositions, unsensed events) and in which every sensed
event has happened, ``L`` steps after the later of their last occurrences their
automaton states are equal or one of them is decided (accepting, rejecting, or unable to
accept).  Then from step ``t0 = T + L`` on, every information state's undecided
hypotheses share one automaton state.

**The collapse.**  A sensor with ``delay >= t0 - 1`` reports no earlier than step
``1 + delay >= t0`` (an event happens at step 1 at the earliest), and its answer is the
blind sensor's.  Proof: up to step ``t0 - 1`` the robot's observations under the sensor
and under a blind one (which never reports) have the same law, since no report can have
come.  From step ``t0`` on, in either model, every information state's undecided
hypotheses have one automaton state ``q`` and every sensed event has happened in each
of them, so the future letters carry no sensed event and each hypothesis's automaton
runs from ``q`` on the observed letters alone: the value of the state is the value of
``(world state, q, pending unsensed events, clock)`` in the ordinary product, whatever
the posterior weights and whatever reports come later (a report only reweights the
hypotheses, and is independent of the world's moves given them).  The two models'
values agree at step ``t0`` for every observation history, the histories before it have
the same law, and a policy can do no better in one than in the other: the optima are
equal.  The truncated mass is the same in both (the same points ``T_a``).  The
construction then drops such a sensor's reports (its controller ignores them), which
keeps the information states' clock below ``T + delay`` instead of past ``K + delay``.

``L`` is found on the automaton alone (:func:`forgetting_horizon`), over every letter
(a superset of what the world can show: sound, possibly larger); a pair of hypotheses
that never agrees while both are undecided (``F(b & F(A & F B))``: which of ``A``,
``B`` came after ``b`` matters until one of them comes) gives no bound, and no sensor is
collapsed.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from mitld_lp.automata.dta import DTA, Diagram
from mitld_lp.sensing.sensors import Sensor

__all__ = ["forgetting_horizon", "Collapse", "collapse", "MAX_WORK"]

MAX_WORK = 1_200_000
"""The most decision-diagram nodes :func:`forgetting_horizon` walks before it gives up
(no bound, nothing collapsed): a few seconds at most; the 720-state automaton of
``models/patrol.toml`` with one sensed event takes about a million.  It runs only when
some sensor's delay could be past the bound (``delay >= T - 1``)."""

_Pair = tuple[int, int, frozenset[str], frozenset[str]]
"""Two hypotheses' automaton states and the sensed events each has seen happen."""


def _live(dta: DTA, gone: frozenset[str]) -> frozenset[int]:
    """The states from which the accepting state is reachable by letters without the
    events ``gone`` (sensed events that have happened: each happens once; the others
    may come in any letter, which can only make more states live)."""
    if dta.accepting is None:
        return frozenset()
    preds: dict[int, set[int]] = {}
    for q in range(dta.n_states):
        for q2 in _leaves(dta.delta[q], gone):
            preds.setdefault(q2, set()).add(q)
    live, todo = {dta.accepting}, [dta.accepting]
    while todo:
        for p in preds.get(todo.pop(), ()):
            if p not in live:
                live.add(p)
                todo.append(p)
    return frozenset(live)


def _leaves(d: Diagram, absent: frozenset[str]) -> set[int]:
    """The successors of a diagram over letters without ``absent``'s propositions."""
    out: set[int] = set()
    stack = [d]
    while stack:
        node = stack.pop()
        if isinstance(node, int):
            out.add(node)
        elif node[0] in absent:
            stack.append(node[1])
        else:
            stack.extend((node[1], node[2]))
    return out


def _pair_steps(d1: Diagram, d2: Diagram, sensed: frozenset[str], new1: frozenset[str],
                new2: frozenset[str], budget: list[int]) -> set[tuple[int, int]] | None:
    """The successor pairs of two diagrams read with one observed letter (any letter
    over the propositions that are not sensed events, shared) and the sensed events
    ``new1``, ``new2`` of each copy; None once ``budget[0]`` nodes are walked."""
    out: set[tuple[int, int]] = set()
    fixed: dict[str, bool] = {}  # the observed propositions decided on this path

    def go(a: Diagram, b: Diagram) -> bool:
        while True:
            budget[0] -= 1
            if budget[0] < 0:
                return False
            if not isinstance(a, int):
                p, low, high = a
                if p in sensed:
                    a = high if p in new1 else low
                    continue
            elif not isinstance(b, int):
                p, low, high = b
                if p in sensed:
                    b = high if p in new2 else low
                    continue
            else:
                out.add((a, b))
                return True
            if p in fixed:  # the shared letter already says
                a, b = _follow(a, p, fixed[p]), _follow(b, p, fixed[p])
                continue
            for value in (False, True):
                fixed[p] = value
                ok = go(_follow(a, p, value), _follow(b, p, value))
                del fixed[p]
                if not ok:
                    return False
            return True

    return out if go(d1, d2) else None


def _follow(d: Diagram, p: str, value: bool) -> Diagram:
    """``d`` past its node when that node tests ``p`` (else ``d`` itself)."""
    if isinstance(d, int) or d[0] != p:
        return d
    return d[2] if value else d[1]


def _subsets(events: Iterable[str]) -> list[frozenset[str]]:
    items = sorted(events)
    return [frozenset(c) for r in range(len(items) + 1)
            for c in itertools.combinations(items, r)]


def forgetting_horizon(dta: DTA, sensed: Iterable[str], *,
                       max_work: int = MAX_WORK) -> int | None:
    """``L`` of the module docs: the most steps, after the later of two hypotheses' last
    sensed events, before their automaton states are equal or one is decided; None when
    some pair stays apart for ever, or past ``max_work`` diagram nodes walked.

    Explored on pairs ``(q1, q2, S1, S2)`` (``S_i`` the sensed events copy ``i`` has
    seen) from ``(q, q, {}, {})`` for every state ``q``, each step reading one shared
    observed letter and each copy its own new sensed events (each at most once).  A pair
    is *done* when a state is accepting, rejecting, or cannot accept any more (no sensed
    event left to help it), or when both have seen every sensed event and the states are
    equal; a done pair stays done.  Among the pairs with every sensed event seen and not
    done (the region ``R``), a cycle means no bound, and otherwise ``L`` is one more than
    the longest path in ``R`` (0 when ``R`` is empty)."""
    events = frozenset(sensed) & frozenset(dta.atoms)
    if not events:
        return 0  # the automaton never reads a sensed event: its time never matters
    every = frozenset(events)
    live = {s: _live(dta, s) for s in _subsets(every)}

    def decided(q: int, gone: frozenset[str]) -> bool:
        return q == dta.accepting or q == dta.rejecting or q not in live[gone]

    news = {s: _subsets(every - s) for s in _subsets(every)}
    none: frozenset[str] = frozenset()
    start = [(q, q, none, none) for q in range(dta.n_states) if not decided(q, none)]
    seen: set[_Pair] = set(start)
    todo = list(start)
    budget = [max_work]
    walked: dict[tuple[int, int, frozenset[str], frozenset[str]], set[tuple[int, int]]] = {}
    region: dict[tuple[int, int], set[tuple[int, int]]] = {}
    while todo:
        q1, q2, s1, s2 = todo.pop()
        full = s1 == every and s2 == every
        succ: set[_Pair] = set()
        for n1 in news[s1]:
            for n2 in news[s2]:
                key = (q1, q2, n1, n2)  # the walk does not depend on S1, S2
                steps = walked.get(key)
                if steps is None:
                    steps = _pair_steps(dta.delta[q1], dta.delta[q2], events, n1, n2,
                                        budget)
                    if steps is None:
                        return None
                    walked[key] = steps
                succ.update((a, b, s1 | n1, s2 | n2) for a, b in steps)
        for pair in succ:
            a, b, t1, t2 = pair
            if decided(a, t1) or decided(b, t2) or (t1 == every and t2 == every
                                                       and a == b):
                continue  # done
            if full:
                region.setdefault((q1, q2), set()).add((a, b))
            if pair not in seen:
                seen.add(pair)
                todo.append(pair)
        if full:
            region.setdefault((q1, q2), set())
    return _longest(region)


def _longest(region: Mapping[tuple[int, int], set[tuple[int, int]]]) -> int | None:
    """One more than the longest path of ``region`` (a graph over its own nodes), 0 if
    empty; None if it has a cycle."""
    depth: dict[tuple[int, int], int] = {}
    active: set[tuple[int, int]] = set()
    for root in region:
        if root in depth:
            continue
        stack = [(root, iter(region[root]))]
        active.add(root)
        while stack:
            node, children = stack[-1]
            for child in children:
                if child in active:
                    return None  # a cycle: the pair can stay apart for ever
                if child not in depth:
                    active.add(child)
                    stack.append((child, iter(region.get(child, ()))))
                    break
            else:
                stack.pop()
                active.discard(node)
                depth[node] = 1 + max((depth[c] for c in region.get(node, ())), default=0)
    return max(depth.values(), default=0)


@dataclass(frozen=True, slots=True)
class Collapse:
    """What :func:`collapse` found: ``last`` the latest step a sensed event can happen
    (``T``), ``horizon`` the forgetting horizon ``L`` (None: none), ``blind`` the
    sensed events whose sensors report too late to matter, ``sensors`` the sensors the
    construction uses (those as blind ones, ``detect = 0``)."""

    last: int
    horizon: int | None
    blind: frozenset[str]
    sensors: Mapping[str, Sensor]

    @property
    def decided_from(self) -> int | None:
        """``t0 = T + L``: the step from which no report changes what the robot should
        do (None without a bound)."""
        return None if self.horizon is None else self.last + self.horizon


def collapse(dta: DTA, sensors: Mapping[str, Sensor], truncation: Mapping[str, int]
             ) -> Collapse:
    """The sensors whose reports come too late for the task (module docs), replaced by
    blind ones: ``delay >= T + L - 1`` with ``T`` the largest of ``truncation`` (the
    sensed events' truncation points) and ``L`` :func:`forgetting_horizon`."""
    last = max((truncation[a] for a in sensors), default=0)
    if not any(s.detect > 0 and s.delay >= last - 1 for s in sensors.values()):
        return Collapse(last, None, frozenset(), sensors)  # none could be late (L >= 0)
    horizon = forgetting_horizon(dta, sensors)
    if horizon is None:
        return Collapse(last, None, frozenset(), sensors)
    late = frozenset(a for a, s in sensors.items()
                     if s.detect > 0 and s.delay >= last + horizon - 1)
    used = {a: Sensor(0.0) if a in late else s for a, s in sensors.items()}
    return Collapse(last, horizon, late, used)
