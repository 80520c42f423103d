"""The one step rule every controller runs, with NumPy alone.

A controller is a :class:`Stepper` over a :class:`Plan`: the plan says what the
controller remembers and what it decides (the synthesis's model, a saved file's
tables, a decision tree, the information states of a controller that acts on sensor
reports); the stepper checks the observation, moves the memory, and turns the decision
into an action: deterministic, drawn from a seeded generator, *stay* (keep to an end
component for ever), *keep* (keep the task's safety part for ever), or the world state's
first action where the plan has none.  :class:`mitld_lp.Controller`,
:class:`mitld_lp.ConstrainedController`, the sensed and the tree controller, and the
runtime's controller (:mod:`mitld_lp.runtime`) all step here, so they cannot disagree.
"""

from __future__ import annotations

from collections.abc import Hashable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from mitld_lp.controllers.format import ACCEPTED, REJECTED, UNDECIDED

__all__ = ["AutomatonMemory", "DECIDED", "Decision", "Plan", "Stepper"]

DECIDED = -2
"""A verdict beside :data:`~mitld_lp.controllers.format.ACCEPTED`, ``REJECTED`` and
``UNDECIDED``: decided, but the robot cannot tell which way (a controller that acts on
sensor reports whose hypotheses left are decided differently); its status stays
``running`` and it acts no more."""


@dataclass(frozen=True, slots=True)
class Decision:
    """What a controller does in one memory state: draw *stay* with probability
    ``stay`` (then keep to the end component for ever, drawing uniformly among
    ``inside``), else one of ``actions`` with probability proportional to ``weights``.
    ``weights`` is None for a deterministic choice (``actions`` has one entry, or none:
    any action will do).  ``lost``: the task can no longer be won (the controller stops);
    ``charged``: a step here counts towards E(steps).  ``keep``: per action, whether it
    is the *keep* choice (the task's safety part kept for ever: from then on the run
    plays uniformly among ``kept``, the actions that stay in the end component of
    persistent task states)."""

    actions: tuple[str, ...]
    weights: np.ndarray | None = None
    stay: float = 0.0
    inside: tuple[str, ...] = ()
    lost: bool = False
    charged: bool = False
    keep: tuple[bool, ...] = ()
    kept: tuple[str, ...] = ()


class Plan(Protocol):
    """What :class:`Stepper` asks of a controller's plan.  A memory is the plan's own
    value (None before step 0 only)."""

    @property
    def events(self) -> frozenset[str]: ...
    @property
    def randomised(self) -> bool: ...

    def observed(self, events: frozenset[str], reports: frozenset[str]) -> frozenset[str]: ...
    def start(self, state: Hashable) -> Any: ...
    def follow(self, memory: Any, state: Hashable, seen: frozenset[str],
               last: str | None) -> tuple[Any, bool]: ...
    def verdicts_at(self, memory: Any) -> tuple[int, ...]: ...
    def decision(self, state: Hashable, memory: Any) -> Decision: ...
    def fallback(self, state: Hashable) -> str: ...


class AutomatonMemory:
    """The memory rule of a plan that follows the task's automaton and a clock: the
    memory is ``(q, pending, clock)``, the automaton state after the label and the
    events seen, the events not seen yet and the steps since the start (capped).  A
    plan using it has ``events``, ``initial``, per automaton state its ``verdicts``,
    ``read(q, state, events)``, ``advance(pending, clock)`` (the next clock and whether
    it crossed a truncation point) and ``decide(state, q, pending, clock)``."""

    __slots__ = ()

    events: frozenset[str]
    initial: int
    verdicts: Sequence[tuple[int, ...]]

    def read(self, q: int, state: Hashable, events: frozenset[str]) -> int:
        raise NotImplementedError

    def advance(self, pending: frozenset[str], clock: int) -> tuple[int, bool]:
        raise NotImplementedError

    def decide(self, state: Hashable, q: int, pending: frozenset[str], clock: int) -> Decision:
        raise NotImplementedError

    def observed(self, events: frozenset[str], reports: frozenset[str]) -> frozenset[str]:
        """The events seen; a report is refused (this controller's model has no sensors
        that miss events: it sees the events themselves)."""
        if reports:
            raise ValueError(
                f"Observation.reports: {sorted(reports)}: this controller sees the events "
                "themselves (its model has no sensors that miss them); give them as events")
        return events

    def start(self, state: Hashable) -> tuple[int, frozenset[str], int]:
        return self.read(self.initial, state, frozenset()), self.events, 0

    def follow(self, memory: tuple[int, frozenset[str], int], state: Hashable,
               seen: frozenset[str], last: str | None
               ) -> tuple[tuple[int, frozenset[str], int], bool]:
        q0, pending0, clock0 = memory
        again = seen - pending0
        if again:
            raise ValueError(f"events observed a second time: {sorted(again)}")
        q = self.read(q0, state, seen)
        pending = pending0 - seen
        clock, crossed = self.advance(pending, clock0)
        return (q, pending, clock), crossed

    def verdicts_at(self, memory: tuple[int, frozenset[str], int] | None) -> tuple[int, ...]:
        if memory is None:
            return tuple(UNDECIDED for _ in self.verdicts[self.initial])
        return tuple(self.verdicts[memory[0]])

    def decision(self, state: Hashable, memory: tuple[int, frozenset[str], int]) -> Decision:
        q, pending, clock = memory
        return self.decide(state, q, pending, clock)


