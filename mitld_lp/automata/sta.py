"""The stochastic timed automaton (STA): the DTA plus the external events' distributions.

A state of the paper's STA is ``(location, clock vector, Y)`` with ``Y`` the events that
have not happened yet.  Two facts make it small and exact here:

* Every event is pending from step 0 and stops mattering once it has happened, so the
  age of *every* pending event is the current step ``t``: one clock serves them all
  (the paper keeps one per event; they would always be equal).
* The per-step probability of a pending event ``a`` at step ``k`` is its *hazard*
  ``h_a(k) = mu_a(k) / P(K_a > k - 1)`` (the paper's ``mu_a(v + tau)`` is right
  only for the geometric distribution).  An event whose hazard is constant from step
  ``k0`` on needs the clock only up to ``k0 - 1`` (memoryless: no clock at all); an
  event whose hazard never becomes constant is truncated at a point ``T_a``: a run still
  waiting for it after step ``T_a`` goes to the truncation sink, with probability
  ``P(K_a > T_a)``.

The paper's four cases of the transition probability are one product over the pending
events: ``p(E) = prod_{a in E} h_a(k) * prod_{b in Y \\ E} (1 - h_b(k))`` for the set ``E``
of events that happen at step ``k = t + 1``.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

from mitld_lp import defaults
from mitld_lp.automata.dta import DTA
from mitld_lp.distributions import FirstOccurrence

__all__ = [
    "EventClock", "STA", "EventOutcome", "Ambiguity", "ClockStep", "TRUNCATED", "advance_clock",
    "make_sta",
]

TRUNCATED = -1
"""The clock value of an outcome that ran past a truncation point."""


@dataclass(frozen=True, slots=True)
class EventClock:
    """How the clock is kept for one event.

    ``cap``: clock values ``>= cap`` are equivalent for this event (its hazard is
    constant from step ``cap + 1`` on); ``truncation``: the point ``T``: a run in which
    the event has not happened by step ``T`` goes to the truncation sink, which cuts
    exactly the mass ``P(K > T)`` (None: exact).  A truncated event's clock thus runs
    up to ``T - 1``.
    """

    event: str
    distribution: FirstOccurrence
    cap: int
    truncation: int | None
    # a sensed event whose law may never happen (:mod:`mitld_lp.sensing.belief`): at
    # ``T`` "never" is kept as a hypothesis of its own, not cut; ``report_limit`` ``R``:
    # a hypothesis "happened, missed by its sensor ``R`` times" is cut, ``report_tail``
    # the most mass that cut takes
    keeps_never: bool = False
    report_limit: int | None = None
    report_tail: float = 0.0

    def hazard(self, clock: int) -> float:
        """Probability that the event happens in the step after ``clock`` steps."""
        return float(self.distribution.hazard(min(clock, self.cap) + 1))

    def band(self, clock: int) -> tuple[float, float]:
        """The hazards the law allows in the step after ``clock`` steps (both
        :meth:`hazard` for a law known exactly)."""
        lo, hi = self.distribution.hazard_band(min(clock, self.cap) + 1)
        return float(lo), float(hi)

    @property
    def tail(self) -> float:
        """P(K > truncation): the probability mass the truncation cuts off (for a band,
        the most any law of the band leaves); for a sensed event that keeps "never",
        ``P(truncation < K < inf)`` and the sensor's cut (``report_tail``)."""
        if self.truncation is None:
            return 0.0
        tail = float(self.distribution.survival_upper(self.truncation))
        if self.keeps_never:  # the never-mass is a hypothesis, not cut
            from mitld_lp.distributions.band import last_event_step  # bands only

            last = last_event_step(self.distribution)  # a band: none happens past it
            tail = 0.0 if last is not None and last <= self.truncation else max(
                tail - float(self.distribution.never), 0.0)
        return tail + self.report_tail


