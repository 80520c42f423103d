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

A sensor with false alarms (``false_alarm > 0``, a law that surely happens: with one
that may never happen the route builds the sensor blind,
:mod:`mitld_lp.routes.sensed_never`) reports or not at *every* step, with probability
``false_alarm`` before step ``k + delay`` and ``detect`` from it on; its event is never
kept as reported, and each hypothesis keeps, after its events' times, its count ``b`` of
that sensor's reports before its own report was due.  The likelihood of the reports
under ``k`` is ``fa^b (1 - fa)^(p - b) d^(r - b) (1 - d)^(n - p - r + b)`` (``p`` its
steps before due; ``r`` reports in ``n`` steps, common to all), so the posterior is a
function of the key (the counts made canonical: :class:`mitld_lp.sensing.merge.Counts`);
once every hypothesis is due the counts stop changing and the clock is no longer kept.
Up to ``2^(T - 1)`` report patterns (the steps between the first and the last due step)
may each keep their own state.  The times are then not shifted
(:mod:`mitld_lp.sensing.merge`), and no such sensor is collapsed to a blind one
(:mod:`mitld_lp.sensing.horizon`).  The truncation is the one above: a hypothesis not
happened by ``T`` goes to the truncation sink, whatever the law (memoryless or not), and
its mass is counted as failure in the lower model and success in the upper.

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

import logging
import math
from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np

from mitld_lp.automata.dta import DTA, SAFE
from mitld_lp.automata.sta import STA, EventClock, make_sta
from mitld_lp.distributions import FirstOccurrence
from mitld_lp.distributions.band import UnboundedBand, last_event_step, tail_bands, tail_step
from mitld_lp.product import default_max_memory, estimate_size
from mitld_lp.sensing.frontier import FrontierBuilder
from mitld_lp.sensing.horizon import collapse
from mitld_lp.sensing.info import (
    BYTES_PER_HYPOTHESIS,
    BYTES_PER_INFO_STATE,
    MAX_PRUNE_ATOMS,
    NEVER,
    NOT_YET,
    WEIGHT_TOL,
    Belief,
    Ends,
    InfoSize,
    InfoState,
    Obs,
    Reaches,
    info_size,
)
from mitld_lp.sensing.rows import small_pages
from mitld_lp.sensing.sensors import Sensor
from mitld_lp.worlds.game import Game

log = logging.getLogger(__name__)

