"""Run a saved controller with NumPy alone: no SciPy, cvxpy, Clarabel, lark or stormpy.

    from mitld_lp.runtime import load
    controller = load("bus.npz")          # deterministic or randomised (seed=...)
    action = controller.act((0, 0))       # step 0: no events yet
    action = controller.act((1, 0), {"b1"})
    ...                                   # None once the task is decided

The file is read by :mod:`mitld_lp.running.saved_plan`; this module is the one place that steps
a controller: :class:`mitld_lp.Controller` and :class:`mitld_lp.ConstrainedController`
act through :class:`Stepper` too, so the runtime and the library cannot disagree.  Both
modules import only the standard library and NumPy (``import mitld_lp`` itself loads
its modules lazily), so a robot's process starts in a fraction of the full package's
time.

:func:`serve` is the line loop behind ``mitld-lp run CONTROLLER``: one JSON object per
line on its input, ``{"state": ..., "events": [...]}`` (the world state as the policy
table writes it; the events seen in the step that led there), one ``{"action": ...}``
per line on its output (``null`` once the task is decided; ``"status"`` says how).
"""

from __future__ import annotations

import json
from collections.abc import Hashable, Iterable, Sequence
from pathlib import Path
from typing import IO, Any, Protocol

import numpy as np

from mitld_lp.running.plan_reader import read_plan
from mitld_lp.running.saved_plan import (
    ACCEPTED,
    FORMAT,
    KEEP,
    REJECTED,
    UNDECIDED,
    VERSION,
    ControllerFileError,
    Decision,
    SavedPlan,
    advance,
    decode_state,
    encode_state,
)

__all__ = [
    "ACCEPTED",
    "ControllerFileError",
    "Decision",
    "FORMAT",
    "KEEP",
    "REJECTED",
    "RuntimeController",
    "SavedPlan",
    "Stepper",
    "UNDECIDED",
    "VERSION",
    "advance",
    "decode_state",
    "encode_state",
    "load",
    "read_plan",
    "serve",
]

_QUOTE = 80  # characters of a foreign value quoted in an error


def _printable(text: str) -> str:
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


def _short(value: object) -> str:
    text = _printable(repr(value))
    return text if len(text) <= _QUOTE else text[: _QUOTE - 3] + "..."


# --------------------------------------------------------------------------- stepping


class Plan(Protocol):
    """What :class:`Stepper` asks of a controller's tables (saved or in memory)."""

    @property
    def events(self) -> frozenset[str]: ...
    @property
    def initial(self) -> int: ...
    @property
    def verdicts(self) -> Sequence[tuple[int, ...]]: ...

    def read(self, q: int, state: Hashable, events: frozenset[str]) -> int: ...
    def advance(self, pending: frozenset[str], clock: int) -> tuple[int, bool]: ...
    def decide(self, state: Hashable, q: int, pending: frozenset[str],
               clock: int) -> Decision: ...
    def fallback(self, state: Hashable) -> str: ...


class Stepper:
    """The controller's memory and its one step rule, over a :class:`Plan`.

    ``status`` is the task's: ``"running"``, ``"accepted"`` or ``"rejected"`` (also
    when the run has drawn *stay* with the task undecided: it decides nothing more).
    ``act`` returns None once every component is decided (or the task is lost).
    ``steps``: the observations taken; ``charged``: the steps taken in states marked
    charged (E(steps)); ``staying``: the run keeps to an end component for ever.
    """

    def _begin(self, plan: Plan, rng: np.random.Generator) -> None:
        self._plan = plan
        self.rng = rng
        self._restart()

    def _restart(self) -> None:
        self._memory: tuple[int, frozenset[str], int] | None = None
        self._lost = False
        self.steps = 0
        self.charged = 0
        self.staying = False
        self.keeping = False
        self.beyond_model = False

    @property
    def events(self) -> frozenset[str]:
        """The task's external events."""
        return self._plan.events

    @property
    def automaton_state(self) -> int | None:
        return None if self._memory is None else self._memory[0]

    @property
    def pending(self) -> frozenset[str]:
        return self._plan.events if self._memory is None else self._memory[1]

    @property
    def clock(self) -> int:
        return 0 if self._memory is None else self._memory[2]

    @property
    def verdicts(self) -> tuple[int, ...]:
        """Per component (the task first): accepted 1, rejected 0, undecided -1 (the task
        accepted once the run keeps its safety part for ever)."""
        if self._memory is None:
            return tuple(UNDECIDED for _ in self._plan.verdicts[self._plan.initial])
        v = tuple(self._plan.verdicts[self._memory[0]])
        return (ACCEPTED, *v[1:]) if self.keeping else v

    def task_verdict(self, state: int) -> int:
        """The task's verdict in automaton state ``state`` of the controller's own
        automaton (accepted 1, rejected 0, undecided -1): which automaton it runs, the
        task's or its complement's, is told by the task's accepting state."""
        return int(self._plan.verdicts[state][0])

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

    def _step(self, state: Hashable, events: frozenset[str]) -> str | None:
        plan = self._plan
        if self._memory is None:
            if events:
                raise ValueError(f"step 0: no event can have happened yet, got {sorted(events)}")
            q, pending, clock = plan.read(plan.initial, state, events), plan.events, 0
        else:
            q0, pending0, clock0 = self._memory
            unknown = events - plan.events
            if unknown:
                raise ValueError(f"unknown events observed: {sorted(unknown)}")
            again = events - pending0
            if again:
                raise ValueError(f"events observed a second time: {sorted(again)}")
            q = plan.read(q0, state, events)
            pending = pending0 - events
            clock, crossed = plan.advance(pending, clock0)
            self.beyond_model = self.beyond_model or crossed
        self._memory = (q, pending, clock)
        self.steps += 1
        if self._lost or UNDECIDED not in plan.verdicts[q]:
            return None
        d = plan.decide(state, q, pending, clock)
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


