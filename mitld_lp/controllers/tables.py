"""A saved controller's tables and their answers, with NumPy alone: :class:`SavedPlan`
(a deterministic or randomised controller: the task's automaton, the clock rule and the
policy over product states) and :class:`SensedPlan` (a controller that acts on sensor
reports: its information states and their moves), each a plan the one step rule
(:class:`~mitld_lp.controllers.stepper.Stepper`) runs.  The file they are saved in is
:mod:`mitld_lp.controllers.format`; :mod:`mitld_lp.controllers.reader` reads it."""

from __future__ import annotations

from collections.abc import Hashable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from mitld_lp.controllers.format import (
    ACCEPTED,
    KEEP,
    REJECTED,
    UNDECIDED,
    Diagram,
    quoted,
    to_bytes,
)
from mitld_lp.controllers.stepper import DECIDED, AutomatonMemory, Decision

__all__ = ["BEYOND", "MixedSensedPlan", "SavedPlan", "SensedPlan", "Obs", "advance", "key",
           "unknown_state"]


def unknown_state(state: Hashable) -> ValueError:
    """The error for a world state a saved controller does not list."""
    return ValueError(f"world state {quoted(state)}: not a state the saved controller knows "
                      "(the world it was saved from does not reach it)")


# --------------------------------------------------------------------------- the automaton's


def _walk(d: Diagram, letter: frozenset[str] | set[str]) -> int:
    while not isinstance(d, int):
        p, low, high = d
        d = high if p in letter else low
    return d


def advance(pending: Iterable[str], clock: int, caps: Mapping[str, int],
            truncations: Mapping[str, int]) -> tuple[int, bool]:
    """The clock one step after ``clock`` while ``pending`` are pending, and whether the
    step crossed a truncation point: the rule of
    :func:`mitld_lp.automata.sta.advance_clock`, restated here without its imports
    (tests/test_runtime.py checks the two agree)."""
    t = clock + 1
    crossed = any((T := truncations.get(a)) is not None and t >= T for a in pending)
    return min(t, max((caps[a] for a in pending), default=0)), crossed


def key(g: int, q: int, pending: int, clock: int, n_q: int, n_events: int, n_clock: int) -> int:
    """The key of product state ``(g, q, pending mask, clock)``; ``clock < n_clock``."""
    return ((g * n_q + q) << n_events | pending) * n_clock + clock