class Stepper:
    """The controller's memory and its one step rule, over a :class:`Plan`.

    ``status_name`` is the task's: ``"running"``, ``"accepted"`` or ``"rejected"`` (also
    when the run has drawn *stay* with the task undecided: it decides nothing more).
    ``_step`` returns None once every component is decided (or the task is lost).
    ``steps``: the observations taken; ``charged``: the steps taken in states marked
    charged (E(steps)); ``staying``: the run keeps to an end component for ever;
    ``beyond_model``: an observation came that the model does not hold (an event later
    than its truncation point), after which the controller acts on as its plan says.
    """

    def _begin(self, plan: Plan, rng: np.random.Generator | None = None, *,
               seed: int | None = 0) -> None:
        """Act by ``plan``, drawing from ``rng``; without one, from a generator seeded
        with ``seed`` made on the first draw (:attr:`rng`)."""
        self._plan = plan
        self._rng = rng
        self._seed = seed
        self._restart()

    @property
    def rng(self) -> np.random.Generator:
        """The generator a randomised decision draws from.  Made on first use when the
        controller was given a seed only: a deterministic controller never draws, so a
        solve that returns one makes no generator.  The same stream as a generator made
        at the start, since nothing draws before."""
        if self._rng is None:
            self._rng = np.random.default_rng(self._seed)
        return self._rng

    @rng.setter
    def rng(self, value: np.random.Generator) -> None:
        self._rng = value

    def _restart(self) -> None:
        self._memory: Any = None
        self._lost = False
        self.last: str | None = None
        self.steps = 0
        self.charged = 0
        self.staying = False
        self.keeping = False
        self.beyond_model = False

    @property
    def plan(self) -> Plan:
        """The tables (or the model) the controller acts by."""
        return self._plan

    @property
    def randomised(self) -> bool:
        return self._plan.randomised

    @property
    def events(self) -> frozenset[str]:
        """The task's external events."""
        return self._plan.events

    @property
    def memory(self) -> Any:
        """The plan's memory after the last observation (None before step 0)."""
        return self._memory

    @property
    def automaton_state(self) -> int | None:
        m = self._memory
        return m[0] if isinstance(m, tuple) else None

    @property
    def pending(self) -> frozenset[str]:
        m = self._memory
        return m[1] if isinstance(m, tuple) else self._plan.events

    @property
    def clock(self) -> int:
        m = self._memory
        return m[2] if isinstance(m, tuple) else 0

    @property
    def verdicts(self) -> tuple[int, ...]:
        """Per component (the task first): accepted 1, rejected 0, undecided -1 (the task
        accepted once the run keeps its safety part for ever)."""
        v = self._plan.verdicts_at(self._memory)
        return (ACCEPTED, *v[1:]) if self.keeping else v

    def task_verdict(self, state: int) -> int:
        """The task's verdict in automaton state ``state`` of the controller's own
        automaton (accepted 1, rejected 0, undecided -1): which automaton it runs, the
        task's or its complement's, is told by the task's accepting state."""
        return int(self._plan.verdicts_at((state, frozenset(), 0))[0])

    @property
    def status_name(self) -> str:
        v = REJECTED if self._lost else self.verdicts[0]
        if v == UNDECIDED and self.staying:
            v = REJECTED
        return "accepted" if v == ACCEPTED else "rejected" if v == REJECTED else "running"

    @property
    def settled(self) -> bool:
        """Nothing can change any more: every component is decided, the task is lost,
        or the run stays in an end component for ever."""
        return self.staying or self.keeping or self._lost or (
            self._memory is not None and UNDECIDED not in self.verdicts)

    def _step(self, state: Hashable, events: frozenset[str],
              reports: frozenset[str] = frozenset()) -> str | None:
        plan = self._plan
        seen = plan.observed(events, reports)
        unknown = seen - plan.events
        if unknown:
            raise ValueError(
                f"unknown events observed: {sorted(unknown)} ({min(unknown)!r} is not an "
                f"event of the task, whose events are {', '.join(sorted(plan.events))})")
        if self._memory is None:
            if seen:
                raise ValueError(f"step 0: no event can have happened yet, got {sorted(seen)}")
            memory = plan.start(state)
        else:
            memory, crossed = plan.follow(self._memory, state, seen, self.last)
            self.beyond_model = self.beyond_model or crossed
        self._memory = memory
        self.steps += 1
        self.last = self._act(state, memory)
        return self.last

    def _act(self, state: Hashable, memory: Any) -> str | None:
        plan = self._plan
        if self._lost or UNDECIDED not in plan.verdicts_at(memory):
            return None
        d = plan.decision(state, memory)
        if d.lost:
            self._lost = True
            return None
        if d.weights is None:  # deterministic; no action: any will do (value 0 there)
            return d.actions[0] if d.actions else plan.fallback(state)
        if not d.actions:
            return plan.fallback(state)
        if self.keeping:  # the task's safety part kept: its end component, for ever
            return self._uniform(d.kept, plan, state)
        if not self.staying and self.rng.random() < d.stay:
            self.staying = True
        if self.staying:  # keep to the end component: its internal actions, uniformly
            if d.inside:
                return d.inside[int(self.rng.integers(len(d.inside)))]
            return plan.fallback(state)
        w = d.weights
        i = int(self.rng.choice(len(w), p=w / w.sum()))
        if d.keep and d.keep[i]:
            self.keeping = True
            return self._uniform(d.kept, plan, state)
        self.charged += d.charged
        return d.actions[i]

    def _uniform(self, actions: tuple[str, ...], plan: Plan, state: Hashable) -> str:
        """One of ``actions`` uniformly (any action where there is none)."""
        if actions:
            return actions[int(self.rng.integers(len(actions)))]
        return plan.fallback(state)