class RuntimeController(Stepper):
    """A saved controller run from its tables: ``act(state, events)``."""

    def __init__(self, plan: SavedPlan, *, seed: int | None = 0) -> None:
        self._begin(plan, np.random.default_rng(seed))

    @property
    def plan(self) -> SavedPlan:
        assert isinstance(self._plan, SavedPlan)
        return self._plan

    @property
    def status(self) -> str:
        return self.status_name

    def reset(self, seed: int | None = None) -> None:
        """Start a new run; with ``seed``, a new generator (else the generator runs on)."""
        if seed is not None:
            self.rng = np.random.default_rng(seed)
        self._restart()

    def act(self, state: Hashable, events: Iterable[str] = ()) -> str | None:
        """The action in world ``state`` after ``events``; None once decided."""
        if isinstance(events, str | bytes):
            raise TypeError(f"events: expected a set of event names, got the string {events!r}")
        return self._step(state, frozenset(events))

    def world_state(self, value: Any) -> Hashable:
        """The world state that ``value`` (as the policy table writes it: a list for a
        tuple, an object of variables for a PRISM world) stands for."""
        variables = self.plan.variables
        if isinstance(value, dict):
            if variables is None:
                raise ValueError(f"state {_short(value)}: this world's states have no "
                                 "variable names; give the state as the policy table does")
            missing = [v for v in variables if v not in value]
            extra = sorted(set(value) - set(variables))
            if missing or extra:
                raise ValueError(f"state {_short(value)}: expected the variables "
                                 f"{', '.join(variables)}")
            value = [value[v] for v in variables]
        return decode_state(value)


def load(path: str | Path, *, seed: int | None = 0) -> RuntimeController:
    """The controller saved at ``path``, ready at step 0 (a randomised one draws from a
    generator seeded with ``seed``).  :class:`ControllerFileError` if it is not one."""
    return RuntimeController(read_plan(path), seed=seed)


# --------------------------------------------------------------------------- the line loop


def serve(controller: RuntimeController, lines: Iterable[str], out: IO[str]) -> int:
    """Answer each JSON observation of ``lines`` with one JSON line on ``out`` (module
    docstring).  An observation with ``"reset": true`` starts a new run first.  A bad
    line is answered with ``{"error": ...}`` naming its line number, and the loop goes
    on; returns how many lines were bad."""
    bad = 0
    for number, line in enumerate(lines, 1):
        if not line.strip():
            continue
        try:
            reply = _answer(controller, line)
        except (ValueError, TypeError, RecursionError) as exc:
            bad += 1
            reply = {"error": f"line {number}: {_printable(str(exc))[:300]}"}
        out.write(json.dumps(reply) + "\n")
        out.flush()
    return bad


def _answer(controller: RuntimeController, line: str) -> dict[str, Any]:
    try:
        o = json.loads(line)
    except ValueError as exc:
        raise ValueError(f"not JSON ({exc})") from None
    if not isinstance(o, dict):
        raise ValueError('expected an object {"state": ..., "events": [...]}')
    extra = sorted(set(o) - {"state", "events", "reset"})
    if extra:
        raise ValueError(f"unknown key {extra[0]!r} (keys: state, events, reset)")
    if "state" not in o:
        raise ValueError('no "state": expected {"state": ..., "events": [...]}')
    events = o.get("events", [])
    if not isinstance(events, list) or not all(isinstance(e, str) for e in events):
        raise ValueError("events: expected a list of event names")
    if o.get("reset", False) is True:
        controller.reset()
    state = controller.world_state(o["state"])
    action = controller.act(state, events)
    return {"action": action, "status": controller.status}