@dataclass(frozen=True, slots=True, eq=False)
class SavedPlan(AutomatonMemory):
    """What a deterministic or randomised controller needs to run, as tables
    (:mod:`mitld_lp.controllers.format`).

    ``verdicts[q]``: per automaton state, the verdict of each component (the task
    first); a deterministic controller's automaton has one component, decided in its
    accepting and rejecting states.  Per product state (``keys``, sorted): a
    deterministic controller's action (``policy``, -1: none) and ``hopeless`` flag; a
    randomised one's choices ``choices[offsets[i]:offsets[i + 1]]`` with their
    ``weights`` and ``inside`` flags, its ``stay`` probability and ``charged`` flag.
    ``variables``: the world's variable names when its states are tuples of them (a
    PRISM world), else None.
    """

    kind: str
    atoms: tuple[str, ...]
    events: frozenset[str]
    actions: tuple[str, ...]
    initial: int
    verdicts: tuple[tuple[int, ...], ...]
    delta: tuple[Diagram, ...]
    caps: Mapping[str, int]
    truncations: Mapping[str, int]
    states: tuple[Hashable, ...]
    props: np.ndarray
    fallback_action: np.ndarray
    keys: np.ndarray
    tables: Mapping[str, np.ndarray]
    variables: tuple[str, ...] | None = None
    _index: dict[Hashable, int] = field(default_factory=dict, repr=False)
    _event_bit: dict[str, int] = field(default_factory=dict, repr=False)
    _letters: dict[int, frozenset[str]] = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        self._index.update((s, g) for g, s in enumerate(self.states))
        self._event_bit.update((e, 1 << i) for i, e in enumerate(sorted(self.events)))
        for a in (self.props, self.fallback_action, self.keys, *self.tables.values()):
            a.flags.writeable = False

    @property
    def randomised(self) -> bool:
        return self.kind == "randomised"

    @property
    def accepting(self) -> int | None:
        """The automaton state where the task has accepted (deterministic plans)."""
        return next((q for q, v in enumerate(self.verdicts) if v == (ACCEPTED,)), None)

    @property
    def rejecting(self) -> int | None:
        return next((q for q, v in enumerate(self.verdicts) if v == (REJECTED,)), None)

    @property
    def n_clock(self) -> int:
        return max(self.caps.values(), default=0) + 1

    def key(self, g: int, q: int, pending: Iterable[str], clock: int) -> int:
        """The key of the product state ``(g, q, pending, clock)``."""
        mask = sum(self._event_bit[e] for e in pending)
        return key(g, q, mask, clock, len(self.delta), len(self.events), self.n_clock)

    def number(self, state: Hashable) -> int:
        """The number of world state ``state``; ``ValueError`` if the plan lacks it."""
        g = self._index.get(state)
        if g is None:
            raise unknown_state(state)
        return g

    def read(self, q: int, state: Hashable, events: frozenset[str]) -> int:
        """The automaton state after ``q`` reads the label of ``state`` plus ``events``."""
        mask = int(self.props[self.number(state)])
        props = self._letters.get(mask)
        if props is None:
            props = self._letters[mask] = frozenset(
                a for i, a in enumerate(self.atoms) if mask >> i & 1)
        return _walk(self.delta[q], props | events)

    def advance(self, pending: frozenset[str], clock: int) -> tuple[int, bool]:
        return advance(pending, clock, self.caps, self.truncations)

    def position(self, state: Hashable, q: int, pending: Iterable[str], clock: int) -> int:
        """The row of the product state in the tables, -1 when it has none."""
        k = self.key(self.number(state), q, pending, clock)
        at = int(np.searchsorted(self.keys, k))
        return at if at < self.keys.size and int(self.keys[at]) == k else -1

    def decide(self, state: Hashable, q: int, pending: frozenset[str], clock: int) -> Decision:
        at = self.position(state, q, pending, clock)
        t = self.tables
        if at < 0:
            return Decision(())
        if not self.randomised:
            a = int(t["policy"][at])
            return Decision(() if a < 0 else (self.actions[a],), lost=bool(t["hopeless"][at]))
        lo, hi = int(t["offsets"][at]), int(t["offsets"][at + 1])
        names = tuple(KEEP if c < 0 else self.actions[c] for c in t["choices"][lo:hi].tolist())
        inside = tuple(n for n, flag in zip(names, t["inside"][lo:hi], strict=True) if flag)
        keep = tuple(bool(k) for k in t["keep"][lo:hi])
        kept = tuple(n for n, flag in zip(names, t["kept"][lo:hi], strict=True) if flag)
        return Decision(names, np.asarray(t["weights"][lo:hi]), float(t["stay"][at]), inside,
                        charged=bool(t["charged"][at]), keep=keep if any(keep) else (),
                        kept=kept)

    def lookup(self, state: Hashable, q: int, pending: frozenset[str],
               clock: int) -> tuple[str | None, bool]:
        """A deterministic plan's action at the product state (None: no record, or no
        policy there) and whether the task is lost there."""
        d = self.decide(state, q, pending, clock)
        return (d.actions[0] if len(d.actions) == 1 and d.weights is None else None), d.lost

    def fallback(self, state: Hashable) -> str:
        return self.actions[int(self.fallback_action[self.number(state)])]

    def to_bytes(self) -> bytes:
        """The ``.npz`` archive of these tables."""
        return to_bytes(self)


# --------------------------------------------------------------------------- sensed

Obs = tuple[Hashable, frozenset[str], frozenset[str]]
"""An observation as a sensed plan looks it up: the world state, the events without a
sensor seen, and the sensed events reported."""

BEYOND = -1
"""A sensed plan's memory once an observation came that its model gives probability 0
(an event past its truncation point): it then plays each world state's first action."""

_END_VERDICTS = {"target": (ACCEPTED,), "sink": (REJECTED,), "truncated": (DECIDED,)}