# the records and constants live in mitld_lp.sensing.info, re-exported here for callers
__all__ = ["InfoState", "Belief", "InfoSize", "info_size", "belief_product", "sensed_sta",
           "WEIGHT_TOL", "Ends", "Reaches", "Obs", "NOT_YET", "NEVER", "MAX_PRUNE_ATOMS",
           "BYTES_PER_INFO_STATE", "BYTES_PER_HYPOTHESIS"]


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
    event's tail is both cuts' mass (``report_tail``; under a band, at nature's highest
    hazards).  A band of tables of masses is cut at its last step
    (:func:`~mitld_lp.distributions.band.last_event_step`), past which no law of it has
    the event: only the sensor's cut is left, whatever never masses its laws keep.  A
    band that no truncation serves keeps a :class:`TailClock` (:func:`_tail`; an
    unsensed event's, :func:`_seen_tail`, exact at its middle law where it can be)."""
    fixed = dict(truncation or {})
    auto = [a for a in sorted(laws) if a not in fixed and (
        a in sensed or not clock_reduction or laws[a].constant_hazard_from is None)]
    share = epsilon / len(auto) if auto else epsilon
    points, cuts, tails = {}, {}, {}
    for a in auto:
        nu = float(laws[a].never) if a in sensed else 0.0
        d = sensors[a].detect if sensors is not None and a in sensors else 0.0
        half = share / 2 if nu > 0.0 and 0.0 < d < 1.0 else share
        eps = min(nu + half, 1.0) if nu > 0.0 else share
        # a band of tables of masses: cut at its last step, past which no law of it has
        # the event (whatever never masses they keep): nothing cut there
        last = last_event_step(laws[a]) if nu > 0.0 else None
        # a band that may never happen whose hazard may stay positive: its laws' chances
        # of "never" once the event is pending differ, so no cut is sound (not even at
        # the middle law's chance); nor is one where the band has no truncation point
        unbounded = laws[a].is_ambiguous and nu > 0.0 and last is None
        if not unbounded:
            try:
                T = last if last is not None else laws[a].truncation_point(eps)
            except UnboundedBand:
                unbounded = True
        if unbounded and a not in sensed:  # fully seen: the middle law's clock, exact
            T, tails[a] = _seen_tail(laws[a], share, clock_reduction)
            if T is None:  # its middle law's hazard constant from a step: no cut
                continue
        elif unbounded:  # the middle law's cut, the band's tail bounded
            T, tails[a] = _tail(laws[a], eps, share)
        points[a] = max(T, 1) if nu > 0.0 else T
        if nu > 0.0 and 0.0 < d < 1.0:
            cuts[a] = max(2, math.ceil(math.log(half) / math.log1p(-d)))
    for a in fixed:  # a fixed point of a sensed event that may never happen
        if a in sensed and float(laws[a].never) > 0.0:
            d = sensors[a].detect if sensors is not None and a in sensors else 0.0
            if 0.0 < d < 1.0:
                cuts[a] = max(2, math.ceil(math.log(share / 2) / math.log1p(-d)))
    sta = make_sta(dta, {**laws, **tails}, epsilon, clock_reduction=clock_reduction,
                   truncation={**fixed, **points})
    clocks = dict(sta.clocks)
    for a in sensed:
        c = clocks[a]
        if float(c.distribution.never) > 0.0 and c.truncation is not None:
            R = cuts.get(a)
            d = sensors[a].detect if sensors is not None and a in sensors else 0.0
            reach = 1.0 - float(c.distribution.survival(c.truncation))  # P(K <= T)
            if c.distribution.is_ambiguous:  # the most nature's hazards give it
                hi = c.distribution.hazard_band(np.arange(1, c.truncation + 1))[1]
                reach = 1.0 - float(np.prod(1.0 - np.asarray(hi, dtype=float)))
            clocks[a] = replace(c, keeps_never=True, report_limit=R,
                                report_tail=0.0 if R is None else reach * (1.0 - d) ** R)
    for a in tails:  # what the information states cut is the middle law's
        clocks[a] = TailClock(**{f.name: getattr(clocks[a], f.name) for f in fields(EventClock)})
    return STA(dta, clocks)


@dataclass(frozen=True, slots=True)
class TailClock(EventClock):
    """The clock of a band that no truncation serves (:func:`sensed_sta`; a sensed
    event's or one seen when it happens): its information states are its middle law's,
    so what their cut takes (``tail``) is that law's ``P(K > T)`` (``P(T < K < inf)``
    where it keeps "never") and the sensor's cut, nothing where it has no cut;
    the controller's chain cuts nothing
    (:func:`mitld_lp.running.sensed_band_chain.tail_sta`)."""

    @property
    def tail(self) -> float:
        if self.truncation is None:
            return 0.0
        law = self.distribution.nominal  # type: ignore[attr-defined]
        cut = float(law.survival(self.truncation))
        if self.keeps_never:
            cut = max(cut - float(law.never), 0.0)
        return cut + self.report_tail


def _tail(band: Any, eps: float, share: float) -> tuple[int, FirstOccurrence]:
    """The truncation point of a sensed band that no truncation serves (its laws' never
    masses differ and its hazard may stay positive for ever) and the law its clock
    keeps: the point is its middle law's alone at ``eps`` (the information states are
    that law's, which is fine alone, even one that may never happen); the law is the
    band with its hazards past a step ``K >= T``
    (:func:`~mitld_lp.distributions.band.tail_step` at ``share``) replaced by the outer
    constant interval, which holds every later one
    (:func:`~mitld_lp.distributions.band.tail_bands`), the middle law kept as its
    nominal.  The controller's interval chain draws the true event from it, nothing
    truncated (:func:`mitld_lp.running.sensed_band_chain.tail_sta`)."""
    T = band.nominal.truncation_point(eps)
    return T, _outer_clock(band, T, max(T, tail_step(band, share), 1))


def _outer_clock(band: Any, T: int | None, K: int) -> FirstOccurrence:
    """The law a tail band's clock keeps: ``band`` with its hazards past ``K`` replaced
    by the outer constant interval (:func:`~mitld_lp.distributions.band.tail_bands`),
    its middle law kept as the nominal (cut at ``T``, or exact where ``T`` is None)."""
    outer = tail_bands(band, K)[0]
    log.info("%s: no truncation point serves the band (its laws' never masses differ and "
             "its hazard may stay positive for ever): the information states are its "
             "middle law's%s; past step %d the controller's chain lets nature pick the "
             "hazard in [%.6g, %.6g] at every step", band.label,
             "" if T is None else f", cut at step {T}", K, outer.lo, outer.hi)
    return replace(outer, nominal=band.nominal)


def _seen_tail(band: Any, share: float, clock_reduction: bool
               ) -> tuple[int | None, FirstOccurrence]:
    """:func:`_tail` for an unsensed event (seen when it happens): the information
    states are its middle law's, exact where that law's hazard is constant from a step
    (no point: ``None``; the clock runs to the band's step ``K``, past every law's
    change), else cut at its truncation point at ``share``.  Raises
    :class:`UnboundedBand` where that law may never happen and its hazard changes for
    ever (no cut of it is sound, none is exact) or where the clock is not reduced."""
    law = band.nominal
    c0 = law.constant_hazard_from if clock_reduction else None
    if c0 is None and law.never > 0.0:
        raise UnboundedBand(
            band.label, f"the band's middle law {law.label} may never happen and its hazard "
            "is not constant from any step" + ("" if clock_reduction else
                                              " (the clock is not reduced)") +
            ": no information states of it serve a band that no truncation serves "
            "on an event no sensor reports (docs/robust.md)")
    T = None if c0 is not None else law.truncation_point(share)
    K = max(T or 1, tail_step(band, share), 1 if c0 is None else c0 - 1)
    return T, _outer_clock(band, T, K)


def belief_product(game: Game[Any], dta: DTA, laws: Mapping[str, FirstOccurrence],
                   sensors: Mapping[str, Sensor], epsilon: float, *,
                   clock_reduction: bool = True, truncation: Mapping[str, int] | None = None,
                   max_states: int, max_memory: int | None = None,
                   progress: bool | None = None, late_reports: bool = True,
                   ends: Ends | None = None, name: str | None = None,
                   merge: bool = True) -> Belief:
    """The reachable information-state MDP (module docs) of a task's automaton ``dta``
    in ``game``, the events of ``sensors`` (missed detections, and false alarms with
    laws that surely happen) hidden.

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
    every record it returns is an absorbing state of the MDP).  The budgets are also
    checked at the end of each level of the build from an estimate of the size it will
    reach (:mod:`mitld_lp.sensing.growth`), which stops a product that will not fit
    seconds in, its message naming the model (``name``) and the sensed events.
    ``merge``: information states whose futures are identical are one state (a sensed
    event's times shifted to a canonical place where only their differences matter:
    :mod:`mitld_lp.sensing.merge`; the same optimum); False builds them apart."""
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
            sta.clocks[a].keeps_never or sensors[a].false_alarm > 0.0 for a in sensed):
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
    with small_pages():  # rows.py: the levels' rows in small pages
        builder = FrontierBuilder(game, dta, sta, sensed, used, max_states, memory, size,
                                  ends, name, merge)
        belief = builder.build(progress)
    builder.release()
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
