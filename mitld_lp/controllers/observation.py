"""What the robot tells its controller after each step, and how the task stands.

    controller.reset()
    action = controller.act(Observation(state=s0))                    # step 0
    action = controller.act(Observation(state=s1, events={"b1"}))     # bus 1 came
    action = controller.act(Observation(state=s2, reports={"b2"}))    # the camera saw b2

One :class:`Observation` for every controller: the world ``state`` the robot is in, the
``events`` it saw happen in the step that led there, and the ``reports`` its sensors
gave in that step (:mod:`mitld_lp.sensing`: a sensor that misses events reports some of
them, possibly late).  A controller synthesised without such sensors reads the events
and refuses reports; one that acts on sensor reports reads the reports, and the events
that have no sensor from either field (a perfect sensor reports an event the step it
happens), and refuses a sensed event given as seen.  Imports the standard library only.
"""

from __future__ import annotations

import enum
from collections.abc import Hashable
from dataclasses import dataclass
from typing import Any

__all__ = ["Observation", "RunStatus"]


class RunStatus(enum.Enum):
    RUNNING = "running"
    ACCEPTED = "accepted"  # the task is satisfied
    REJECTED = "rejected"  # the task can no longer be satisfied


def _names(value: Any, field: str) -> frozenset[str]:
    """``value`` as a frozenset of event names; ``TypeError`` naming ``field``."""
    if isinstance(value, str | bytes):
        raise TypeError(
            f"Observation.{field}: expected a set of event names, got the string "
            f"{value!r}; write {field}={{{value!r}}} for that one event")
    if not isinstance(value, frozenset):
        try:
            value = frozenset(value)
        except TypeError:
            raise TypeError(f"Observation.{field}: expected a set of event names, got "
                            f"{type(value).__name__}") from None
    for e in value:
        if not isinstance(e, str):
            raise TypeError(f"Observation.{field}: an event name is a string, got {e!r}")
    return value


@dataclass(frozen=True, slots=True)
class Observation:
    """What the robot sees after a step: the world ``state`` it is in (hashable), the
    ``events`` it saw happen in the step that led there and the ``reports`` its sensors
    gave in that step (none at step 0).

    ``events`` and ``reports`` are any collections of event names (stored as
    frozensets).  A bare string is refused with ``TypeError``: ``events="b1"`` would
    otherwise read as the events ``"b"`` and ``"1"``; write ``events={"b1"}``.
    """

    state: Hashable
    events: frozenset[str] = frozenset()
    reports: frozenset[str] = frozenset()

    def __post_init__(self) -> None:
        try:
            hash(self.state)
        except TypeError:
            raise TypeError(
                f"Observation.state: a world state is hashable, got {type(self.state).__name__}"
            ) from None
        object.__setattr__(self, "events", _names(self.events, "events"))
        object.__setattr__(self, "reports", _names(self.reports, "reports"))
