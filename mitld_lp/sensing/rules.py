"""The rules of one step of the information-state product
(:mod:`mitld_lp.sensing.belief`'s module docs): the events' hazards, the outcomes of the
unsensed events, the branches of one hypothesis's sensed events and their reports, the
automaton's step, where a hypothesis ends, and the clock an information state keeps;
the construction (:mod:`mitld_lp.sensing.frontier`) asks each once per new key, and
each is cached.  A hypothesis's times hold one value per sensed event, then, for each
sensed event whose sensor gives false alarms (``StepRules.alarms``), the count of its
reports before its report was due (the belief's module docs)."""

from __future__ import annotations

import itertools
import math
from collections.abc import Hashable, Mapping
from typing import Any

from mitld_lp.automata.dta import DTA
from mitld_lp.automata.sta import STA
from mitld_lp.product import Absorbing
from mitld_lp.sensing.info import MAX_PRUNE_ATOMS, NEVER, NOT_YET, Ends
from mitld_lp.sensing.sensors import Sensor
from mitld_lp.worlds.game import Game

__all__ = ["StepRules"]


class StepRules:
    """The step rules of a task's automaton ``dta`` with the clocks of ``sta`` in
    ``game``, the events of ``sensors`` (in ``sensed`` order) hidden; ``ends``: where a
    hypothesis ends (:data:`mitld_lp.sensing.info.Ends`, None: the task's verdict)."""

    def __init__(self, game: Game[Any], dta: DTA, sta: STA, sensed: tuple[str, ...],
                 sensors: Mapping[str, Sensor], ends: Ends | None = None) -> None:
        self.game, self.dta, self.sta = game, dta, sta
        self.ends = ends
        self.sensed, self.sensors = sensed, sensors
        # the sensed events whose sensors give false alarms: each keeps, after the
        # events' times, the count of its reports before its report is due (module docs)
        self.alarms = tuple(i for i, a in enumerate(sensed) if sensors[a].false_alarm > 0.0)
        self.unsensed = frozenset(sta.events) - frozenset(sensed)
        self.clocks = sta.clocks
        # the clock matters up to these bounds (a truncated event's point, an exact
        # event's cap); past all of them the key keeps none
        self.bound = {a: (c.truncation if c.truncation is not None else c.cap)
                      for a, c in sta.clocks.items()}
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


    def initial_verdict(self) -> tuple[int, Hashable | None]:
        """The automaton's state after the world's initial label, and where a hypothesis
        in it ends before any step (:meth:`end` with every event still to come; asked
        only when ``ends`` is given or the state already decides the task), None while
        it is undecided: the initial information state is then built."""
        game, dta = self.game, self.dta
        q0 = dta.step(dta.initial, frozenset(game.propositions(game.initial)))
        if self.ends is None and q0 not in (dta.accepting, dta.rejecting):
            return q0, None
        return q0, self.end(q0, frozenset(self.sta.events))

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
        n = len(self.sensed)
        count = dict(zip(self.alarms, times[n:], strict=True))
        per_event = []
        for i, a in enumerate(self.sensed):
            clock, sensor = self.clocks[a], self.sensors[a]
            d, fa, delay = sensor.detect, sensor.false_alarm, sensor.delay
            k = times[i]
            # (k', reported, probability, truncated, reports counted before due)
            options: list[tuple[int, bool, float, bool, int]] = []
            if fa > 0.0:  # a report or none at every step (module docs)
                options = self._alarm_options(k, t, clock, d, fa, delay)
            elif k == NOT_YET:
                h = self.hazard(a, t)
                T = clock.truncation
                assert T is not None and t < T
                if h < 1.0 and clock.keeps_never and t + 1 >= T:
                    # past T: "never" kept, "later than T" cut (module docs)
                    never = min(float(clock.distribution.never)
                                / float(clock.distribution.survival(T)), 1.0)
                    options += [(NEVER, False, (1.0 - h) * never, False, 0),
                                (NOT_YET, False, (1.0 - h) * (1.0 - never), True, 0)]
                elif h < 1.0:
                    options.append((NOT_YET, False, 1.0 - h, t + 1 >= T, 0))
                if h > 0.0 and delay == 0:
                    options += [(t + 1, True, h * d, False, 0),
                                (t + 1, False, h * (1 - d), False, 0)]
                elif h > 0.0:  # its report is not due before step t + 1 + delay
                    options.append((t + 1, False, h, False, 0))
            elif k == NEVER or a in reported or k + delay > t + 1:
                options.append((k, False, 1.0, False, 0))
            else:  # due: reported, or missed (cut at the R-th miss, module docs)
                R = clock.report_limit
                options += [(k, True, d, False, 0),
                            (k, False, 1.0 - d, R is not None and t + 2 - k - delay >= R, 0)]
            per_event.append([o for o in options if o[2] > 0.0])
        out = []
        for combo in itertools.product(*per_event):
            p = math.prod(o[2] for o in combo)
            times2 = tuple(o[0] for o in combo) + tuple(
                count[i] + combo[i][4] for i in self.alarms)
            out.append((times2,
                        frozenset(a for a, o in zip(self.sensed, combo, strict=True) if o[1]),
                        p, any(o[3] for o in combo),
                        frozenset(a for a, k, k2 in zip(self.sensed, times[:n], times2[:n],
                                                        strict=True) if k2 != k and k2 > 0),
                        frozenset(a for a, k2 in zip(self.sensed, times2[:n], strict=True)
                                  if k2 == NOT_YET)))
        return out

    def _alarm_options(self, k: int, t: int, clock: Any, d: float, fa: float, delay: int
                       ) -> list[tuple[int, bool, float, bool, int]]:
        """One sensed event's options over step ``t + 1`` when its sensor gives false
        alarms: it reports with probability ``fa`` before step ``k + delay`` (a report
        counted) and ``d`` from it on, whether it reported before or not; the law surely
        happens (a law that may never happen is refused), truncated at ``T``."""
        def reports(k2: int, p: float, cut: bool) -> list[tuple[int, bool, float, bool, int]]:
            if k2 != NOT_YET and k2 + delay <= t + 1:  # due
                return [(k2, True, p * d, cut, 0), (k2, False, p * (1.0 - d), cut, 0)]
            return [(k2, True, p * fa, cut, 1), (k2, False, p * (1.0 - fa), cut, 0)]

        if k != NOT_YET:
            return reports(k, 1.0, False)
        T = clock.truncation
        assert T is not None and t < T and not clock.keeps_never
        h = self.hazard(clock.event, t)
        out = reports(NOT_YET, 1.0 - h, t + 1 >= T) if h < 1.0 else []
        return out + (reports(t + 1, h, False) if h > 0.0 else [])
