"""The information-state product: the MDP over what the robot knows when some events
are reported by sensors that miss (:mod:`mitld_lp.sensing.sensors`).

The robot observes the world's state, its own actions, the step count, the events that
have no sensor (the step they happen) and its sensors' reports; it never observes a
sensed event itself.  What it does not know is *when* (and whether) each sensed event
happened.  A *hypothesis* is one value per sensed event: ``0`` (not happened yet) or
the step ``k >= 1`` it happened at.  Given the observations, a hypothesis fixes the
whole hidden run: the world ignores the sensed events (the problem refuses the other
case), so the automaton's state under a hypothesis is a function of the observed path.

An information state is therefore ``(world state, clock, reported events, pending
unsensed events, {hypothesis: automaton state})`` over the hypotheses still possible
and still undecided, with the posterior weights of those hypotheses.  The posterior is
a function of that key: with missed detections and no false alarms, the likelihood of
a report history under "happened at ``k``" is ``(1 - d)^(misses)`` and the ratio of two
such hypotheses of one event does not change with time once both reports are due (both
miss every step), while "not happened yet" against "happened at ``k``", or a hypothesis
whose report is not due yet (a sensor with a ``delay``: reports from step ``k + delay``
on), depends on the step count, which the key keeps while such a hypothesis is alive.
The construction stores the weights the first time it meets a key and checks them on
every later visit (an internal check of this argument).

Every sensed event is truncated at its point ``T_a`` (``P(K_a > T_a) <= `` its share
of epsilon), geometric laws included: the hypothesis "not happened by ``T_a``" goes to
the truncation sink, so the clock and the hypotheses stay finite.  The lower model
counts that mass as failure, the upper as success, as in the fully observed product.
A law that may never happen (``never > 0``) cuts only ``P(T_a < K_a < inf)`` at ``T_a``
(half the share when its sensor detects): "not happened by ``T_a``" becomes
:data:`NEVER` with probability ``never / P(K_a > T_a)``, a hypothesis of its own in which
the event never comes.  Against it a hypothesis "happened at ``k``, not reported" loses
weight by ``1 - detect`` at every missed report for ever, so such a hypothesis is cut at
its ``R``-th miss (``(1 - detect)^R <= `` the other half; :func:`sensed_sta`): past
that the posterior stops changing, and the clock with it.  Both cuts are the event's
tail (:attr:`mitld_lp.automata.sta.EventClock.tail`), inside the epsilon achieved.
A hypothesis is lost (the sink) when its automaton can reach no persistent state (the
accepting one, or a safe one of a task with a safety part) with the events left.

One step from an information state under action ``act``: the unsensed events happen by
their hazards at the clock; each hypothesis's sensed events that had not happened
happen by their hazards (or stay pending, or cross their truncation point); each
sensed event that has happened and is not reported yet is reported with probability
``detect``; the world moves by ``P(s' | s, act, E_unsensed)``; each hypothesis's
automaton reads ``props(s') | E``.  Hypotheses whose automaton accepts go to the
target, those that reject to the sink; the rest, grouped by what the robot observes
(``s'``, the unsensed events, the new reports), make the successor information states,
each entered with its group's probability.  A policy of this MDP acts on the
information state, a function of the observation history: the optimum over it is the
optimum over observation-based policies.
"""

from __future__ import annotations

import itertools
import logging
import math
from collections.abc import Callable, Hashable, Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import scipy.sparse as sp

from mitld_lp.automata.dta import DTA, SAFE
from mitld_lp.automata.sta import STA, make_sta
from mitld_lp.distributions import FirstOccurrence
from mitld_lp.mdp import ABSORB, MDP
from mitld_lp.product import Absorbing, ProductTooLarge, default_max_memory, estimate_size
from mitld_lp.sensing.horizon import collapse
from mitld_lp.sensing.sensors import Sensor
from mitld_lp.util.progress import bar as progress_bar
from mitld_lp.worlds.game import Game, world_members

log = logging.getLogger(__name__)

__all__ = ["InfoState", "Belief", "InfoSize", "info_size", "belief_product", "sensed_sta",
           "WEIGHT_TOL", "Ends", "Reaches"]

