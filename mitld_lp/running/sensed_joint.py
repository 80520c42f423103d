"""The ends and labels of the controlled chain of a sensed answer with constraints or
``then`` (the ``sensed-constrained`` route): the true run follows the joint automaton of
the task and the constraints' formulas (:mod:`mitld_lp.automata.joint`), and
:mod:`mitld_lp.running.sensed_chain` asks this module where a run ends and how a state
is labelled.

* A run whose true joint state has every component decided enters the absorbing state of
  its verdicts (``verdict(accepted,rejected)``); so does a run whose controller stops or
  draws *stay* (keeps to an end component of its information states for ever), with the
  true run's verdicts there, an undecided component counting as not satisfied -- the
  synthesis's accounting of a stay (:mod:`mitld_lp.routes.sensed_constrained`).  For a
  task with a safety part a stay in a keep state (:class:`Keeps`) is a *keep*: the
  controller plays that state's end component for ever, which keeps the true run's task
  exactly when its hypothesis is persistent there; the task accepted when the true run
  is persistent, the constraints as they are.
* Labels: ``accept`` where the task has accepted, ``c<i>`` where the formula of the
  ``i``-th constraint (``P(...)``, counted from 1 in the problem's order) has accepted,
  ``done`` on the absorbing states.  ``truncated`` (an event later than its truncation
  point) counts as the lower model counts it: the task failed, each ``<=`` constraint's
  formula satisfied (violated), each ``>=`` one's not.
* Rewards: ``steps`` (1 where the true task is undecided and can still be won) and
  ``cost`` (there, the expected cost of the controller's action), what ``E(steps)``
  and ``E(cost)`` count.

So ``P=? [F "accept"]`` is at least the answer's ``lower`` and ``P=? [F "c<i>"]`` at most
(``<=``) or at least (``>=``) the constraint's certified bound.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from mitld_lp.automata.dta import DTA, SAFE
from mitld_lp.automata.joint import ACCEPTED, REJECTED, UNDECIDED, Joint
from mitld_lp.sensing.belief import MAX_PRUNE_ATOMS, NOT_YET

__all__ = ["JointEnds", "joint_ends", "held", "TaskLive", "Keeps", "keeps_for", "winnable"]


class JointEnds:
    """Where a run of the joint automaton ends and its labels (module docs);
    ``names[i]``: the label of component ``i`` (the task's ``accept``), ``against``:
    the labels a truncated run carries."""

    def __init__(self, joint: Joint, names: Sequence[str], against: frozenset[str],
                 events: frozenset[str], costs: Mapping[str, float],
                 belief: Any = None) -> None:
        self.joint, self.names, self.events = joint, tuple(names), events
        self.belief = belief
        self.costs = costs
        self._task_live = TaskLive(joint.parts[0], events)
        self._kept: tuple[Keeps | None, np.ndarray | None] | None = None
        self._ends: dict[str, frozenset[str]] = {
            "truncated": frozenset({"truncated", "done"}) | against}

    def _where(self) -> tuple[Keeps | None, np.ndarray | None]:
        """The keep states and the winnable states of the information-state product
        (:func:`keeps_for`, :func:`winnable`; None without it)."""
        if self._kept is None:
            keeps = None if self.belief is None else keeps_for(self.belief, self.joint)
            self._kept = (keeps, None if self.belief is None else
                          winnable(self.belief, keeps))
        return self._kept

    def _named(self, verdicts: tuple[int, ...]) -> str:
        name = "verdict(" + ",".join("accepted" if v == ACCEPTED else "rejected"
                                     for v in verdicts) + ")"
        if name not in self._ends:
            self._ends[name] = frozenset(
                {"done", "accept" if verdicts[0] == ACCEPTED else "reject"}
                | {n for n, v in zip(self.names[1:], verdicts[1:], strict=True)
                   if v == ACCEPTED})
        return name

    def end(self, q: int) -> str | None:
        v = self.joint.verdicts[q]
        return None if UNDECIDED in v else self._named(v)

    def stopped(self, q: int) -> str:
        return self._named(tuple(v if v != UNDECIDED else REJECTED
                                 for v in self.joint.verdicts[q]))

    def stayed(self, q: int, memory: Any) -> str:
        """The end of a run whose controller draws *stay* in information state
        ``memory``: a *keep* where ``memory`` is a keep state (:class:`Keeps`): the task
        accepted if the true run is persistent, else :meth:`stopped`."""
        j = self.joint
        true_held = j.verdicts[q][0] == ACCEPTED or j.parts[0].is_safe(j.components[q][0])
        keeps = self._where()[0]
        if (true_held and keeps is not None and isinstance(memory, (int, np.integer))
                and 0 <= memory < len(keeps.states) and keeps.states[memory]):
            return self._named((ACCEPTED, *(v if v != UNDECIDED else REJECTED
                                            for v in self.joint.verdicts[q][1:])))
        return self.stopped(q)

    def labels(self, q: int) -> frozenset[str]:
        return frozenset(n for n, v in zip(self.names, self.joint.verdicts[q], strict=True)
                         if v == ACCEPTED)

    def end_labels(self, name: str) -> frozenset[str]:
        return self._ends[name]

    def rewards(self, states: list[tuple[int, frozenset[str], Any] | None],
                mixes: Mapping[int, list[tuple[str, float]]]
                ) -> tuple[tuple[str, np.ndarray], ...]:
        """``steps``: 1 on a state ``(q, pending, memory)`` whose true task is undecided
        and can still accept with the events pending, the controller's memory an
        information state from which the task can still be won (:func:`winnable`) (the
        synthesis's E(steps) counts its steps), times the probability that the
        controller does not stay there, else 0;
        ``cost``: there, the expected cost of the controller's action (each action's
        ``costs`` entry, 1 if it has none; *stay* costs nothing)."""
        j, win = self.joint, self._where()[1]

        def lost(memory: Any) -> bool:
            return (win is not None and isinstance(memory, (int, np.integer))
                    and 0 <= memory < len(win) and not win[memory])

        steps = np.array([0.0 if x is None or j.verdicts[x[0]][0] != UNDECIDED
                          or not self.live(j.components[x[0]][0], x[1]) or lost(x[2])
                          else 1.0 for x in states])
        # a step is taken unless the controller stays (a keep takes none)
        steps *= np.array([math.fsum(p for _, p in mixes[k]) if k in mixes else 1.0
                           for k in range(len(states))])
        cost = np.array([sum(p * self.costs.get(a, 1.0) for a, p in mixes.get(k, ()))
                         for k in range(len(states))]) * steps
        return (("steps", steps), ("cost", cost))

    def live(self, q: int, pending: frozenset[str]) -> bool:
        """Whether the task's automaton reaches acceptance from ``q`` (:class:`TaskLive`)."""
        return self._task_live(q, pending)


class TaskLive:
    """Whether ``task``'s automaton reaches acceptance (a persistent or the accepting
    state) from a state on some word of the world's propositions and the events still
    ``pending`` (each may still come; ``events``: every event); beyond
    :data:`~mitld_lp.sensing.belief.MAX_PRUNE_ATOMS` atoms, True (as the synthesis
    counts it)."""

    def __init__(self, task: DTA, events: frozenset[str]) -> None:
        self.task, self.events = task, events
        self._live: dict[tuple[int, frozenset[str]], bool] = {}

    def __call__(self, q: int, pending: frozenset[str]) -> bool:
        key = (q, pending)
        hit = self._live.get(key)
        if hit is None:
            task = self.task
            atoms = sorted(a for a in task.atoms if a not in self.events or a in pending)
            hit = len(atoms) > MAX_PRUNE_ATOMS or _reaches(task, q, atoms)
            self._live[key] = hit
        return hit


def _reaches(dta: DTA, q: int, atoms: Sequence[str]) -> bool:
    """Whether some word over ``atoms`` leads ``dta`` from ``q`` to a persistent or
    accepting state."""
    goal = dta.persistent | ({dta.accepting} if dta.accepting is not None else set())
    letters = [frozenset(a for a, bit in zip(atoms, bits, strict=True) if bit)
               for bits in itertools.product((False, True), repeat=len(atoms))]
    seen, todo = {q}, [q]
    while todo:
        u = todo.pop()
        if u in goal:
            return True
        for letter in letters:
            v = dta.step(u, letter)
            if v not in seen:
                seen.add(v)
                todo.append(v)
    return False


def joint_ends(joint: Joint, constraints: Sequence[Any], belief: Any,
               costs: Mapping[str, float]) -> JointEnds:
    """The ends of ``joint`` (the task first, then one component per ``P(...)``
    constraint of ``constraints``, in order): component labels ``c<i>`` by the
    constraint's position among all of them; ``belief``: the information-state product
    (its events, for the steps); ``costs``: the actions' costs (the reward ``cost``)."""
    names = ["accept"]
    against: set[str] = set()
    for i, c in enumerate(constraints, start=1):
        if c.kind == "prob":
            names.append(f"c{i}")
            if c.sense == "<=":
                against.add(f"c{i}")
    if len(names) != len(joint.parts):
        raise ValueError(f"the joint automaton has {len(joint.parts)} components, the task "
                         f"and {len(names) - 1} constraint formulas were given")
    return JointEnds(joint, names, frozenset(against), frozenset(belief.sta.events),
                     costs, belief)


def held(joint: Joint, state: Any, sensed: Sequence[str], live: TaskLive
         ) -> list[bool | None]:
    """Per hypothesis ``(times, q)`` of the information state ``state`` of a product on
    ``joint`` (``sensed``: its sensed events, in its hypotheses' order; the times then
    hold the report counts of the sensors with false alarms, not read here): True where it is
    *persistent* -- its task accepted, or its task automaton's state safe (staying there
    for ever keeps a task's safety part) --, False where its task is lost (rejected, or
    no longer reaching acceptance with the events left, ``live``), None where it is
    open."""
    task, comps = joint.parts[0], joint.components
    out: list[bool | None] = []
    for times, q in state.hypotheses:
        v, c = joint.verdicts[q][0], comps[q][0]
        if v == ACCEPTED or task.is_safe(c):
            out.append(True)
        elif v == REJECTED:
            out.append(False)
        else:
            left = state.pending | frozenset(
                a for a, k in zip(sensed, times[:len(sensed)], strict=True) if k == NOT_YET)
            out.append(None if live(c, left) else False)
    return out


class Keeps:
    """Where a task with a safety part is *kept* on the information-state product
    ``belief`` of ``joint`` (:mod:`mitld_lp.routes.sensed_constrained`): ``every`` and
    ``some`` mark the information states with no open hypothesis and with some
    persistent one (:func:`held`); ``states`` the keep states: those of a maximal end
    component of ``every`` states, or else of ``some`` states, in which each hypothesis
    is persistent in every state that holds it or in none (a run playing it for ever
    keeps the task exactly when the true hypothesis is persistent: given the true
    hypothesis, the run stays among the states that hold it);
    ``inside`` per choice, whether a kept run plays it (its end component's internal
    choices); ``open_keeps`` the keep states with an open hypothesis."""

    def __init__(self, belief: Any, joint: Joint) -> None:
        from mitld_lp.sensing.belief import InfoState
        from mitld_lp.solvers.graph import maximal_end_components

        mdp = belief.mdp
        n = mdp.n_states
        self.live = TaskLive(joint.parts[0], frozenset(belief.sta.events))
        self.status: dict[int, list[bool | None]] = {}
        info = np.array([isinstance(r, InfoState) for r in mdp.states], dtype=bool)
        self.every = np.zeros(n, dtype=bool)
        self.some = np.zeros(n, dtype=bool)
        hypotheses: dict[int, Any] = {}  # each information state made once
        for i in np.flatnonzero(info).tolist():
            s = mdp.states[i]
            hypotheses[i] = s.hypotheses
            kinds = self.status[i] = held(joint, s, belief.sensed, self.live)
            self.every[i], self.some[i] = None not in kinds, True in kinds
        whole = maximal_end_components(mdp, info & self.every)
        wider = maximal_end_components(mdp, info & self.some)
        self.states = np.zeros(n, dtype=bool)
        self.inside = np.zeros(mdp.n_choices, dtype=bool)
        self.in_some = np.asarray(wider.mec_of) >= 0
        cs = mdp.choice_state()
        for ecs in (whole, wider):  # the first found keeps its own end component
            internal = np.asarray(ecs.internal, dtype=bool)
            for m in range(ecs.n_mecs):
                members = ecs.states_of(m)
                if self._uniform(hypotheses, members):
                    fresh = members[~self.states[members]]
                    self.states[fresh] = True
                    among = np.zeros(n, dtype=bool)
                    among[fresh] = True
                    self.inside |= internal & among[cs]
        self.open_keeps = self.states & ~self.every

    def _uniform(self, hypotheses: Mapping[int, Any], members: np.ndarray) -> bool:
        """Whether each hypothesis of these states (``hypotheses``: per state, its
        hypotheses) is persistent in all that hold it or in none."""
        seen: dict[tuple[int, ...], bool] = {}
        for y in members.tolist():
            for (times, _), kind in zip(hypotheses[y], self.status[y], strict=True):
                mine = kind is True
                if seen.setdefault(times, mine) != mine:
                    return False
        return True


def keeps_for(belief: Any, joint: Joint) -> Keeps | None:
    """The keep states of a task with a safety part on ``belief`` (:class:`Keeps`);
    None for a co-safe task."""
    return Keeps(belief, joint) if SAFE in joint.parts[0].kinds else None


def winnable(belief: Any, keeps: Keeps | None) -> np.ndarray:
    """Per state of ``belief``'s product: whether some policy reaches from it a verdict
    state with the task accepted, the truncation, or a keep state with a persistent
    hypothesis.  Where none is reached no step counts towards ``E(steps)`` (the task can
    no longer be won, as on the fully observed product)."""
    from mitld_lp.product import Absorbing
    from mitld_lp.solvers.quotient import backward_reachable

    mdp = belief.mdp
    seeds = np.array([r is Absorbing.TRUNCATED or getattr(r, "verdicts", (None,))[0]
                      == ACCEPTED for r in mdp.states], dtype=bool)
    if keeps is not None:
        seeds |= keeps.states & keeps.some
    e = mdp.matrix.tocoo()
    return backward_reachable(mdp.n_states, mdp.choice_state()[e.row], e.col, seeds)
