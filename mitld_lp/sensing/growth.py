"""How fast the information-state product grows, judged level by level while it is built
(:mod:`mitld_lp.sensing.frontier`), and the early stop when it will not fit.

A *level* is the states first found one step after the previous level's (the build is
breadth first, and the frontier builder expands one level before the next).  What
multiplies the information states is the posterior over when each sensed event happened:
each observation history that a sensor leaves ambiguous keeps its own set of hypotheses
and weights, so while the clock runs (up to :attr:`~mitld_lp.sensing.info.InfoSize.clock`,
the last step any state keeps) the levels tend to grow by a steady factor, and once it
stops the hypotheses are decided and the levels shrink (the bus case with a camera on
bus 2: factors of about 1.5 a step up to the clock's end, then none new ten levels on).

No sound bound on the product's size is known short of the hypothesis sets' count (about
``1e19`` on the bus case), so the budget is checked from an *estimate* meant to err low
(:func:`projected`): at the end of each level from the clock's half-way step on (the
first levels grow fast whatever comes after: two cameras on the bus case grow by 2.5 a
step for four levels, then not at all), the levels still to come before the clock stops
are taken to grow by the least of the last three levels' factors, shrinking as the last
factors shrank, and none after it (a steady growth two levels after it: the largest
level came two steps after the clock's end on every case measured).  Where even that
passes ``max_states``, or ``max_memory`` at the bytes the states so far took each, the build
stops there, seconds in, instead of running to the budget; a product the estimate lets
through still meets the budget's exact check before each batch is stored.  On the cases
measured (experiments/bench_sensed.py's) the estimate is at no level above the true
size, so it stops a product later than the truth would allow rather than one that fits;
it is an estimate, not a bound, and raising the budget past it lets the build run.  With
false alarms the report patterns keep telling hypotheses apart for up to three levels
past the clock's last step, at some 1.15 a step, a growth neither steady nor fast, so
from the clock's last step on any growth above 1 is carried :data:`ALARM_PAST` levels
past it (the bus case's camera on bus 2, ``detect = 0.8, false_alarm = 0.05`` at
epsilon 0.05: at level 10, 170,234 states against 193,856 built; 86,964 at most
without it, at level 8).  The reacting build
(:mod:`mitld_lp.sensing.reacting`) with false alarms carries no growth past the clock's
last step (``past = 0``: its levels shrink from there), and its estimate errs high by
some 1.2 to 1.3 on the cases measured there."""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping

from mitld_lp.product import ProductTooLarge
from mitld_lp.sensing.info import BYTES_PER_HYPOTHESIS, BYTES_PER_INFO_STATE, InfoSize
from mitld_lp.sensing.sensors import Sensor

__all__ = ["Growth", "MIN_LEVEL", "STEADY", "MIN_GROWTH", "PAST", "ALARM_PAST", "projected"]

log = logging.getLogger("mitld_lp.sensing.belief")

MIN_LEVEL = 256
"""The fewest new states a level must have before the growth is judged (a smaller
product does not need stopping early; its factors are noise)."""
STEADY = 0.95
"""How close the last three factors must be for the growth to count as steady."""
MIN_GROWTH = 1.2
"""The least factor of a steady growth."""
PAST = 2
"""The levels a steady growth is carried past the clock's last step: on every case
measured the largest level came two steps after it (the hypotheses of the last steps
still split while the task's windows after them are open)."""
ALARM_PAST = 3
"""With false alarms, the levels any growth (a factor above 1, steady or not) seen at or
after the clock's last step is carried past it: the report patterns keep telling
hypotheses apart for up to three levels past it, at some 1.15 a step, below
:data:`MIN_GROWTH` (the bus case's camera on bus 2, ``detect = 0.8, false_alarm =
0.05`` at epsilon 0.05: levels of 21,953 at the clock's step 9, then 25,621, 29,935,
34,113 and 37,970, then 8,299)."""


def projected(sizes: list[int], clock: int, past: int = PAST,
              alarm_past: int = 0) -> tuple[int, float, int]:
    """The estimate (module docs) of the states the build will hold, from the sizes of
    its levels so far (``sizes[0]`` the first) and the last step the clock runs to: the
    least of the last three levels' factors, itself shrinking at each level to come by
    the last factor's ratio to the one before (when that is below 1), carried on up to
    level ``clock`` -- ``past`` (:data:`PAST`) levels further when the growth is steady (the three
    factors within :data:`STEADY` of each other, the least at least
    :data:`MIN_GROWTH`) --, or, from level ``clock`` on, ``alarm_past`` levels further
    where the growth (shrunk) is still above 1 (false alarms: :data:`ALARM_PAST`), none
    after.  Returns the estimate, the least factor and the
    level it is carried to.  Fewer than four levels, or before level ``clock / 2`` (the
    early levels grow fast whatever comes after): the states so far."""
    found, level = sum(sizes), len(sizes) - 1
    if level < 3 or 2 * level < clock or min(sizes[-4:]) <= 0:
        return found, 0.0, level
    factors = [sizes[-1] / sizes[-2], sizes[-2] / sizes[-3], sizes[-3] / sizes[-4]]
    factor, shrink = min(factors), min(1.0, factors[0] / factors[1])
    steady = factor >= MIN_GROWTH and factor >= STEADY * max(factors)
    last = clock + (past if steady else 0)
    if alarm_past and level >= clock and factor * shrink > 1.0:
        last = max(last, clock + alarm_past)
    least, more, n = factor, 0.0, float(sizes[-1])
    for _ in range(level, last):
        factor *= shrink
        n *= factor
        more += n
    return found + int(more), least, max(last, level)