NOT_YET = 0
"""A hypothesis's value for a sensed event that has not happened (yet)."""
NEVER = -1
"""A hypothesis's value for a sensed event that will never happen (a law with
``never > 0``, past its truncation point: module docs)."""

MAX_PRUNE_ATOMS = 14
"""The most atoms whose letters :meth:`_Builder.can_accept` enumerates."""

WEIGHT_TOL = 1e-9

BYTES_PER_INFO_STATE = 6_500
"""Bytes an information state costs in the build (its record, index entry, rows, moves
and caches): with :data:`BYTES_PER_HYPOTHESIS`, a fit of the build's peak (tracemalloc)
on the bus case with one and with two sensed buses (2,693 states / 6,996 hypotheses:
17.6 MB; 3,751 / 17,213: 25.6 MB)."""
BYTES_PER_HYPOTHESIS = 200
"""Bytes each hypothesis of a state costs (its key tuple, its weight, its row entries)."""
"""How far two visits of one information state may disagree on its posterior."""

Obs = tuple[Hashable, frozenset[str], frozenset[str]]
"""What the robot observes after a step: world state, unsensed events, new reports."""

Reaches = Callable[[DTA, int, frozenset[str]], bool]
"""Whether some word reaches acceptance of a DTA from a state when only the given
events can still happen (:meth:`_Builder.can_accept`)."""

Ends = Callable[[int, frozenset[str], Reaches], Hashable | None]
"""Where a hypothesis ends: given its automaton state and the events that can still
happen, the absorbing record it goes to (hashable, not an :class:`InfoState`), or None
while it is undecided.  The default: :class:`Absorbing` ``TARGET`` / ``SINK`` by the
task's acceptance; :mod:`mitld_lp.routes.sensed_constrained` ends hypotheses of a joint
automaton in one record per verdict tuple."""


@dataclass(frozen=True, slots=True)
class InfoState:
    """One information state (module docs).  ``hypotheses``: ``(times, automaton
    state)`` pairs, ``times`` one value per sensed event (in ``Belief.sensed`` order,
    ``0`` for not happened), sorted; ``weights``: their posterior, in that order."""

    world: Hashable
    clock: int
    reported: frozenset[str]
    pending: frozenset[str]
    hypotheses: tuple[tuple[tuple[int, ...], int], ...]
    weights: tuple[float, ...]

    def key(self) -> Hashable:
        return (self.world, self.clock, self.reported, self.pending, self.hypotheses)


@dataclass(frozen=True, slots=True, eq=False)
class Belief:
    """The information-state MDP and what a controller needs to follow it.

    ``moves[(state, action)][obs]`` is the successor state of an observation, or an
    :class:`Absorbing` member when nothing undecided is left with it (``TARGET``: every
    hypothesis left accepted; ``SINK``: every one rejected; ``TRUNCATED``: some of each,
    the robot cannot tell which).  ``sta``: the clocks (sensed events truncated).
    ``sensors``: the sensors as given; ``ignored``: the sensed events whose reports
    come too late to matter (:mod:`mitld_lp.sensing.horizon`), built as blind ones: an
    observation's reports of them are dropped before it is looked up in ``moves``."""

    mdp: MDP
    sta: STA
    sensed: tuple[str, ...]
    sensors: Mapping[str, Sensor]
    moves: Mapping[tuple[int, str], Mapping[Obs, int | Absorbing]]
    ignored: frozenset[str] = frozenset()


@dataclass(frozen=True, slots=True)
class InfoSize:
    """What one information state can hold, from the factors, before any is built:
    ``clock`` the largest clock value a state keeps (an unsensed event's bound; a sensed
    event's truncation point plus its sensor's delay: :meth:`_Builder.clock_key`),
    ``hypotheses`` the most hypotheses a state holds (a step up to the truncation point,
    or not yet, per sensed event; one automaton state each, the observations fixing the
    run), ``world_states`` (None if the game does not say).  The states themselves are
    counted as they are built."""

    world_states: int | None
    clock: int
    hypotheses: int

    def __str__(self) -> str:
        world = "an unknown number of" if self.world_states is None else (
            f"{self.world_states:,}")
        return (f"{world} world states, the clock kept up to step {self.clock:,}, at most "
                f"{self.hypotheses:,} hypotheses per state")