@dataclass(frozen=True, slots=True)
class ClockStep:
    """The clock after one step (:meth:`STA.advance`).

    ``clock``: ``min(t + 1, cap(pending))``, the value the model keeps; ``truncated``:
    some pending event ran past its truncation point (``t + 1 >= T_a``), so the model
    has left its truncated region (the product sends the run to the truncation sink;
    a controller keeps acting with ``clock``).
    """

    clock: int
    truncated: bool


@dataclass(frozen=True, slots=True)
class EventOutcome:
    """One outcome of a step's events: which happened, its probability, what follows.

    In :meth:`STA.robust_outcomes` the probability is that of the events known exactly
    only, and ``branch`` says which ambiguous events happened (bit ``i``: the ``i``-th of
    the situation's :class:`Ambiguity`); elsewhere ``branch`` is 0."""

    occurred: frozenset[str]
    probability: float
    pending: frozenset[str]
    clock: int  # TRUNCATED when the outcome crosses a truncation point
    branch: int = 0


@dataclass(frozen=True, slots=True)
class Ambiguity:
    """The pending events of a situation whose hazard for the next step is an interval
    (``lo < hi``), in order, with their intervals: nature picks each hazard inside."""

    events: tuple[str, ...]
    lo: tuple[float, ...]
    hi: tuple[float, ...]


@dataclass(frozen=True, slots=True, eq=False)
class STA:
    """A DTA with the distributions of its external events (see the module docstring)."""

    dta: DTA
    clocks: Mapping[str, EventClock]
    _cache: dict[tuple[frozenset[str], int], tuple[EventOutcome, ...]] = field(
        default_factory=dict, repr=False
    )

    @property
    def events(self) -> frozenset[str]:
        return frozenset(self.clocks)

    @property
    def is_ambiguous(self) -> bool:
        """Whether some event's law is a band (the product is then an interval MDP)."""
        return any(c.distribution.is_ambiguous for c in self.clocks.values())

    @property
    def truncation_points(self) -> dict[str, int]:
        return {a: c.truncation for a, c in self.clocks.items() if c.truncation is not None}

    @property
    def epsilon_achieved(self) -> float:
        """The probability that some truncated event is still pending after its truncation
        point, ``1 - prod_a (1 - P(K_a > T_a))`` (events are independent); it bounds
        ``upper - lower``."""
        keep = 1.0
        for c in self.clocks.values():
            keep *= 1.0 - c.tail
        return 1.0 - keep

    def advance(self, pending: frozenset[str], clock: int) -> ClockStep:
        """The clock one step after ``clock`` while ``pending`` are still pending
        (:func:`advance_clock` with this STA's caps and truncation points)."""
        return advance_clock(
            pending, clock, {a: c.cap for a, c in self.clocks.items()}, self.truncation_points
        )

    def outcomes(self, pending: frozenset[str], clock: int) -> tuple[EventOutcome, ...]:
        """The distribution of the events of the next step, from ``clock`` with ``pending``.

        The outcomes' probabilities sum to 1; outcomes of probability 0 are left out.
        """
        key = (pending, clock)
        hit = self._cache.get(key)
        if hit is not None:
            return hit
        events = sorted(pending)
        result = self._outcomes(pending, clock, events, [self.clocks[a].hazard(clock)
                                                         for a in events], ())
        self._cache[key] = result
        return result

    def robust_outcomes(
        self, pending: frozenset[str], clock: int
    ) -> tuple[tuple[EventOutcome, ...], Ambiguity]:
        """The next step's outcomes when some hazards are intervals: the events whose
        hazard at this step is an interval (:class:`Ambiguity`) are left to nature; each
        outcome's probability is the product over the other events only, and its
        ``branch`` says which ambiguous events happened.  For every branch the
        probabilities sum to 1.  With no ambiguous event this is :meth:`outcomes`."""
        bands = {a: self.clocks[a].band(clock) for a in sorted(pending)}
        open_ = tuple(a for a, (lo, hi) in bands.items() if lo < hi)
        exact = [a for a in bands if a not in open_]
        events = [*exact, *open_]
        hazards = [bands[a][0] for a in exact] + [0.5] * len(open_)
        outs = self._outcomes(pending, clock, events, hazards, open_)
        return outs, Ambiguity(open_, tuple(bands[a][0] for a in open_),
                               tuple(bands[a][1] for a in open_))

    def _outcomes(
        self, pending: frozenset[str], clock: int, events: list[str], hazards: list[float],
        ambiguous: tuple[str, ...],
    ) -> tuple[EventOutcome, ...]:
        """``p(E) = prod_{a in E} h_a prod_{b not in E} (1 - h_b)`` over the events not in
        ``ambiguous``; each ambiguous event's outcome is a bit of the branch."""
        out = []
        for happened in itertools.product((False, True), repeat=len(events)):
            p = 1.0
            branch = 0
            for a, h, yes in zip(events, hazards, happened, strict=True):
                if a in ambiguous:
                    branch |= int(yes) << ambiguous.index(a)
                else:
                    p *= h if yes else 1.0 - h
            if p <= 0.0:
                continue
            occurred = frozenset(a for a, yes in zip(events, happened, strict=True) if yes)
            left = pending - occurred
            step = self.advance(left, clock)
            out.append(EventOutcome(occurred, p, left,
                                    TRUNCATED if step.truncated else step.clock, branch))
        return tuple(out)


