"""The controlled chain of a controller that acts on sensor reports (the ``sensed``
route, :mod:`mitld_lp.sensing`), for anyone to re-check with Storm
(``P=? [F "accept"]``).

A state of the chain is what the world is and what the robot knows of it:

* the *truth*: the world state, the task's automaton state on the true events (the
  sensed ones included, when they really happen), the events still pending, the clock,
  and for each sensed event that has happened and is not reported yet the steps until
  its report can come (``unreported={b1:0}``: it can come next step; a sensor reports an
  event once);
* the controller's *memory*: what the robot has observed, its information state (the
  controller's own value: a state number of its tables, or ``target`` / ``sink`` /
  ``truncated`` once every hypothesis it keeps is decided).

It is built from the dynamics, not from the information-state product: one step lets
every pending event happen by its hazard at the true clock, each sensed event's sensor
report it (with probability ``detect`` once its ``delay`` has passed; a sensed event
that may never happen, still pending at its truncation point, never happens with its
conditional probability, else it is truncated), the world move by
the controller's action, and the automaton read the new state's propositions and the
true events; the controller's memory then follows the *observation* (the world state,
the events without a sensor, the sensors' reports) through the controller's own plan
(``follow``), and its next action is the plan's ``decision`` there -- the tables the
robot runs (a synthesis's controller or one loaded from its file), never the synthesis's
policy vector.  So the chain re-checks the controller and the information-state
construction it was made from.

Labels: ``init``; ``accept`` where the true automaton has accepted, and for a task with a
safety part also on the bottom strongly connected components of the chain whose every
state's true automaton state is persistent (a run reaching one stays in safe states for
ever: the task holds); ``reject`` where it
has rejected, or where the controller stops with the task undecided (every hypothesis
it keeps is decided: the true run's task can no longer be won); ``persistent`` where the
true automaton's state is safe or accepting (a task with a safety part is satisfied by
the runs that stay in such states from some step on); ``truncated`` where an
event came later than its truncation point (counted as failure, as ``lower`` counts
it); ``beyond`` on a state whose memory met an observation the controller's model gives
probability 0 (none is expected: its presence says the controller and the world
disagree); and each world proposition that holds (``world_<name>`` for a proposition
named like a label).  ``P=? [F "accept"]`` is the controller's probability of
satisfying the task: inside the synthesis's certified bracket, at least ``lower``.

A randomised controller over information states (constraints or ``then``, the
``sensed-constrained`` route) has its choice mixed into the rows: *stay* with its
probability, else each action by its weight.  Its true run follows the joint automaton
of the task and the constraints' formulas, whose ends (a decided run, a stop, a stay)
and labels (``c<i>``, ``done``, the reward ``steps``) are
:mod:`mitld_lp.running.sensed_joint`'s.
"""

from __future__ import annotations

from collections.abc import Hashable, Mapping
from typing import Any

import numpy as np
import scipy.sparse as sp

from mitld_lp.automata.dta import DTA, SAFE
from mitld_lp.automata.sta import STA
from mitld_lp.controllers.format import UNDECIDED
from mitld_lp.controllers.kinds import ControllerLike
from mitld_lp.controllers.tables import BEYOND
from mitld_lp.distributions.band import last_event_step
from mitld_lp.running.chain_model import Chain, prop_labels, rows_matrix
from mitld_lp.sensing.sensors import Sensor
from mitld_lp.worlds.game import Game
from mitld_lp.worlds.names import state_fields, state_values, valuation_text

__all__ = ["TaskEnds", "Unfolding", "is_sensed", "never_share", "plan_of", "sensed_chain",
           "sensed_chain_of"]


_REPORTED = -1
"""A sensed event's report status once it is reported (or before it happens)."""

_ENDS = ("accept", "reject", "truncated")


def is_sensed(result: Any) -> bool:
    """Whether ``result`` answers a problem with sensors that miss events (the one place
    this package's running and export code asks a result for it: its route's part says
    its controller acts on observations)."""
    part = getattr(result, "part", None)
    return bool(getattr(part, "observation_based", False))


