"""The information-state product when the world's moves react to a sensed event (the
world's ``event_names`` hold an event a sensor reports:
:func:`~mitld_lp.sensing.sensors.reacting_events`).

:mod:`mitld_lp.sensing.belief` assumes the world ignores the sensed events: then a
hypothesis's automaton state is a function of the observed path and its posterior a
function of the information state's key, which the fast frontier builder
(:mod:`mitld_lp.sensing.frontier`) relies on.  When the world reacts, the robot's
observation of the world's state tells it about the event: the world moves by
``P(s' | s, act, E)`` with ``E`` the step's events *including the sensed ones that
happen in it under the hypothesis*, so each hypothesis's posterior is multiplied by its
likelihood of the observed world transition, and a hypothesis under which the observed
transition is impossible is dropped.  The automaton state under a hypothesis is still a
function of the observations (the observed world state and the hypothesis's events), so
an information state has the same parts (:class:`~mitld_lp.sensing.info.InfoState`),
but its posterior is no longer a function of its hypothesis set: two observation
histories may leave the same hypotheses with different weights, and so different
futures.

Here an information state is identified by its key *and its posterior, exactly*: every
probability of a step (the events' hazards, the sensors' reports, the world's moves, as
the step rules :mod:`mitld_lp.sensing.rules` and the world give them in floating point)
is read as the exact rational its float stands for (python-flint's ``fmpq`` where the
``exact`` extra is installed, else :class:`fractions.Fraction`: the same values, FLINT's
faster), the posterior is computed and normalised in rationals, and two states are one
only when their hypotheses and their rational weights are equal.  No float rounding decides an
identity: two histories whose posteriors differ only in the floats' last bits stay two
states (the same futures, so the same optimum; only the product is larger).  The MDP's
rows and the states' ``weights`` are the rationals rounded to floats once.

A sensor with false alarms (``false_alarm > 0``, a law that surely happens; one that may
never happen is built blind and bracketed: :mod:`mitld_lp.routes.sensed_reacting`)
reports or not at every step, with probability ``false_alarm`` before a hypothesis's
step ``k + delay`` and ``detect`` from it on (:meth:`~mitld_lp.sensing.rules.StepRules.
sensed_branches`): every step's report or silence multiplies each hypothesis's weight
by its likelihood, and the event is never kept as reported.  The exact posterior holds
all the reports tell, so no count of reports is kept (the counts of
:class:`~mitld_lp.sensing.merge.Counts` are dropped from the hypotheses).  The states
stay finitely many: the clock is kept while some hypothesis's report is not due
(:meth:`~mitld_lp.sensing.rules.StepRules.clock_key`), and once every hypothesis left
has happened and is due each step multiplies every weight by the same ``detect`` or
``1 - detect`` (and the world's move, no sensed event happening any more, is alike
under all), so the normalised rationals are equal and the state is met again.  The levels of the
build then shrink from the clock's last step on (a camera with ``detect = 0.6,
false_alarm = 0.3`` on tests/test_sensing_reacting_fa.py's world, the bus uniform over 8
steps: levels 6,734, 27,118, 45,149, 27,873, then none, 109,072 states), so the estimate
that stops a build early (:mod:`mitld_lp.sensing.growth`) does not carry a steady growth
past that step: carried two levels further it said 2.2 million states at level 6, 20
times the truth; not carried, 143,131 (over 7 steps: 35,937 against 29,311 built).

The construction is breadth first, one state at a time, under the budgets of
:class:`~mitld_lp.sensing.growth.Growth` (the exact check before each state is stored,
the estimate at each level's end).  Every sensor is built as given (no late-report
collapse of :mod:`mitld_lp.sensing.horizon`) and no states are merged by shifting their
times (:mod:`mitld_lp.sensing.merge`): both arguments read the posterior as a function
of the key.  A world that ignores its events never comes here: the frontier builder
builds its product, the same one with fewer states.
"""

from __future__ import annotations

import logging
from collections.abc import Hashable, Mapping
from fractions import Fraction
from typing import Any

try:  # FLINT's rationals (the exact extra): the same values as Fraction's, faster
    from flint import fmpq as _rational
except ImportError:  # pragma: no cover - the standard library's
    _rational = Fraction

