"""Run a synthesised policy online: the robot reports what it sees, the controller answers
with an action, tracking the automaton state, the pending events and the clock itself.

    controller.reset()
    action = controller.act(Observation(state=s0))          # step 0: no events yet
    ...                                                     # the robot moves; events happen
    action = controller.act(Observation(state=s1, events=frozenset({"b1"})))

``act`` returns ``None`` once the task is decided (``status`` says how).

A controller is saved as a file of plain tables (:meth:`Controller.save`, format in
:mod:`mitld_lp.running.controller_file`) that :meth:`Controller.load` parses without running
anything from it, in a process that needs neither the world's class nor a solver.
"""

from __future__ import annotations

import enum
import os
from collections.abc import Hashable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from mitld_lp import defaults
from mitld_lp.automata.sta import STA
from mitld_lp.files import write as files
from mitld_lp.mdp import MDP
from mitld_lp.product import ProductState, ProductStates
from mitld_lp.running.controller_file import ControllerFileError, SavedPlan, read_plan, tabulate
from mitld_lp.runtime import ACCEPTED, REJECTED, UNDECIDED, Decision, Stepper
from mitld_lp.worlds.game import Game

__all__ = ["Observation", "Controller", "ControllerFileError", "ControllerLike", "RunStatus",
           "save_tables"]


class RunStatus(enum.Enum):
    RUNNING = "running"
    ACCEPTED = "accepted"  # the task is satisfied
    REJECTED = "rejected"  # the task can no longer be satisfied


@dataclass(frozen=True, slots=True)
class Observation:
    """What the robot sees after a step: the game state it is in and the external events
    that happened in the step that led there (none at step 0).

    ``events`` is any collection of event names (stored as a frozenset).  A bare string
    is refused with ``TypeError``: ``events="b1"`` would otherwise read as the events
    ``"b"`` and ``"1"``; write ``events={"b1"}``.  ``state`` must be hashable.
    """

    state: Hashable
    events: frozenset[str] = frozenset()

    def __post_init__(self) -> None:
        try:
            hash(self.state)
        except TypeError:
            raise TypeError(
                f"Observation.state: a world state is hashable, got {type(self.state).__name__}"
            ) from None
        events: Any = self.events
        if isinstance(events, str | bytes):
            raise TypeError(
                f"Observation.events: expected a set of event names, got the string "
                f"{events!r}; write events={{{events!r}}} for that one event"
            )
        if not isinstance(events, frozenset):
            try:
                events = frozenset(events)
            except TypeError:
                raise TypeError(
                    "Observation.events: expected a set of event names, got "
                    f"{type(events).__name__}"
                ) from None
            object.__setattr__(self, "events", events)
        for e in events:
            if not isinstance(e, str):
                raise TypeError(f"Observation.events: an event name is a string, got {e!r}")


class ControllerLike(Protocol):
    """What every controller offers (:class:`Controller`, deterministic, and
    :class:`mitld_lp.ConstrainedController`, randomised), and what :func:`simulate
    <mitld_lp.running.simulate.simulate>`, ``mitld-lp simulate``, the exports and the runtime
    take: ``act`` on an observation (None once the task is decided), ``reset`` to start
    a new run, the memory (``automaton_state``, ``pending``, ``clock``), the task's
    ``status``, and ``save``.  A randomised controller draws from ``rng``, a seeded
    ``numpy.random.Generator`` (``reset(seed=...)`` reseeds it); a deterministic one
    never draws."""

    randomised: bool

    @property
    def events(self) -> frozenset[str]: ...
    @property
    def status(self) -> RunStatus: ...
    @property
    def automaton_state(self) -> int | None: ...
    @property
    def pending(self) -> frozenset[str]: ...
    @property
    def clock(self) -> int: ...
    @property
    def beyond_model(self) -> bool: ...
    @property
    def settled(self) -> bool: ...
    @property
    def steps(self) -> int: ...

    def reset(self, seed: int | None = None) -> None: ...
    def act(self, observation: Observation) -> str | None: ...
    def task_verdict(self, state: int) -> int: ...
    def tables(self, max_states: int = defaults.MAX_STATES) -> SavedPlan: ...
    def save(self, path: str | os.PathLike[str], *, overwrite: bool = False,
             max_states: int = defaults.MAX_STATES) -> Path: ...


@dataclass(frozen=True, slots=True, eq=False)
class _LivePlan:
    """The synthesised model itself: the world, the STA, the product MDP, the policy
    (a choice per state, -1 where there is none) and the optional hopeless mask."""

    game: Game[Any]
    sta: STA
    mdp: MDP
    policy: np.ndarray
    hopeless: np.ndarray | None
    _index: dict[Hashable, int] = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        if not isinstance(self.mdp.states, ProductStates):  # a hand-made MDP: index it
            self._index.update((s, i) for i, s in enumerate(self.mdp.states))

    @property
    def events(self) -> frozenset[str]:
        return self.sta.events

    @property
    def initial(self) -> int:
        return self.sta.dta.initial

    @property
    def verdicts(self) -> tuple[tuple[int, ...], ...]:
        dta = self.sta.dta
        return tuple((ACCEPTED,) if q == dta.accepting else (REJECTED,)
                     if q == dta.rejecting else (UNDECIDED,) for q in range(dta.n_states))

    def read(self, q: int, state: Hashable, events: frozenset[str]) -> int:
        return self.sta.dta.step(q, self.game.propositions(state) | events)

    def advance(self, pending: frozenset[str], clock: int) -> tuple[int, bool]:
        step = self.sta.advance(pending, clock)
        return step.clock, step.truncated

    def decide(self, state: Hashable, q: int, pending: frozenset[str], clock: int) -> Decision:
        record = ProductState(state, q, pending, clock)
        states = self.mdp.states
        i = states.position(record) if isinstance(states, ProductStates) else (
            self._index.get(record))
        if i is None:
            return Decision(())
        lost = self.hopeless is not None and bool(self.hopeless[i])
        c = int(self.policy[i])
        return Decision(() if c < 0 else (self.mdp.action_name(c),), lost=lost)

    def lookup(
        self, state: Hashable, q: int, pending: frozenset[str], clock: int
    ) -> tuple[str | None, bool]:
        d = self.decide(state, q, pending, clock)
        return (d.actions[0] if d.actions else None), d.lost

    def fallback(self, state: Hashable) -> str:
        return self.game.actions(state)[0]

    def tables(self, max_states: int) -> SavedPlan:
        return tabulate(self.game, self.sta, self.mdp, self.policy, self.hopeless,
                        max_states=max_states)