class Growth:
    """The budgets of one build: the exact check before each batch of states is stored
    (:meth:`check`), and the states of each level, judged against the budgets at the end
    of each level (:meth:`level`, module docs).  ``name``: the model's (None: not
    known); ``points``: the sensed events' truncation points, for the messages;
    ``past``: the levels a steady growth is carried past the clock's last step
    (:func:`projected`)."""

    def __init__(self, *, max_states: int, max_memory: int, size: InfoSize,
                 sensors: Mapping[str, Sensor], points: Mapping[str, int],
                 name: str | None = None, past: int = PAST, alarm_past: int = 0) -> None:
        self.past, self.alarm_past = past, alarm_past
        self.sizes: list[int] = []
        self.estimate = 0  # the last level's estimate (the states so far before any)
        self.max_states, self.max_memory, self.size = max_states, max_memory, size
        self.sensors, self.points, self.name = sensors, points, name
        self.t0 = time.perf_counter()

    def start(self, first: int) -> None:
        """The build's first level: the ``first`` states stored before any expansion."""
        self.sizes = [first]
        self.estimate = 0
        self.t0 = time.perf_counter()

    def check(self, stored: int, used: int, new: int, hyps: int) -> None:
        """Raise :class:`ProductTooLarge` before ``new`` states of ``hyps`` hypotheses in
        all are stored past a budget, ``stored`` states of ``used`` bytes held so far (at
        :data:`BYTES_PER_INFO_STATE` a state and :data:`BYTES_PER_HYPOTHESIS` a
        hypothesis)."""
        sensed = ", ".join(sorted(self.sensors))
        if stored + new > self.max_states:
            raise ProductTooLarge(
                f"the information-state product{self.of()} has more than "
                f"{self.max_states:,} states (sensed events: {sensed}; truncation points: "
                f"{dict(self.points)}; {self.size}); raise max_states, loosen epsilon, or "
                "shrink the model")
        if used + BYTES_PER_INFO_STATE * new + BYTES_PER_HYPOTHESIS * hyps > self.max_memory:
            raise ProductTooLarge(
                f"the information-state product{self.of()} would need more than "
                f"{self.max_memory:,} bytes ({stored:,} states so far, sensed events: "
                f"{sensed}; {self.size}); raise max_memory, loosen epsilon, or shrink the "
                "model")

    def of(self) -> str:
        return "" if self.name is None else f" of model {self.name!r}"

    def level(self, new: int, hypotheses: int, used: int) -> None:
        """A level is done: ``new`` states found one step on, ``hypotheses`` and ``used``
        bytes held by every state so far.  Raises :class:`ProductTooLarge` where the
        estimate passes a budget."""
        self.sizes.append(new)
        found = sum(self.sizes)
        log.debug("information-state product: level %d, %s new states (%s in all, %s "
                  "hypotheses, %s bytes)", len(self.sizes) - 1, f"{new:,}", f"{found:,}",
                  f"{hypotheses:,}", f"{used:,}")
        if new < MIN_LEVEL:
            return
        estimate, factor, last = projected(self.sizes, self.size.clock, self.past,
                                           self.alarm_past)
        self.estimate = estimate
        need = used / max(found, 1) * estimate
        if estimate <= self.max_states and need <= self.max_memory:
            return
        budget = (f"max_states {self.max_states:,}" if estimate > self.max_states else
                  f"max_memory {self.max_memory:,} bytes, at the {used / found:,.0f} bytes "
                  f"a state the {found:,} so far took")
        events = ", ".join(f"{a} (sensors.{a}: detect {s.detect:g}, delay {s.delay}"
                           + (f", false_alarm {s.false_alarm:g}: every step's report "
                              "counts" if s.false_alarm else "") + "; "
                           f"truncated at step {self.points[a]})"
                           for a, s in sorted(self.sensors.items()))
        recent = ", ".join(f"{n:,}" for n in self.sizes[-4:])
        raise ProductTooLarge(
            f"the information-state product{self.of()} will not fit: its last levels found "
            f"{recent} new states, growing by a factor of {factor:.2f} a step or more, and "
            f"carried on to level {last} (the clock stops at step {self.size.clock}), the "
            f"growth shrinking as it did, it holds about {estimate:,} states, past "
            f"{budget} (stopped after "
            f"{found:,} states, {time.perf_counter() - self.t0:.1f} s). The cause: the "
            f"robot's posterior over when {events} happened differs with each observation "
            "history the sensor leaves ambiguous, and each such history keeps its own "
            "information state. Raise max_states or max_memory, loosen epsilon (earlier "
            "truncation points), use a sensor that detects more often, or shrink the model")
