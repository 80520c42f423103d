"""Run a synthesised policy online: the robot reports what it sees, the controller answers
with an action, tracking the automaton state, the pending events and the clock itself.

    controller.reset()
    action = controller.act(Observation(state=s0))          # step 0: no events yet
    ...                                                     # the robot moves; events happen
    action = controller.act(Observation(state=s1, events=frozenset({"b1"})))

``act`` returns ``None`` once the task is decided (``status`` says how).
"""

from __future__ import annotations

import enum
import os
import pickle
from collections.abc import Hashable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from mitld_lp import files
from mitld_lp.automata.sta import STA
from mitld_lp.game import Game
from mitld_lp.mdp import MDP
from mitld_lp.product import ProductState, ProductStates

__all__ = ["Observation", "Controller", "RunStatus"]

_SAVE_FORMAT = "mitld_lp.Controller/1"


class RunStatus(enum.Enum):
    RUNNING = "running"
    ACCEPTED = "accepted"  # the task is satisfied
    REJECTED = "rejected"  # the task can no longer be satisfied


@dataclass(frozen=True, slots=True)
class Observation:
    """What the robot sees after a step: the game state it is in and the external events
    that happened in the step that led there (none at step 0)."""

    state: Hashable
    events: frozenset[str] = frozenset()


@dataclass(slots=True, eq=False)
class Controller:
    """A deterministic stationary policy on product states, run on the original game.

    Beyond a truncation point (an event later than the model looked) it keeps acting
    with the clock held at the last modelled value and sets ``beyond_model``.
    """

    game: Game[Any]
    sta: STA
    mdp: MDP
    policy: np.ndarray
    hopeless: np.ndarray | None = None
    """Optional ``(n_states,)`` mask of states from which no policy can satisfy the task
    even if every truncated event came in time (``prob0_max`` of the upper model); the
    controller reports ``REJECTED`` there instead of acting on forever."""
    _index: dict[Hashable, int] = field(default_factory=dict, repr=False)
    _state: tuple[int, frozenset[str], int] | None = field(default=None, repr=False)
    status: RunStatus = RunStatus.RUNNING
    steps: int = 0
    beyond_model: bool = False

    def __post_init__(self) -> None:
        if not isinstance(self.mdp.states, ProductStates):  # a hand-made MDP: index it
            self._index = {s: i for i, s in enumerate(self.mdp.states)}

    def _position(self, state: ProductState) -> int | None:
        states = self.mdp.states
        if isinstance(states, ProductStates):
            return states.position(state)
        return self._index.get(state)

    def reset(self) -> None:
        """Start a new run (the next ``act`` is step 0)."""
        self._state = None
        self.status = RunStatus.RUNNING
        self.steps = 0
        self.beyond_model = False

    @property
    def automaton_state(self) -> int | None:
        return None if self._state is None else self._state[0]

    @property
    def pending(self) -> frozenset[str]:
        return self.sta.events if self._state is None else self._state[1]

    @property
    def clock(self) -> int:
        return 0 if self._state is None else self._state[2]

    def save(self, path: str | os.PathLike[str], *, overwrite: bool = False) -> Path:
        """Write the controller (policy, automaton, events, world) to ``path`` so that a
        robot's process can :meth:`load` it without solving again.  The file is a
        pickle: load only files you wrote.  Refuses to replace a file unless
        ``overwrite``."""
        out = files.writable_path(path, overwrite=overwrite)
        with files.replacing(out, "wb") as handle:
            pickle.dump((_SAVE_FORMAT, self), handle, protocol=pickle.HIGHEST_PROTOCOL)
        return out

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> Controller:
        """A controller written by :meth:`save`, reset to step 0.  ``ValueError`` if the
        file is not one."""
        source = Path(path)
        try:
            with source.open("rb") as handle:
                tag, controller = pickle.load(handle)
        except (pickle.UnpicklingError, EOFError, ValueError, TypeError) as exc:
            raise ValueError(f"{source}: not a saved controller ({exc})") from None
        if tag != _SAVE_FORMAT or not isinstance(controller, cls):
            raise ValueError(f"{source}: not a saved controller")
        controller.reset()
        return controller

    def act(self, observation: Observation) -> str | None:
        """The action to take in ``observation.state``; ``None`` once the task is decided."""
        dta = self.sta.dta
        label = self.game.propositions(observation.state) | observation.events
        if self._state is None:
            if observation.events:
                raise ValueError(
                    f"step 0: no event can have happened yet, got {sorted(observation.events)}"
                )
            q, pending, clock = dta.step(dta.initial, label), self.sta.events, 0
        else:
            q0, pending0, clock0 = self._state
            unknown = observation.events - self.sta.events
            if unknown:
                raise ValueError(f"unknown events observed: {sorted(unknown)}")
            again = observation.events - pending0
            if again:
                raise ValueError(f"events observed a second time: {sorted(again)}")
            q = dta.step(q0, label)
            pending = pending0 - observation.events
            step = self.sta.advance(pending, clock0)
            clock = step.clock
            self.beyond_model = self.beyond_model or step.truncated
        self._state = (q, pending, clock)
        self.steps += 1
        if dta.is_accepting(q):
            self.status = RunStatus.ACCEPTED
            return None
        if dta.is_rejecting(q):
            self.status = RunStatus.REJECTED
            return None
        i = self._position(ProductState(observation.state, q, pending, clock))
        if i is not None and self.hopeless is not None and self.hopeless[i]:
            self.status = RunStatus.REJECTED
            return None
        if i is None or self.policy[i] < 0:
            # Not a state of the model: the value there is 0 (it was never reached by the
            # product construction, or it cannot reach the target); any action will do.
            return self.game.actions(observation.state)[0]
        return self.mdp.action_name(int(self.policy[i]))