def info_size(game: Game[Any], sta: STA, sensors: Mapping[str, Sensor]) -> InfoSize:
    """:class:`InfoSize` of the information states of ``sta``'s events with ``sensors``
    (the sensors the construction uses)."""
    bounds = [c.truncation if c.truncation is not None else c.cap
              for a, c in sta.clocks.items() if a not in sensors]
    last = {a: sta.clocks[a].truncation for a in sensors}
    points = {a: t for a, t in last.items() if t is not None}
    assert len(points) == len(sensors)  # every sensed event is truncated (sensed_sta)
    bounds += [points[a] + sensor.delay + (sta.clocks[a].report_limit or 0)
               for a, sensor in sensors.items()]
    return InfoSize(world_members(game).n_states, max(bounds, default=0),
                    math.prod(t + 1 + sta.clocks[a].keeps_never for a, t in points.items()))


def sensed_sta(dta: DTA, laws: Mapping[str, FirstOccurrence], sensed: tuple[str, ...],
               epsilon: float, *, clock_reduction: bool = True,
               truncation: Mapping[str, int] | None = None,
               sensors: Mapping[str, Sensor] | None = None) -> STA:
    """The STA with every sensed event truncated: the events truncated (the sensed ones,
    and the unsensed ones whose hazard never becomes constant, or all without
    ``clock_reduction``) share ``epsilon`` equally, as :func:`make_sta` shares it; a
    point in ``truncation`` is kept as given.

    A sensed event whose law may never happen (``never > 0``) keeps "never" as a
    hypothesis of its own (:data:`NEVER`, module docs): its point ``T`` cuts only
    ``P(T < K < inf)``; with a sensor that detects (``0 < detect < 1``) the belief in
    "never" against "happened at ``k``, missed since" grows at every miss, so a
    hypothesis missed ``R`` times (``report_limit``) is cut too, ``R`` the first with
    ``(1 - detect)^R <= `` half the event's share (the other half is ``T``'s), and the
    event's tail is both cuts' mass (``report_tail``)."""
    fixed = dict(truncation or {})
    auto = [a for a in sorted(laws) if a not in fixed and (
        a in sensed or not clock_reduction or laws[a].constant_hazard_from is None)]
    share = epsilon / len(auto) if auto else epsilon
    points, cuts = {}, {}
    for a in auto:
        nu = float(laws[a].never) if a in sensed else 0.0
        d = sensors[a].detect if sensors is not None and a in sensors else 0.0
        if nu > 0.0:
            half = share / 2 if 0.0 < d < 1.0 else share
            points[a] = max(laws[a].truncation_point(min(nu + half, 1.0)), 1)
            if 0.0 < d < 1.0:
                cuts[a] = max(2, math.ceil(math.log(half) / math.log1p(-d)))
        else:
            points[a] = laws[a].truncation_point(share)
    for a in fixed:  # a fixed point of a sensed event that may never happen
        if a in sensed and float(laws[a].never) > 0.0:
            d = sensors[a].detect if sensors is not None and a in sensors else 0.0
            if 0.0 < d < 1.0:
                cuts[a] = max(2, math.ceil(math.log(share / 2) / math.log1p(-d)))
    sta = make_sta(dta, laws, epsilon, clock_reduction=clock_reduction,
                   truncation={**fixed, **points})
    clocks = dict(sta.clocks)
    for a in sensed:
        c = clocks[a]
        if float(c.distribution.never) > 0.0 and c.truncation is not None:
            R = cuts.get(a)
            d = sensors[a].detect if sensors is not None and a in sensors else 0.0
            reach = 1.0 - float(c.distribution.survival(c.truncation))  # P(K <= T)
            clocks[a] = replace(c, keeps_never=True, report_limit=R,
                                report_tail=0.0 if R is None else reach * (1.0 - d) ** R)
    return STA(dta, clocks)