import numpy as np
import scipy.sparse as sp

from mitld_lp.automata.dta import DTA
from mitld_lp.distributions import FirstOccurrence
from mitld_lp.mdp import ABSORB, MDP
from mitld_lp.product import Absorbing, default_max_memory
from mitld_lp.sensing.belief import sensed_sta
from mitld_lp.sensing.growth import Growth
from mitld_lp.sensing.info import (
    BYTES_PER_HYPOTHESIS,
    BYTES_PER_INFO_STATE,
    NOT_YET,
    Belief,
    Ends,
    InfoState,
    Obs,
    info_size,
)
from mitld_lp.sensing.rules import StepRules
from mitld_lp.sensing.sensors import Sensor, reacting_events
from mitld_lp.util.progress import bar as progress_bar
from mitld_lp.worlds.game import Game

__all__ = ["reacting_events", "reacting_product", "ReactingBuilder"]

log = logging.getLogger(__name__)

Rational = Any
"""An exact rational (``flint.fmpq`` or :class:`fractions.Fraction`)."""

Hyp = tuple[tuple[int, ...], int]  # (times, automaton state)
ZERO, ONE = _rational(0), _rational(1)


def reacting_product(game: Game[Any], dta: DTA, laws: Mapping[str, FirstOccurrence],
                     sensors: Mapping[str, Sensor], epsilon: float, *,
                     clock_reduction: bool = True, truncation: Mapping[str, int] | None = None,
                     max_states: int, max_memory: int | None = None,
                     progress: bool | None = None, ends: Ends | None = None,
                     name: str | None = None) -> Belief:
    """The reachable information-state MDP (module docs) of a task's automaton ``dta``
    in ``game`` whose moves may react to the events of ``sensors`` (missed detections,
    and false alarms with laws that surely happen), those events hidden; the same record as
    :func:`mitld_lp.sensing.belief.belief_product`, with the same clocks
    (:func:`~mitld_lp.sensing.belief.sensed_sta`) and budgets: raises
    :class:`~mitld_lp.product.ProductTooLarge` before a state past ``max_states`` or
    ``max_memory`` is stored, or at a level's end where the estimate of the final size
    passes either (:mod:`mitld_lp.sensing.growth`).  ``progress``: a bar of the states
    built; ``ends``: where a hypothesis ends (:data:`~mitld_lp.sensing.info.Ends`)."""
    sensed = tuple(sorted(sensors))
    sta = sensed_sta(dta, laws, sensed, epsilon, clock_reduction=clock_reduction,
                     truncation=truncation, sensors=sensors)
    memory = default_max_memory() if max_memory is None else max_memory
    size = info_size(game, sta, sensors)
    points = sta.truncation_points
    log.info("information-state product of a world that reacts to %s (its moves depend on "
             "when the sensed events happen): each state keeps its exact posterior; %s; "
             "sensed events truncated at %s; it stops past %s states or %.1f GiB",
             ", ".join(sorted(reacting_events(game, sensed))) or "no sensed event", size,
             ", ".join(f"{a} step {points[a]}" for a in sensed), f"{max_states:,}",
             memory / 2**30)
    # with false alarms the levels shrink from the clock's last step on (every hypothesis
    # then due: the posterior stops changing), so a steady growth is not carried past it
    # (module docs)
    alarms = any(s.false_alarm > 0.0 for s in sensors.values())
    growth = Growth(max_states=max_states, max_memory=memory, size=size, sensors=sensors,
                    points=points, name=name, **({"past": 0} if alarms else {}))
    builder = ReactingBuilder(game, dta, sta, sensed, sensors, growth, ends)
    return builder.build(progress)