def sensed_chain_of(result: Any, controller: ControllerLike | None = None, *,
                    costs: Mapping[str, float] | None = None) -> Chain:
    """The controlled chain (module docs) of a ``sensed`` result under its controller,
    or under ``controller`` (one of the same model, such as the result's controller
    saved and loaded again); ``costs``: the actions' costs the synthesis was given
    (the reward ``cost`` of a ``sensed-constrained`` chain; default the model's)."""
    c = controller if controller is not None else result.controller
    if c is None:
        raise ValueError(f"no controller to export: the synthesis is {result.status}")
    if getattr(result.part, "randomised", False):  # sensed-constrained: the joint automaton
        from mitld_lp.running.sensed_joint import joint_ends

        ends = joint_ends(result.joint, [v.constraint for v in result.constraints],
                          result.belief, result.model.costs if costs is None else costs)
        return sensed_chain(result.model.game, result.joint.dta, result.sta, result.sensors,
                            c, ends=ends)
    return sensed_chain(result.model.game, result.dta, result.sta, result.sensors, c)


def sensed_chain(game: Game[Any], dta: DTA, sta: STA, sensors: Mapping[str, Sensor],
                 controller: ControllerLike, *, ends: Any = None) -> Chain:
    """The chain of ``controller`` (a controller that acts on sensor reports) in
    ``game``, the task's automaton ``dta``, the events' clocks ``sta`` (the sensed events
    truncated, as the synthesis did) and the ``sensors`` that miss events.  ``ends``:
    for a joint automaton (:mod:`mitld_lp.running.sensed_joint`), its states' ends and
    labels; None: the task's accepting and rejecting states."""
    plan, sensed = plan_of(controller, sensors)
    return Unfolding(game, dta, sta, sensors, sensed, plan, ends or TaskEnds(dta)).chain()


def plan_of(controller: ControllerLike, sensors: Mapping[str, Sensor]
             ) -> tuple[Any, tuple[str, ...]]:
    """The controller's plan and the sensed events, refused unless it acts on the
    reports of exactly these sensors."""
    plan: Any = controller.plan
    sensed = tuple(sorted(sensors))
    if frozenset(sensed) != getattr(plan, "sensed", None):
        raise ValueError(f"the controller does not act on the reports of {', '.join(sensed)} "
                         "(it is not a controller of this model's sensors)")
    return plan, sensed


class TaskEnds:
    """The ends of a task's own automaton: ``accept`` and ``reject`` (no label on the
    states before).  :class:`mitld_lp.running.sensed_joint.JointEnds` is its joint
    automaton's twin."""

    def __init__(self, dta: DTA) -> None:
        self.dta = dta

    def end(self, q: int) -> str | None:
        """The absorbing state the run enters in automaton state ``q`` (None: none)."""
        return ("accept" if q == self.dta.accepting else
                "reject" if q == self.dta.rejecting else None)

    def stopped(self, q: int) -> str:
        """The absorbing state of a run whose controller stops (or stays for ever) in
        ``q``: its verdicts, the undecided counting as not satisfied."""
        return "accept" if q == self.dta.accepting else "reject"

    def stayed(self, q: int, memory: Any) -> str:
        """The absorbing state of a run whose controller draws *stay* (only the
        randomised controller of :mod:`mitld_lp.running.sensed_joint` does)."""
        return self.stopped(q)

    def labels(self, q: int) -> frozenset[str]:
        return frozenset()

    def end_labels(self, name: str) -> frozenset[str]:
        return frozenset({name})

    def rewards(self, states: list[tuple[int, frozenset[str], Any] | None],
                mixes: Mapping[int, list[tuple[str, float]]]
                ) -> tuple[tuple[str, np.ndarray], ...]:
        """The chain's reward models from its states (``(automaton state, events
        pending, memory)``, None for an end) and the controller's actions in each (``mixes``:
        ``(action, probability)``); the task's own chain has none."""
        return ()