def belief_product(game: Game[Any], dta: DTA, laws: Mapping[str, FirstOccurrence],
                   sensors: Mapping[str, Sensor], epsilon: float, *,
                   clock_reduction: bool = True, truncation: Mapping[str, int] | None = None,
                   max_states: int, max_memory: int | None = None,
                   progress: bool | None = None, late_reports: bool = True,
                   ends: Ends | None = None) -> Belief:
    """The reachable information-state MDP (module docs) of a task's automaton ``dta``
    in ``game``, the events of ``sensors`` (missed detections only) hidden.

    A sensor whose reports all come after the task stops depending on when the sensed
    events happened is built as a blind one, its reports ignored (the same optimum:
    :mod:`mitld_lp.sensing.horizon`), before any state is built; ``late_reports=False``
    builds every sensor as given (to compare the two).  Raises :class:`ProductTooLarge`
    before storing a state beyond ``max_states``, or one that would take the states past
    ``max_memory`` bytes (default: half the machine's memory) at
    :data:`BYTES_PER_INFO_STATE` per state and :data:`BYTES_PER_HYPOTHESIS` per
    hypothesis it holds.  ``progress``: a bar of the states built
    (:mod:`mitld_lp.util.progress`: ``None`` on a terminal only), after a line saying
    how large the product may grow.  ``ends``: where a hypothesis ends (:data:`Ends`;
    every record it returns is an absorbing state of the MDP)."""
    sensed = tuple(sorted(sensors))
    sta = sensed_sta(dta, laws, sensed, epsilon, clock_reduction=clock_reduction,
                     truncation=truncation, sensors=sensors)
    memory = default_max_memory() if max_memory is None else max_memory
    used: dict[str, Sensor] = dict(sensors)
    ignored: frozenset[str] = frozenset()
    # the collapse's argument (every sensed event has happened by T, the task's
    # acceptance is reaching its accepting state) holds for co-safe tasks and laws that
    # surely happen only
    if late_reports and SAFE not in dta.kinds and not any(
            sta.clocks[a].keeps_never for a in sensed):
        found = collapse(dta, sensors, sta.truncation_points)
        used, ignored = dict(found.sensors), found.blind
        for a in sorted(ignored):
            log.info("sensors.%s: its reports come %d steps after the event at the "
                     "earliest, and from step %s on the task no longer depends on when the "
                     "sensed events happened (the last can happen at step %d): solved as "
                     "a blind sensor, the same optimum", a, sensors[a].delay,
                     found.decided_from, found.last)
    size = info_size(game, sta, used)
    _announce(game, sta, sensed, max_states, memory, size)
    belief = _Builder(game, dta, sta, sensed, used, max_states, memory, size,
                      ends).build(progress)
    return Belief(belief.mdp, sta, sensed, sensors, belief.moves, ignored)