def advance_clock(
    pending: Iterable[str], clock: int, caps: Mapping[str, int], truncations: Mapping[str, int]
) -> ClockStep:
    """The clock one step after ``clock`` while ``pending`` are still pending.

    The one rule of the clock: it counts steps, ``t -> t + 1``; it is capped at
    ``max(caps[a] for a in pending)`` (beyond it no pending hazard changes); and the step
    crosses a truncation point when some pending event ``a`` has ``t + 1 >= T_a``
    (``truncations[a]``; an event without one is exact).  :meth:`STA.advance` and a
    controller loaded from a file (which has no distributions) both step through it.
    """
    t = clock + 1
    crossed = any((T := truncations.get(a)) is not None and t >= T for a in pending)
    return ClockStep(min(t, max((caps[a] for a in pending), default=0)), crossed)


def make_sta(
    dta: DTA,
    distributions: Mapping[str, FirstOccurrence],
    epsilon: float,
    *,
    clock_reduction: bool = True,
    truncation: Mapping[str, int] | None = None,
) -> STA:
    """Attach event distributions to ``dta``, choosing each event's clock.

    With ``clock_reduction`` an event whose hazard is constant from step ``k0`` on keeps
    the clock up to ``k0 - 1`` and is exact; the others are truncated, at the explicit
    points in ``truncation`` or else at the smallest ``T_a`` with ``P(K_a > T_a) <=
    epsilon / m`` (``m`` truncated events share the budget equally).  Without it every
    event is truncated, as in the paper.
    """
    truncation = dict(truncation or {})
    unknown = set(truncation) - set(distributions)
    if unknown:
        raise ValueError(f"truncation: no event named {', '.join(sorted(unknown))}")
    for a, T in truncation.items():
        if isinstance(T, bool) or not isinstance(T, int) or T < 1:
            raise ValueError(f"truncation.{a}: must be an integer >= 1, got {T!r}")
    exact = {
        a: d.constant_hazard_from
        for a, d in distributions.items()
        if clock_reduction and a not in truncation and d.constant_hazard_from is not None
    }
    cut = [a for a in distributions if a not in exact]
    auto = [a for a in cut if a not in truncation]
    if auto:
        try:
            defaults.check_epsilon(epsilon)
        except ValueError as err:
            raise ValueError(f"epsilon: {err}") from None
    clocks: dict[str, EventClock] = {}
    for a, d in sorted(distributions.items()):
        if a in exact:
            clocks[a] = EventClock(a, d, cap=exact[a] - 1, truncation=None)
        else:
            T = truncation[a] if a in truncation else d.truncation_point(epsilon / len(auto))
            clocks[a] = EventClock(a, d, cap=max(T - 1, 0), truncation=T)
    return STA(dta, clocks)