class Unfolding:
    """The reachable states of the chain, one step at a time (module docs).  A node is
    ``(world, q, pending, clock, unreported, memory)``; ``unreported`` one value per
    sensed event: :data:`_REPORTED`, or the steps until its report can come (0: it can
    come in the next step)."""

    def __init__(self, game: Game[Any], dta: DTA, sta: STA, sensors: Mapping[str, Sensor],
                 sensed: tuple[str, ...], plan: Any, ends: Any) -> None:
        self.game, self.dta, self.sta, self.plan, self.ends = game, dta, sta, plan, ends
        self.sensors, self.sensed = sensors, sensed
        self.index: dict[Hashable, int] = {}
        self.mixes: dict[int, list[tuple[str, float]]] = {}  # the actions taken per state
        self.order: list[Hashable] = []
        self.props: dict[Hashable, frozenset[str]] = {}

    def number(self, node: Hashable) -> int:
        at = self.index.get(node)
        if at is None:
            at = self.index[node] = len(self.order)
            self.order.append(node)
        return at

    def label(self, world: Hashable) -> frozenset[str]:
        props = self.props.get(world)
        if props is None:
            props = self.props[world] = frozenset(self.game.propositions(world))
        return props

    def enter(self, q: int, node: tuple[Any, ...]) -> int:
        """The chain state of ``node``, or the end its automaton state ``q`` decides."""
        end = self.ends.end(q)
        return self.number(node if end is None else end)

    def start(self) -> None:
        """Number the initial state."""
        g0 = self.game.initial
        q0 = self.dta.step(self.dta.initial, self.label(g0))
        unreported = (_REPORTED,) * len(self.sensed)
        self.enter(q0, (g0, q0, frozenset(self.sta.events), 0, unreported,
                        self.plan.start(g0)))

    def chain(self) -> Chain:
        self.start()
        rows: list[dict[int, float]] = []
        while len(rows) < len(self.order):
            node = self.order[len(rows)]
            if isinstance(node, str):
                rows.append({len(rows): 1.0})
            else:
                rows.append(self.step(node))
        return self.record(rows)

    def step(self, node: tuple[Any, ...]) -> dict[int, float]:
        g, q, pending, clock, unreported, memory = node
        plan = self.plan
        row: dict[int, float] = {}
        if UNDECIDED not in plan.verdicts_at(memory):  # the controller stops
            return {self.number(self.ends.stopped(q)): 1.0}
        d = plan.decision(g, memory)
        if d.lost:
            return {self.number(self.ends.stopped(q)): 1.0}
        if d.weights is None or not d.actions:
            branches = [(d.actions[0] if d.actions else plan.fallback(g), 1.0)]
        else:  # randomised: stay for ever (an end by the true run's verdicts), or an action
            if d.stay > 0.0:
                row[self.number(self.ends.stayed(q, memory))] = d.stay
            w = np.asarray(d.weights, dtype=float)
            branches = [(a, (1.0 - d.stay) * float(x)) for a, x in
                        zip(d.actions, w / w.sum(), strict=True) if x > 0.0]
        self.mixes[self.index[node]] = branches
        for action, p_action in branches:
            self.moves(node, action, p_action, row)
        return row

    def moves(self, node: tuple[Any, ...], action: str, p_action: float,
              row: dict[int, float]) -> None:
        """Add to ``row`` the successors of ``node`` when the controller takes
        ``action`` (with probability ``p_action``)."""
        g, q, pending, clock, unreported, memory = node
        plan = self.plan
        for occurred, left, p_events in self.outcomes(pending, clock):
            after = self.sta.advance(left, clock)
            if after.truncated:
                k = self.number("truncated")
                row[k] = row.get(k, 0.0) + p_action * p_events
                continue
            for reports, unreported2, p_reports in self.reports(occurred, unreported):
                seen = (occurred - frozenset(self.sensed)) | reports
                for g2, p_world in self.game.successors(g, action, occurred):
                    p = p_action * p_events * p_reports * p_world
                    if p <= 0.0:
                        continue
                    q2 = self.dta.step(q, self.label(g2) | occurred)
                    memory2, _ = plan.follow(memory, g2, seen, action)
                    k = self.enter(q2, (g2, q2, left, after.clock, unreported2, memory2))
                    row[k] = row.get(k, 0.0) + p

    def events(self, pending: frozenset[str], clock: int
               ) -> list[tuple[frozenset[str], float]]:
        """The events of the next step, each with its probability (their hazards at the
        true clock, independent)."""
        out: list[tuple[frozenset[str], float]] = [(frozenset(), 1.0)]
        for a in sorted(pending):
            h = self.sta.clocks[a].hazard(clock)
            out = [(e | {a}, p * h) for e, p in out] + [(e, p * (1.0 - h)) for e, p in out]
        return [(e, p) for e, p in out if p > 0.0]

    def outcomes(self, pending: frozenset[str], clock: int
                 ) -> list[tuple[frozenset[str], frozenset[str], float]]:
        """``(events, still pending, probability)`` of the next step: a sensed event that
        may never happen and reaches its truncation point still pending never happens
        with probability ``never / P(K > T)`` (it leaves ``pending``), else it comes
        later, past the point (the truncation); a band's event past the band's last step
        (:func:`~mitld_lp.distributions.band.last_event_step`) never happens, under
        every law of the band."""
        out = []
        for occurred, p in self.events(pending, clock):
            branches = [(pending - occurred, p)]
            for a in sorted(pending - occurred):
                never = never_share(self.sta.clocks[a], clock)
                if never is None:
                    continue
                branches = [(b - {a}, q * never) for b, q in branches] + [
                    (b, q * (1.0 - never)) for b, q in branches]
            out += [(occurred, b, q) for b, q in branches if q > 0.0]
        return out

    def reports(self, occurred: frozenset[str], unreported: tuple[int, ...]
                ) -> list[tuple[frozenset[str], tuple[int, ...], float]]:
        """The sensors' reports of the next step: ``(reported, unreported after,
        probability)``."""
        out: list[tuple[frozenset[str], tuple[int, ...], float]] = [(frozenset(), (), 1.0)]
        for a, wait in zip(self.sensed, unreported, strict=True):
            sensor = self.sensors[a]
            if sensor.false_alarm > 0.0:  # a report or none at every step
                out = _alarm_reports(out, a, sensor, a in occurred, wait)
                continue
            if a in occurred:
                due = sensor.delay  # the event happens now: its report from step + delay
            elif wait == _REPORTED:  # not happened yet, or reported already
                out = [(r, (*u, _REPORTED), p) for r, u, p in out]
                continue
            else:
                due = wait - 1
            if due > 0:
                out = [(r, (*u, due), p) for r, u, p in out]
                continue
            d = sensor.detect
            out = ([(r | {a}, (*u, _REPORTED), p * d) for r, u, p in out] +
                   [(r, (*u, 0), p * (1.0 - d)) for r, u, p in out])
        return [(r, u, p) for r, u, p in out if p > 0.0]

    def record(self, rows: list[dict[int, float]]) -> Chain:
        n = len(rows)
        matrix = rows_matrix(rows)
        props = prop_labels()
        fields = ("q", "pending", "clock", "unreported", "memory")
        world_fields = state_fields(self.game)
        worlds: dict[Hashable, tuple[frozenset[str], str]] = {}  # labels, valuation text
        labels: list[frozenset[str]] = []
        valuations: list[str] = []
        origin = np.full(n, -1, dtype=np.int64)
        for k, node in enumerate(self.order):
            if isinstance(node, str):
                labels.append(self.ends.end_labels(node))
                valuations.append(node)
                continue
            g, q, pending, clock, unreported, memory = node
            world = worlds.get(g)
            if world is None:
                world = worlds[g] = (frozenset(props(p) for p in self.label(g)),
                                     valuation_text(world_fields, state_values(self.game, g)))
            here = set(world[0]) | self.ends.labels(q)
            if q in self.dta.persistent:
                here.add("persistent")
            if memory == BEYOND:
                here.add("beyond")
            if isinstance(memory, (int, np.integer)) and memory >= 0:
                origin[k] = memory
            labels.append(frozenset(here))
            waiting = ",".join(f"{a}:{w}" for a, w in zip(self.sensed, unreported, strict=True)
                               if w != _REPORTED)
            valuations.append(world[1] + " & " + valuation_text(fields, (
                q, "{" + ",".join(sorted(pending)) + "}", clock, "{" + waiting + "}",
                "beyond" if memory == BEYOND else str(memory))))
        if SAFE in self.dta.kinds:
            for k in _kept_for_ever(matrix, self.order, self.dta.persistent):
                labels[k] = labels[k] | {"accept"}
        none = np.zeros(n, dtype=bool)
        rewards = self.ends.rewards([None if isinstance(x, str) else (x[1], x[2], x[5])
                                     for x in self.order], self.mixes)
        return Chain(matrix, tuple(labels), tuple(valuations), origin, none, none.copy(),
                     rewards)