def _announce(game: Game[Any], sta: STA, sensed: tuple[str, ...], max_states: int,
              max_memory: int, size: InfoSize) -> None:
    """Say, before the build, how large the information-state product may grow: the
    fully observed product's bound at these truncation points, the hypotheses each
    state may hold, and the budgets that stop it."""
    points = sta.truncation_points
    # not yet, or at step 1..T, or never
    hypotheses = math.prod(points[a] + 1 + sta.clocks[a].keeps_never for a in sensed)
    cap = min(max_states, max_memory // BYTES_PER_INFO_STATE)
    log.info("information-state product: the fully observed one has %s; each state here "
             "also holds up to %s hypotheses of when %s happened (%s), so it may be far "
             "larger: it stops past %s states (max_states %s; max_memory %.1f GiB at %s "
             "bytes a state)",
             estimate_size(game, sta), f"{hypotheses:,}", ", ".join(sensed),
             ", ".join(f"{a} truncated at step {points[a]}" for a in sensed), f"{cap:,}",
             f"{max_states:,}", max_memory / 2**30, f"{BYTES_PER_INFO_STATE:,}")
    log.info("information states: %s", size)


class _Builder:
    def __init__(self, game: Game[Any], dta: DTA, sta: STA, sensed: tuple[str, ...],
                 sensors: Mapping[str, Sensor], max_states: int, max_memory: int,
                 size: InfoSize, ends: Ends | None = None) -> None:
        self.game, self.dta, self.sta, self.size = game, dta, sta, size
        self.ends = ends
        self.sensed, self.sensors, self.max_states = sensed, sensors, max_states
        self.max_memory, self.bytes = max_memory, 0
        self.unsensed = frozenset(sta.events) - frozenset(sensed)
        self.clocks = sta.clocks
        # the clock matters up to these bounds (a truncated event's point, an exact
        # event's cap); past all of them the key keeps none
        self.bound = {a: (c.truncation if c.truncation is not None else c.cap)
                      for a, c in sta.clocks.items()}
        self.index: dict[Hashable, int] = {}
        self.states: list[InfoState | Hashable] = []
        self.moves: dict[tuple[int, str], dict[Obs, int | Absorbing]] = {}
        self.succ: dict[tuple[Hashable, str, frozenset[str]], tuple[Any, ...]] = {}
        self.step_cache: dict[tuple[int, frozenset[str]], int] = {}
        self.live_cache: dict[tuple[int, frozenset[str], int], bool] = {}
        self.label_cache: dict[Hashable, frozenset[str]] = {}
        self.branch_cache: dict[tuple[tuple[int, ...], frozenset[str], int], list[Any]] = {}
        self.hazard_cache: dict[tuple[str, int], float] = {}
        self.props = frozenset(dta.atoms) - frozenset(sta.events)
        # where acceptance can still come from: the accepting state, or a safe one a run
        # may stay in (a task with a safety part); a hypothesis reaching none is lost
        self.persistent = dta.persistent | (
            frozenset() if dta.accepting is None else frozenset({dta.accepting}))

    # ---------------------------------------------------------------- states

    def intern(self, state: InfoState | Hashable) -> int:
        key = state.key() if isinstance(state, InfoState) else state
        i = self.index.get(key)
        if i is not None:
            if isinstance(state, InfoState):
                old = self.states[i]
                assert isinstance(old, InfoState)
                gap = max(abs(a - b) for a, b in zip(old.weights, state.weights, strict=True))
                if gap > WEIGHT_TOL:  # the posterior is not a function of the key
                    raise RuntimeError(
                        f"internal error: information state {key!r} reached with two "
                        f"posteriors (they differ by {gap:.3g})")
            return i
        if len(self.states) >= self.max_states:
            raise ProductTooLarge(
                f"the information-state product has more than {self.max_states:,} states "
                f"(sensed events: {', '.join(self.sensed)}; truncation points: "
                f"{self.sta.truncation_points}; {self.size}); raise max_states, loosen "
                "epsilon, or shrink the model")
        cost = BYTES_PER_INFO_STATE + (
            BYTES_PER_HYPOTHESIS * len(state.hypotheses) if isinstance(state, InfoState) else 0)
        if self.bytes + cost > self.max_memory:
            raise ProductTooLarge(
                f"the information-state product would need more than {self.max_memory:,} "
                f"bytes ({len(self.states):,} states so far, sensed events: "
                f"{', '.join(self.sensed)}; {self.size}); raise max_memory, loosen "
                "epsilon, or shrink the model")
        self.bytes += cost
        self.index[key] = len(self.states)
        self.states.append(state)
        return len(self.states) - 1

    def clock_key(self, t: int, hyps: list[tuple[int, ...]], pending: frozenset[str],
                  reported: frozenset[str]) -> int:
        """``t`` capped where nothing left reads it any more (module docs): an unsensed
        pending event reads it up to its bound; a sensed one while it may not have
        happened (up to its truncation point plus its delay) or, not reported, while some
        hypothesis's report may not be due yet (``k + delay > t``)."""
        need = [self.bound[b] for b in pending]
        for i, a in enumerate(self.sensed):
            values = [h[i] for h in hyps]
            delay = self.sensors[a].delay
            cut = self.clocks[a].report_limit or 0  # the misses counted up to R
            happened = [k for k in values if k > 0]
            if NOT_YET in values:
                need.append(self.bound[a] + delay + cut)
            elif a not in reported and happened:
                need.append(max(happened) + delay + cut)
        return min(t, max(need, default=0))

    def make(self, world: Hashable, t: int, reported: frozenset[str],
             pending: frozenset[str], mass: Mapping[tuple[tuple[int, ...], int], float],
             ) -> InfoState:
        total = math.fsum(mass.values())
        hyps = tuple(sorted(mass))
        return InfoState(world, self.clock_key(t, [h for h, _ in hyps], pending, reported),
                         reported, pending, hyps, tuple(mass[h] / total for h in hyps))

    def automaton(self, q: int, label: frozenset[str]) -> int:
        key = (q, label)
        q2 = self.step_cache.get(key)
        if q2 is None:
            q2 = self.step_cache[key] = self.dta.step(q, label)
        return q2

    def end(self, q: int, left: frozenset[str]) -> Hashable | None:
        """Where a hypothesis in automaton state ``q`` ends, ``left`` the events that can
        still happen (:data:`Ends`; by default the task's verdict, a task it can no
        longer accept counting as rejected)."""
        if self.ends is not None:
            return self.ends(q, left, self.reaches)
        if q == self.dta.accepting:
            return Absorbing.TARGET
        if q == self.dta.rejecting or not self.can_accept(q, left):
            return Absorbing.SINK
        return None

    def reaches(self, dta: DTA, q: int, pending: frozenset[str]) -> bool:
        """:meth:`can_accept` for another automaton ``dta`` (a part of a joint one)."""
        return self.can_accept(q, pending, dta)

    def can_accept(self, q: int, pending: frozenset[str], dta: DTA | None = None) -> bool:
        """Whether some word reaches acceptance (the accepting state, or a safe state of
        a task with a safety part) from ``q`` when only ``pending`` events can still
        happen (an event happens once): a hypothesis that cannot is lost
        whatever the robot does, and goes to the sink.  Beyond
        :data:`MAX_PRUNE_ATOMS` letters' atoms every hypothesis is kept (sound, larger).
        ``dta``: the automaton (the task's by default)."""
        d = self.dta if dta is None else dta
        key = (q, pending, id(d))
        hit = self.live_cache.get(key)
        if hit is not None:
            return hit
        props = frozenset(d.atoms) - frozenset(self.sta.events)
        atoms = sorted(props | (pending & frozenset(d.atoms)))
        if len(atoms) > MAX_PRUNE_ATOMS:
            self.live_cache[key] = True
            return True
        letters = [frozenset(x for x, bit in zip(atoms, bits, strict=True) if bit)
                   for bits in itertools.product((0, 1), repeat=len(atoms))]
        seen, todo = {q}, [q]
        persistent = self.persistent if d is self.dta else d.persistent | (
            frozenset() if d.accepting is None else frozenset({d.accepting}))
        found = q in persistent
        while todo and not found:
            u = todo.pop()
            for letter in letters:
                v = self.automaton(u, letter) if d is self.dta else d.step(u, letter)
                if v in persistent:
                    found = True
                    break
                if v not in seen:
                    seen.add(v)
                    todo.append(v)
        self.live_cache[key] = found
        return found

    # ---------------------------------------------------------------- one step

    def unsensed_outcomes(self, pending: frozenset[str], t: int
                          ) -> list[tuple[frozenset[str], float, bool]]:
        """``(events, probability, truncated)`` of the unsensed events of the next step."""
        events = sorted(pending)
        out = []
        for happened in itertools.product((False, True), repeat=len(events)):
            p = 1.0
            for a, yes in zip(events, happened, strict=True):
                h = self.hazard(a, t)
                p *= h if yes else 1.0 - h
            if p <= 0.0:
                continue
            occurred = frozenset(a for a, yes in zip(events, happened, strict=True) if yes)
            crossed = any((T := self.clocks[a].truncation) is not None and t + 1 >= T
                          for a in pending - occurred)
            out.append((occurred, p, crossed))
        return out

    def hazard(self, event: str, t: int) -> float:
        key = (event, t)
        h = self.hazard_cache.get(key)
        if h is None:
            h = self.hazard_cache[key] = self.clocks[event].hazard(t)
        return h

    def label(self, world: Hashable) -> frozenset[str]:
        props = self.label_cache.get(world)
        if props is None:
            props = self.label_cache[world] = frozenset(self.game.propositions(world))
        return props

    def sensed_branches(self, times: tuple[int, ...], reported: frozenset[str], t: int
                        ) -> list[tuple[tuple[int, ...], frozenset[str], float, bool]]:
        """``(times', newly reported, probability, truncated)`` of one hypothesis's
        sensed events over the next step, with the events that happen in it."""
        key = (times, reported, t)
        hit = self.branch_cache.get(key)
        if hit is None:
            hit = self.branch_cache[key] = self._sensed_branches(times, reported, t)
        return hit

    def _sensed_branches(self, times: tuple[int, ...], reported: frozenset[str], t: int
                         ) -> list[Any]:
        per_event = []
        for i, a in enumerate(self.sensed):
            clock, d = self.clocks[a], self.sensors[a].detect
            delay = self.sensors[a].delay
            k = times[i]
            options: list[tuple[int, bool, float, bool]] = []
            if k == NOT_YET:
                h = self.hazard(a, t)
                T = clock.truncation
                assert T is not None and t < T
                if h < 1.0 and clock.keeps_never and t + 1 >= T:
                    # past T: "never" kept, "later than T" cut (module docs)
                    never = min(float(clock.distribution.never)
                                / float(clock.distribution.survival(T)), 1.0)
                    options += [(NEVER, False, (1.0 - h) * never, False),
                                (NOT_YET, False, (1.0 - h) * (1.0 - never), True)]
                elif h < 1.0:
                    options.append((NOT_YET, False, 1.0 - h, t + 1 >= T))
                if h > 0.0 and delay == 0:
                    options += [(t + 1, True, h * d, False), (t + 1, False, h * (1 - d), False)]
                elif h > 0.0:  # its report is not due before step t + 1 + delay
                    options.append((t + 1, False, h, False))
            elif k == NEVER or a in reported or k + delay > t + 1:
                options.append((k, False, 1.0, False))
            else:  # due: reported, or missed (cut at the R-th miss, module docs)
                R = clock.report_limit
                options += [(k, True, d, False),
                            (k, False, 1.0 - d, R is not None and t + 2 - k - delay >= R)]
            per_event.append([o for o in options if o[2] > 0.0])
        out = []
        for combo in itertools.product(*per_event):
            p = math.prod(o[2] for o in combo)
            times2 = tuple(o[0] for o in combo)
            out.append((times2,
                        frozenset(a for a, o in zip(self.sensed, combo, strict=True) if o[1]),
                        p, any(o[3] for o in combo),
                        frozenset(a for a, k, k2 in zip(self.sensed, times, times2, strict=True)
                                  if k2 != k and k2 > 0),
                        frozenset(a for a, k2 in zip(self.sensed, times2, strict=True)
                                  if k2 == NOT_YET)))
        return out

    def expand(self, i: int, s: InfoState) -> list[tuple[str, dict[int, float]]]:
        rows = []
        t = s.clock
        for act in self.game.actions(s.world):
            row: dict[int, float] = {}
            groups: dict[tuple[Obs, frozenset[str]], dict[tuple[tuple[int, ...], int], float]]
            groups = {}
            ends: dict[Obs, set[Hashable]] = {}
            for occurred, pu, crossed in self.unsensed_outcomes(s.pending, t):
                if crossed:
                    j = self.intern(Absorbing.TRUNCATED)
                    row[j] = row.get(j, 0.0) + pu
                    continue
                skey = (s.world, act, occurred)
                succ = self.succ.get(skey)
                if succ is None:
                    succ = self.succ[skey] = tuple(self.game.successors(s.world, act, occurred))
                for (times, q), w in zip(s.hypotheses, s.weights, strict=True):
                    for times2, new, pc, cut, now, waiting in self.sensed_branches(
                            times, s.reported, t):
                        base = w * pu * pc
                        if cut:
                            j = self.intern(Absorbing.TRUNCATED)
                            row[j] = row.get(j, 0.0) + base
                            continue
                        happened = occurred | now
                        left = (s.pending - occurred) | waiting
                        for g2, pg in succ:
                            if pg <= 0.0:
                                continue
                            label = self.label(g2) | happened
                            q2 = self.automaton(q, label)
                            obs: Obs = (g2, occurred, new)
                            mass = base * pg
                            end = self.end(q2, left)
                            if end is not None:
                                j = self.intern(end)
                                row[j] = row.get(j, 0.0) + mass
                                ends.setdefault(obs, set()).add(end)
                                continue
                            group = groups.setdefault((obs, s.pending - occurred), {})
                            group[(times2, q2)] = group.get((times2, q2), 0.0) + mass
            moves = self.moves.setdefault((i, act), {})
            for (obs, pending2), mass in groups.items():
                g2, _, new = obs
                state = self.make(g2, t + 1, s.reported | new, pending2, mass)
                j = self.intern(state)
                row[j] = row.get(j, 0.0) + math.fsum(mass.values())
                moves[obs] = j
            for obs, kinds in ends.items():
                if obs not in moves:  # nothing undecided left: the verdict, if one
                    moves[obs] = (next(iter(kinds)) if len(kinds) == 1
                                  else Absorbing.TRUNCATED)
            rows.append((act, row))
        return rows

    # ---------------------------------------------------------------- the MDP

    def build(self, progress: bool | None = None) -> Belief:
        game, dta = self.game, self.dta
        q0 = dta.step(dta.initial, frozenset(game.propositions(game.initial)))
        first = self.end(q0, frozenset(self.sta.events)) if (
            self.ends is not None or q0 in (dta.accepting, dta.rejecting)) else None
        if first is not None:
            initial = self.intern(first)
        else:
            times0 = (NOT_YET,) * len(self.sensed)
            initial = self.intern(self.make(game.initial, 0, frozenset(), self.unsensed,
                                            {(times0, q0): 1.0}))
        indptr, cols, vals = [0], [], []
        groups, actions = [0], []
        names: dict[str, int] = {}
        head = 0
        shown = progress_bar(progress, total=None, unit=" states", desc="information states",
                             leave=False, mininterval=0.5)
        while head < len(self.states):
            shown.update()
            s = self.states[head]
            if not isinstance(s, InfoState):
                cols.append(head)
                vals.append(1.0)
                actions.append(ABSORB)
            else:
                for act, row in self.expand(head, s):
                    cols.extend(row)
                    vals.extend(row.values())
                    actions.append(names.setdefault(act, len(names)))
                    indptr.append(len(cols))
                groups.append(len(actions))
                head += 1
                continue
            indptr.append(len(cols))
            groups.append(len(actions))
            head += 1
        shown.close()
        log.info("information-state product: %s states, %s choices, %s transitions",
                 f"{len(self.states):,}", f"{len(actions):,}", f"{len(cols):,}")
        n = len(self.states)
        kind = np.array([{Absorbing.TARGET: 1, Absorbing.SINK: 2, Absorbing.TRUNCATED: 3}
                         .get(s, 0) if isinstance(s, Absorbing) else 0 for s in self.states],
                        dtype=np.int8)
        matrix = sp.csr_array((np.asarray(vals, dtype=np.float64),
                               np.asarray(cols, dtype=np.int32),
                               np.asarray(indptr, dtype=np.int64)), shape=(len(actions), n))
        mdp = MDP(matrix=matrix, row_groups=np.asarray(groups, dtype=np.int64),
                  choice_actions=np.asarray(actions, dtype=np.int32),
                  action_names=tuple(sorted(names, key=names.__getitem__)),
                  initial=initial, target=kind == 1, sink=kind == 2, truncated=kind == 3,
                  states=tuple(self.states))
        return Belief(mdp, self.sta, self.sensed, self.sensors, self.moves)