@dataclass(frozen=True, slots=True, eq=False)
class SensedPlan:
    """What a controller that acts on sensor reports needs to run: per information state
    (what the robot knows, :mod:`mitld_lp.sensing.belief`) its action (``actions``, None:
    nothing is left to do) and, per state and action taken, the next information state
    of each observation (``moves``), or an end when nothing undecided is left
    (``"target"``: every hypothesis left accepted; ``"sink"``: every one rejected;
    ``"truncated"``: decided, the robot cannot tell which).

    The memory is the information state (``BEYOND`` past the model, an end once
    decided).  The reports of the ``ignored`` sensed events (they come too late to
    matter) are dropped.  A plan made by the synthesis has its ``game`` (a world state's
    first action is the world's); a saved one lists its world ``states`` with their
    first actions (``first``) instead, and refuses a state it does not list."""

    kind: ClassVar[str] = "sensed"

    initial: int | str
    actions: tuple[str | None, ...]
    moves: Mapping[tuple[int, str], Mapping[Obs, int | str]]
    sensed: frozenset[str]
    events: frozenset[str]
    ignored: frozenset[str] = frozenset()
    game: Any = None
    first: Mapping[Hashable, str] = field(default_factory=dict)
    variables: tuple[str, ...] | None = None

    @property
    def randomised(self) -> bool:
        return False

    @property
    def states(self) -> tuple[Hashable, ...]:
        """The world states the saved plan lists (a synthesis's plan: none)."""
        return tuple(self.first)

    def fallback(self, state: Hashable) -> str:
        """The world state's first action (the world's, else the saved table's)."""
        if self.game is not None:
            return str(next(iter(self.game.actions(state))))
        action = self.first.get(state)
        if action is None:
            raise unknown_state(state)
        return action

    def _check(self, state: Hashable) -> None:
        if self.game is None and state not in self.first:
            raise unknown_state(state)

    def observed(self, events: frozenset[str], reports: frozenset[str]) -> frozenset[str]:
        """What the robot learnt in the step: the reports, and the events without a
        sensor (either field); a sensed event given as seen is refused."""
        hidden = events & self.sensed
        if hidden:
            raise ValueError(
                f"Observation.events: {sorted(hidden)}: the robot learns of a sensed event "
                "through its sensor only; give the sensor's report as reports")
        return events | reports

    def start(self, state: Hashable) -> int | str:
        self._check(state)
        return self.initial

    def follow(self, memory: int | str, state: Hashable, seen: frozenset[str],
               last: str | None) -> tuple[int | str, bool]:
        self._check(state)
        if isinstance(memory, str) or memory == BEYOND:
            return memory, False
        seen = seen - self.ignored
        obs = (state, seen - self.sensed, seen & self.sensed)
        nxt = self.moves.get((memory, last or ""), {}).get(obs)
        if nxt is None:  # the model gives this observation probability 0
            return BEYOND, True
        return nxt, False

    def verdicts_at(self, memory: int | str | None) -> tuple[int, ...]:
        return _END_VERDICTS[memory] if isinstance(memory, str) else (UNDECIDED,)

    def decision(self, state: Hashable, memory: int | str) -> Decision:
        a = None if isinstance(memory, str) or memory == BEYOND else self.actions[memory]
        return Decision(() if a is None else (a,))

    def played(self, memory: int) -> frozenset[str]:
        """The actions the controller may take in information state ``memory`` (whose
        moves a file keeps)."""
        a = self.actions[memory]
        return frozenset() if a is None else frozenset({a})

    def to_bytes(self) -> bytes:
        """The ``.npz`` archive of these tables (a saved plan's: it lists its world
        states)."""
        assert self.game is None, "a synthesis's plan is tabulated first"
        return to_bytes(self)


@dataclass(frozen=True, slots=True, eq=False)
class MixedSensedPlan(SensedPlan):
    """A :class:`SensedPlan` whose decision per information state is randomised
    (``decisions``, None where nothing is left to do): *stay* with its probability (then
    the actions ``inside`` the end component, uniformly, for ever), else an action by
    its weights (the ``sensed-constrained`` route's controller; ``actions`` unused)."""

    kind: ClassVar[str] = "sensed-randomised"

    decisions: tuple[Decision | None, ...] = ()

    @property
    def randomised(self) -> bool:
        return True

    def decision(self, state: Hashable, memory: int | str) -> Decision:
        if isinstance(memory, str) or memory < 0:
            return Decision(())
        d = self.decisions[memory]
        return Decision(()) if d is None else d

    def played(self, memory: int) -> frozenset[str]:
        d = self.decisions[memory]
        return frozenset() if d is None else frozenset(d.actions) | frozenset(d.inside)