class ReactingBuilder(StepRules):
    """The breadth-first construction (module docs) from the step rules, each state
    identified by its key and its exact posterior; ``growth`` holds the budgets."""

    def __init__(self, game: Game[Any], dta: DTA, sta: Any, sensed: tuple[str, ...],
                 sensors: Mapping[str, Sensor], growth: Growth,
                 ends: Ends | None = None) -> None:
        super().__init__(game, dta, sta, sensed, sensors, ends)
        self.growth = growth
        self.states: list[InfoState | Hashable] = []
        self.exact: list[tuple[Rational, ...]] = []  # each state's exact posterior
        # the information states by their key and float weights: the candidates' exact
        # weights and indices (:meth:`info_state`); the absorbing records by themselves
        self.index: dict[Hashable, list[tuple[tuple[Rational, ...], int]]] = {}
        self.records: dict[Hashable, int] = {}
        self.bytes = self.hypotheses = 0
        self.choices: list[tuple[int, str | None, dict[int, Rational]]] = []
        self.moves: dict[tuple[int, str], dict[Obs, Any]] = {}
        self.rationals: dict[float, Rational] = {}
        self.world_cache: dict[tuple[Hashable, str, frozenset[str]],
                               tuple[tuple[Hashable, Rational], ...]] = {}
        # the sensors with false alarms: never kept as reported, and no report counts
        # kept (the exact posterior holds what they tell: module docs)
        self.alarmed = frozenset(sensed[i] for i in self.alarms)
        self.counts = (0,) * len(self.alarms)

    # ---------------------------------------------------------------- states

    def store(self, state: InfoState | Hashable, weights: tuple[Rational, ...] = ()) -> int:
        """Store a new state (after the budget's check) and return its index."""
        self.growth.check(len(self.states), self.bytes, 1, len(weights))
        self.states.append(state)
        self.exact.append(weights)
        self.bytes += BYTES_PER_INFO_STATE + BYTES_PER_HYPOTHESIS * len(weights)
        self.hypotheses += len(weights)
        return len(self.states) - 1

    def record(self, record: Hashable) -> int:
        """The index of an absorbing record (a verdict, the truncation)."""
        i = self.records.get(record)
        if i is None:
            i = self.records[record] = self.store(record)
        return i

    def info_state(self, world: Hashable, t: int, reported: frozenset[str],
                   pending: frozenset[str], mass: Mapping[Hyp, Rational]) -> int:
        """The index of the information state of these hypotheses with these masses
        (normalised here, exactly).  Its key with the weights as floats only picks the
        bucket of candidates (hashing a rational is slow); a candidate is this state
        when its rational weights are equal, never by the floats."""
        hyps = tuple(sorted(mass))
        total = sum(mass.values(), ZERO)
        weights = tuple(mass[h] / total for h in hyps)
        clock = self.clock_key(t, [times for times, _ in hyps], pending, reported)
        near = tuple(float(w) for w in weights)
        bucket = self.index.setdefault((world, clock, reported, pending, hyps, near), [])
        for exact, i in bucket:
            if exact == weights:
                return i
        i = self.store(InfoState(world, clock, reported, pending, hyps, near), weights)
        bucket.append((weights, i))
        return i

    def exact_of(self, p: float) -> Rational:
        """The exact rational a float stands for."""
        q = self.rationals.get(p)
        if q is None:
            q = self.rationals[p] = _rational(*float(p).as_integer_ratio())
        return q

    def world_moves(self, world: Hashable, act: str, events: frozenset[str]
                    ) -> tuple[tuple[Hashable, Rational], ...]:
        """The world's successors under the step's events (sensed ones included), each
        probability as the exact rational of its float."""
        key = (world, act, events)
        hit = self.world_cache.get(key)
        if hit is None:
            hit = self.world_cache[key] = tuple(
                (g2, self.exact_of(p)) for g2, p in self.game.successors(world, act, events)
                if p > 0.0)
        return hit

    # ---------------------------------------------------------------- one state

    def expand(self, i: int) -> None:
        """The choices of state ``i`` (an absorbing record: its loop), their rows and
        the controller's moves; new states stored."""
        s = self.states[i]
        if not isinstance(s, InfoState):
            self.choices.append((i, None, {i: ONE}))
            return
        for act in self.game.actions(s.world):
            row: dict[int, Rational] = {}
            groups: dict[Obs, dict[Hyp, Rational]] = {}
            ended: dict[Obs, set[Hashable]] = {}

            def add(j: int, m: Rational, row: dict[int, Rational] = row) -> None:
                row[j] = row.get(j, ZERO) + m

            n = len(self.sensed)
            for occurred, pu, crossed in self.unsensed_outcomes(s.pending, s.clock):
                if crossed:
                    add(self.record(Absorbing.TRUNCATED), self.exact_of(pu))
                    continue
                for (times, q), w in zip(s.hypotheses, self.exact[i], strict=True):
                    # six fields (rules.StepRules.sensed_branches says four); the report
                    # counts of false alarms not kept (module docs)
                    for times2, new, pc, cut, now, waiting in self.sensed_branches(  # pyright: ignore[reportAssignmentType]
                            times + self.counts, s.reported, s.clock):
                        times2 = times2[:n]
                        m = w * self.exact_of(pu) * self.exact_of(pc)
                        if cut:
                            add(self.record(Absorbing.TRUNCATED), m)
                            continue
                        # the world moves on every event of the step, the sensed ones
                        # this hypothesis makes happen included: its likelihood
                        for g2, pg in self.world_moves(s.world, act, occurred | now):
                            q2 = self.automaton(q, self.label(g2) | occurred | now)
                            end = self.end(q2, (s.pending - occurred) | waiting)
                            obs = (g2, occurred, new)
                            if end is not None:
                                add(self.record(end), m * pg)
                                ended.setdefault(obs, set()).add(end)
                            else:
                                group = groups.setdefault(obs, {})
                                group[(times2, q2)] = group.get((times2, q2), ZERO) \
                                    + m * pg
            table: dict[Obs, Any] = {}
            for obs, mass in groups.items():
                g2, occurred, new = obs
                j = self.info_state(g2, s.clock + 1, s.reported | (new - self.alarmed),
                                    s.pending - occurred, mass)
                add(j, sum(mass.values(), ZERO))
                table[obs] = j
            for obs, records in ended.items():
                if obs not in table:  # nothing undecided left with it: the verdict
                    table[obs] = next(iter(records)) if len(records) == 1 else \
                        Absorbing.TRUNCATED
            self.choices.append((i, act, row))
            self.moves[(i, act)] = table

    # ---------------------------------------------------------------- the MDP

    def build(self, progress: bool | None = None) -> Belief:
        game = self.game
        q0, first = self.initial_verdict()
        if first is not None:
            initial = self.record(first)
        else:
            hyp: Hyp = ((NOT_YET,) * len(self.sensed), q0)
            initial = self.info_state(game.initial, 0, frozenset(), self.unsensed,
                                      {hyp: ONE})
        self.growth.start(len(self.states))
        shown = progress_bar(progress, total=None, unit=" states",
                             desc="information states (a reacting world)", leave=False,
                             mininterval=0.5)
        head, level = 0, len(self.states)
        while head < len(self.states):
            self.expand(head)
            head += 1
            shown.update(1)
            if head == level:  # a level done: its growth judged before the next
                self.growth.level(len(self.states) - level, self.hypotheses, self.bytes)
                level = len(self.states)
        shown.close()
        return Belief(self.mdp(initial), self.sta, self.sensed, self.sensors, self.moves)

    def mdp(self, initial: int) -> MDP:
        """The MDP of the choices built, the actions numbered as the choices first show
        them, each row's rationals rounded to floats once."""
        n = len(self.states)
        names: dict[str, int] = {}
        acts, per_state = [], np.zeros(n + 1, np.int64)
        indptr, cols, vals = [0], [], []
        for owner, act, row in self.choices:
            per_state[owner + 1] += 1
            acts.append(ABSORB if act is None else names.setdefault(act, len(names)))
            cols += list(row)
            vals += [float(p) for p in row.values()]
            indptr.append(len(cols))
        matrix = sp.csr_array((np.asarray(vals, np.float64), np.asarray(cols, np.int32),
                               np.asarray(indptr, np.int64)), shape=(len(self.choices), n))
        kind = np.array([{Absorbing.TARGET: 1, Absorbing.SINK: 2, Absorbing.TRUNCATED: 3}
                         .get(s, 0) if isinstance(s, Absorbing) else 0 for s in self.states],
                        dtype=np.int8)
        log.info("information-state product (a reacting world): %s states, %s choices, "
                 "%s transitions", *(f"{x:,}" for x in (n, len(self.choices), matrix.nnz)))
        return MDP(matrix=matrix, row_groups=np.cumsum(per_state),
                   choice_actions=np.asarray(acts, np.int32), action_names=tuple(names),
                   initial=initial, target=kind == 1, sink=kind == 2, truncated=kind == 3,
                   states=tuple(self.states))