class Controller(Stepper):
    """A deterministic stationary policy on product states, run on the original game.

    ``Controller(game, sta, mdp, policy, hopeless=None)``: ``policy`` gives a choice of
    ``mdp`` per state (-1: none, any action will do); the optional ``hopeless`` mask
    marks states from which no policy can satisfy the task even if every truncated event
    came in time (``prob0_max`` of the upper model): the controller reports
    ``REJECTED`` there instead of acting on forever.

    Beyond a truncation point (an event later than the model looked) it keeps acting
    with the clock held at the last modelled value and sets ``beyond_model``.
    """

    randomised = False

    def __init__(
        self,
        game: Game[Any],
        sta: STA,
        mdp: MDP,
        policy: np.ndarray,
        hopeless: np.ndarray | None = None,
    ) -> None:
        self._begin(_LivePlan(game, sta, mdp, policy, hopeless), np.random.default_rng(0))

    def __repr__(self) -> str:
        return f"Controller(status={self.status.value}, steps={self.steps})"

    @property
    def status(self) -> RunStatus:
        return RunStatus(self.status_name)

    def reset(self, seed: int | None = None) -> None:
        """Start a new run (the next ``act`` is step 0); ``seed`` is accepted for the
        common interface and unused (a deterministic controller never draws)."""
        self._restart()

    def tables(self, max_states: int = defaults.MAX_STATES) -> SavedPlan:
        """The controller as plain tables (what :meth:`save` writes)."""
        plan = self._plan
        return plan if isinstance(plan, SavedPlan) else plan.tables(max_states)  # type: ignore[attr-defined]

    def save(
        self,
        path: str | os.PathLike[str],
        *,
        overwrite: bool = False,
        max_states: int = defaults.MAX_STATES,
    ) -> Path:
        """Write the controller to ``path`` (by convention ``*.npz``) as plain tables:
        the policy over product states, the automaton's transition diagrams, the clock
        rule, and every world state it may observe with its propositions (see
        :mod:`mitld_lp.running.controller_file`).  :meth:`load` reads it back in any process,
        without the world's class.  The file holds data only, never pickled objects.
        The path follows the package's one rule for output files (:mod:`mitld_lp.files.write`):
        checked before any work, written to a temporary file renamed into place.

        Raises ``FileExistsError`` if ``path`` exists and not ``overwrite``;
        ``ValueError`` (before writing) if a world state is not made of None, booleans,
        numbers, strings and tuples, or if the world states to tabulate exceed
        ``max_states``.
        """
        return save_tables(self, path, overwrite=overwrite, max_states=max_states)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> Controller:
        """The controller :meth:`save` wrote to ``path``, reset to step 0.

        The file is parsed as data (NumPy arrays with ``allow_pickle=False`` and JSON);
        nothing in it is executed.  A file that is not a deterministic controller of a
        format version this package reads (foreign, damaged, truncated, another
        version, unreadable, a randomised controller) raises
        :class:`ControllerFileError` (a ``ValueError``) naming the file and the fault;
        :func:`load_controller` loads either kind.
        """
        plan = read_plan(Path(path))
        if plan.randomised:
            raise ControllerFileError(
                f"{path}: cannot load the controller: a randomised controller; load it "
                "with mitld_lp.ConstrainedController.load or mitld_lp.load_controller")
        controller = cls.__new__(cls)
        controller._begin(plan, np.random.default_rng(0))
        return controller

    def act(self, observation: Observation) -> str | None:
        """The action to take in ``observation.state``; ``None`` once the task is decided."""
        return self._step(observation.state, _events(observation))


def _events(observation: Any) -> frozenset[str]:
    """The events of a fully observed :class:`Observation`; a ``TypeError`` naming the
    class for anything else (a sensed ``Observation`` carries reports, not events: its
    controller is the one the synthesis of a model with sensors returns)."""
    events = getattr(observation, "events", None)
    if events is None or not hasattr(observation, "state"):
        raise TypeError(f"act: expected a mitld_lp.Observation(state, events), got "
                        f"{type(observation).__module__}.{type(observation).__qualname__}")
    return events


def save_tables(controller: ControllerLike, path: str | os.PathLike[str], *,
                overwrite: bool, max_states: int) -> Path:
    """Write ``controller.tables()`` to ``path`` under the package's rule for outputs."""
    out = files.writable_path(path, overwrite=overwrite)
    data = controller.tables(max_states).to_bytes()
    with files.replacing(out, "wb") as handle:
        handle.write(data)
    return out
