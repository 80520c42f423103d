"""The records of the information-state product (:mod:`mitld_lp.sensing.belief`): an
information state, the product with what a controller needs to follow it, the size one
state can reach, and the constants and callback types the construction shares."""

from __future__ import annotations

import math
from collections.abc import Callable, Hashable, Mapping
from dataclasses import dataclass
from typing import Any

from mitld_lp.automata.dta import DTA
from mitld_lp.automata.sta import STA
from mitld_lp.mdp import MDP
from mitld_lp.product import Absorbing
from mitld_lp.sensing.sensors import Sensor
from mitld_lp.worlds.game import Game, world_members

__all__ = ["InfoState", "Belief", "InfoSize", "info_size", "Obs", "Reaches", "Ends",
           "NOT_YET", "NEVER", "MAX_PRUNE_ATOMS", "WEIGHT_TOL", "BYTES_PER_INFO_STATE",
           "BYTES_PER_HYPOTHESIS"]

NOT_YET = 0
"""A hypothesis's value for a sensed event that has not happened (yet)."""
NEVER = -1
"""A hypothesis's value for a sensed event that will never happen (a law with
``never > 0``, past its truncation point: module docs)."""

MAX_PRUNE_ATOMS = 14
"""The most atoms whose letters :meth:`mitld_lp.sensing.rules.StepRules.can_accept` enumerates."""

WEIGHT_TOL = 1e-9
"""How far two visits of one information state may disagree on its posterior."""

BYTES_PER_INFO_STATE = 6_500
"""Bytes an information state costs in the build (its record, index entry, rows, moves
and caches): with :data:`BYTES_PER_HYPOTHESIS`, a fit of the build's peak (tracemalloc)
on the bus case with one and with two sensed buses (2,693 states / 6,996 hypotheses:
17.6 MB; 3,751 / 17,213: 25.6 MB)."""
BYTES_PER_HYPOTHESIS = 200
"""Bytes each hypothesis of a state costs (its key tuple, its weight, its row entries)."""

Obs = tuple[Hashable, frozenset[str], frozenset[str]]
"""What the robot observes after a step: world state, unsensed events, new reports."""

Reaches = Callable[[DTA, int, frozenset[str]], bool]
"""Whether some word reaches acceptance of a DTA from a state when only the given
events can still happen (:meth:`mitld_lp.sensing.rules.StepRules.can_accept`)."""

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
    event's truncation point plus its sensor's delay:
    :meth:`mitld_lp.sensing.rules.StepRules.clock_key`),
    ``hypotheses`` the most hypotheses a state holds (a step up to the truncation point,
    or not yet, per sensed event; one automaton state each, the observations fixing the
    run), ``world_states`` (None if the game does not say), ``patterns`` the report
    patterns whose posteriors a world path may tell apart (1 without false alarms; with
    them, per such sensor ``sum_t 2^(min(t, T + D - 1) - D)`` over the clock ``t <= T +
    D``: the reports of the steps between the first and the last due step, multiplied
    over the sensors).  The states themselves are counted as they are built."""

    world_states: int | None
    clock: int
    hypotheses: int
    patterns: int = 1

    def __str__(self) -> str:
        world = "an unknown number of" if self.world_states is None else (
            f"{self.world_states:,}")
        alarms = "" if self.patterns == 1 else (
            f", up to {self.patterns:,} report patterns (false alarms) per world path")
        return (f"{world} world states, the clock kept up to step {self.clock:,}, at most "
                f"{self.hypotheses:,} hypotheses per state{alarms}")


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
    patterns = math.prod(
        sum(2 ** max(0, min(t, points[a] + s.delay - 1) - s.delay)
            for t in range(points[a] + s.delay + 1))
        for a, s in sensors.items() if s.false_alarm > 0.0)
    return InfoSize(world_members(game).n_states, max(bounds, default=0),
                    math.prod(t + 1 + sta.clocks[a].keeps_never for a, t in points.items()),
                    patterns)