def never_share(c: Any, clock: int) -> float | None:
    """The probability that the event of the clock ``c``, a sensed event that may never
    happen, still pending when the step from ``clock`` reaches its truncation point,
    never happens: ``never / P(K > T)``, or 1 past a band's last step
    (:meth:`Unfolding.outcomes`); None where the step does not reach that point or the
    event keeps no such hypothesis."""
    if not c.keeps_never or c.truncation is None or clock + 1 < c.truncation:
        return None
    last = last_event_step(c.distribution)
    return 1.0 if last is not None and last <= c.truncation else min(
        float(c.distribution.never) / float(c.distribution.survival(c.truncation)), 1.0)


def _kept_for_ever(matrix: Any, order: list[Hashable], persistent: frozenset[int]
                   ) -> list[int]:
    """The chain states of the bottom strongly connected components whose every state's
    true automaton state is persistent: a run that reaches one stays in it, and in
    persistent states, for ever (with probability 1), so its task holds."""
    from scipy.sparse.csgraph import connected_components

    n = len(order)
    _, comp = connected_components(matrix, directed=True, connection="strong")
    rows = sp.csr_array(matrix)
    src = np.repeat(np.arange(n), np.diff(rows.indptr))
    leaves = comp[src] != comp[rows.indices]
    bottom = np.ones(comp.max() + 1 if n else 0, dtype=bool)
    bottom[comp[src[leaves]]] = False
    good = bottom.copy()
    for k, node in enumerate(order):
        if isinstance(node, str) or node[1] not in persistent:
            good[comp[k]] = False
    return [k for k in range(n) if good[comp[k]]]


def _alarm_reports(out: list[tuple[frozenset[str], tuple[int, ...], float]], a: str,
                   sensor: Sensor, occurs: bool, wait: int
                   ) -> list[tuple[frozenset[str], tuple[int, ...], float]]:
    """:meth:`Unfolding.reports` for one sensor with false alarms: it reports with
    probability ``false_alarm`` before the event's report is due (``wait``:
    :data:`_REPORTED` while the event has not happened, else the steps until it is due)
    and ``detect`` from then on, at every step; ``wait`` stays 0 once due."""
    if occurs:
        wait = sensor.delay
    elif wait > 0:
        wait -= 1
    p = sensor.detect if wait == 0 else sensor.false_alarm
    return [x for x in ([(r | {a}, (*u, wait), q * p) for r, u, q in out] +
                        [(r, (*u, wait), q * (1.0 - p)) for r, u, q in out]) if x[2] > 0.0]
