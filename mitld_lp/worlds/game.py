"""The robot's world: the paper's two-player turn-based probabilistic game.

The paper (section "Problem formulation") models the interaction as a game
``G = <S u S x A, A u 2^U, P, L, s0, AP>``: at a state ``s`` the robot picks an action
``a``; at ``(s, a)`` the environment picks the set ``e`` of external events that happen
in this step (a subset of those that have not happened yet); then the next state is
drawn from ``P((s, a), e)``.  The labelling of a state is its robot propositions plus
the events of the step that led into it.

This module fixes what a *user* supplies for a world, and leaves to the product
construction what the formula decides:

* the set ``U`` of events, the record of which have already happened (the paper's ``Y``)
  and their distributions come from the specification, so a :class:`Game` never tracks
  them; it only receives the events of the current step in :meth:`Game.successors`
  (a world whose dynamics ignore the events ignores the argument);
* :meth:`Game.propositions` gives only the robot propositions of a state; the product
  adds the step's events to form the paper's label ``L(s')``.

Implement :class:`Game` for any world (it is a structural protocol, no base class is
needed), say which events its moves react to (:class:`WorldMembers`), use
:class:`ExplicitGame` for small worlds written as tables, and run :func:`check_game` on
a new implementation before trusting it.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Hashable, Iterable, Mapping
from collections.abc import Set as AbstractSet
from dataclasses import dataclass, field, fields
from itertools import combinations
from types import MappingProxyType
from typing import Any, Generic, Protocol, TypeVar, cast, runtime_checkable

from mitld_lp.worlds.successors import PROBABILITY_TOLERANCE, is_real, place

__all__ = [
    "Game",
    "GameError",
    "ExplicitGame",
    "GameCheck",
    "check_game",
    "PROBABILITY_TOLERANCE",
    "WorldMembers",
    "world_members",
]

S = TypeVar("S", bound=Hashable)

Distribution = tuple[tuple[Any, float], ...]
_NO_PROPS: frozenset[str] = frozenset()


class GameError(ValueError):
    """A game violates the contract of :class:`Game` (named state and action)."""


@runtime_checkable
class Game(Protocol[S]):
    """A two-player turn-based probabilistic game, as the product construction reads it.

    Attributes:
        initial: the initial state ``s0`` (hashable).
        proposition_names: every robot proposition any state may carry; a specification's
            propositions must be among these or be its external events.

    The robot moves first (:meth:`actions`), then the environment chooses the events of
    the step, then the world moves (:meth:`successors`).

    Beyond these members a world says which events its moves react to, and may say
    more: the members of :class:`WorldMembers`, read by :func:`world_members`.
    """

    @property
    def initial(self) -> S: ...

    @property
    def proposition_names(self) -> frozenset[str]: ...

    def actions(self, state: S) -> tuple[str, ...]:
        """The robot's enabled actions at ``state``: non-empty, distinct names."""
        ...

    def successors(
        self, state: S, action: str, events: frozenset[str]
    ) -> tuple[tuple[S, float], ...]:
        """``P((state, action), events)``: pairs ``(next_state, probability)``, each
        probability in (0, 1], distinct next states, total 1.  ``events`` is the set of
        external events the environment chose in this step."""
        ...

    def propositions(self, state: S) -> frozenset[str]:
        """The robot propositions true at ``state`` (a subset of ``proposition_names``)."""
        ...


# --------------------------------------------------------------------------- members


@dataclass(frozen=True, slots=True)
class WorldMembers:
    """The members a world declares beyond :class:`Game`, with their defaults.

    Attributes:
        event_names: the events whose occurrence changes the world's moves (a frozenset
            of names).  A specification must give each a law, or it would silently never
            happen.  Required, unless ``ignores_events`` is true (then empty).
        ignores_events: the moves never depend on the step's events; the product asks
            :meth:`Game.successors` once per (state, action) instead of once per event
            outcome.  Default false.
        n_states: how many states the world has (a non-negative int), so that the
            product's size is bounded before it is built
            (:func:`mitld_lp.product.estimate_size`).  Default None: unknown.
    """

    event_names: frozenset[str] = frozenset()
    ignores_events: bool = False
    n_states: int | None = None


_DEFAULT = WorldMembers()
_ABSENT = object()
_GAME_MEMBERS = "initial, proposition_names, actions, successors, propositions"


def _public_names(world: object) -> list[str]:
    return [n for n in dir(world) if not n.startswith("_")]


def _member_values(world: object) -> dict[str, object]:
    """The members of :class:`WorldMembers` that ``world`` has.  A public name of the
    world that is close to a member it lacks (``ignore_events``) is refused as a
    misspelling: a misspelt member would otherwise silently take its default."""
    given: dict[str, object] = {}
    names = _public_names(world)
    for member in (f.name for f in fields(WorldMembers)):
        value = getattr(world, member, _ABSENT)  # the one place a member is looked up
        if value is not _ABSENT:
            given[member] = value
            continue
        near = difflib.get_close_matches(member, names, n=1, cutoff=0.9)
        if near:
            raise GameError(
                f"{type(world).__name__}.{near[0]} is not a member of a world; did you mean "
                f"{member}? (the members are listed in docs/worlds.md)"
            )
    return given


def _event_hint(world: object) -> str:
    """`` (Kind.events = ['door'] is not a member of a world)`` when the world has a
    public name with ``event`` in it (a misspelt ``event_names``), else empty."""
    near = [n for n in _public_names(world) if "event" in n.lower()]
    if not near:
        return ""
    value = getattr(world, near[0])
    shown = ""
    names = isinstance(value, AbstractSet) and all(isinstance(e, str) for e in value)
    if names and len(value) <= 5:
        shown = f" = {sorted(value)}"
    return f" ({type(world).__name__}.{near[0]}{shown} is not a member of a world)"


def world_members(world: object) -> WorldMembers:
    """The :class:`WorldMembers` of ``world``, checked: a :class:`Game`; ``event_names``
    a set of names, given unless ``ignores_events`` is true (and then empty);
    ``ignores_events`` a bool; ``n_states`` a non-negative int.  Raises
    :class:`GameError` naming the member."""
    kind = type(world).__name__
    if not isinstance(world, Game):
        raise GameError(f"must implement the Game protocol ({_GAME_MEMBERS}), got {kind}")
    given = _member_values(world)
    ignores = given.get("ignores_events", _DEFAULT.ignores_events)
    if not isinstance(ignores, bool):
        raise GameError(f"{kind}.ignores_events must be True or False, got {ignores!r}")
    events = given.get("event_names", _ABSENT)
    if events is _ABSENT:
        if not ignores:
            hint = _event_hint(world)
            raise GameError(
                f"{kind} does not say which events its moves react to{hint}: give it "
                "event_names (a frozenset of event names, frozenset() if none) or "
                "ignores_events = True"
            )
        events = _DEFAULT.event_names
    if not isinstance(events, AbstractSet) or not all(isinstance(e, str) for e in events):
        raise GameError(f"{kind}.event_names must be a frozenset of names, got {events!r}")
    if ignores and events:
        raise GameError(
            f"{kind} says ignores_events = True but reacts to events {sorted(events)} "
            "(event_names)"
        )
    n = given.get("n_states", _DEFAULT.n_states)
    if n is not None and (not isinstance(n, int) or isinstance(n, bool) or n < 0):
        raise GameError(f"{kind}.n_states must be a non-negative int or None, got {n!r}")
    return WorldMembers(frozenset(events), ignores, n)


# --------------------------------------------------------------------------- validation


def _freeze_distribution(
    value: Mapping[Any, float] | Iterable[tuple[Any, float]], where: str
) -> Distribution:
    """Validate one successor distribution and return it as a tuple of pairs.

    Accepts a mapping ``next -> probability`` or pairs; repeated next states are merged
    and exact zeros dropped.  Raises :class:`GameError` naming ``where``."""
    pairs = value.items() if isinstance(value, Mapping) else value
    merged: dict[Any, float] = {}
    for item in pairs:
        try:
            nxt, p = item
        except (TypeError, ValueError):
            raise GameError(f"{where}: expected (next_state, probability), got {item!r}") from None
        if not is_real(p) or not math.isfinite(float(p)):
            raise GameError(f"{where}: probability of {nxt!r} must be a number, got {p!r}")
        p = float(p)
        if p < 0.0 or p > 1.0:
            raise GameError(f"{where}: probability of {nxt!r} must be in [0, 1], got {p!r}")
        try:
            merged[nxt] = merged.get(nxt, 0.0) + p
        except TypeError:
            raise GameError(f"{where}: next state {nxt!r} is not hashable") from None
    out = tuple((s, p) for s, p in merged.items() if p > 0.0)
    total = math.fsum(p for _, p in out)
    if not out or abs(total - 1.0) > PROBABILITY_TOLERANCE:
        raise GameError(f"{where}: probabilities must sum to 1, got {total!r}")
    return out


# --------------------------------------------------------------------------- explicit game


@dataclass(frozen=True, eq=False)
class ExplicitGame(Generic[S]):
    """A game given by explicit tables; for tests and small worlds.

    Attributes:
        initial: the initial state.
        transitions: ``state -> action -> distribution``, where a distribution is a
            mapping ``next_state -> probability`` (or an iterable of pairs).  Used for
            every event set that ``event_transitions`` does not list.  Every state that
            appears (as a key or as a successor) must have at least one action.
        labels: ``state -> robot propositions``; a state not listed has none.
        proposition_names: all robot propositions; ``None`` means the union of
            ``labels``.  When given, it must contain every label.
        event_transitions: optional overrides ``(state, action, events) -> distribution``,
            used when the environment's events of the step are exactly ``events``.

    On construction the tables are validated (probabilities in [0, 1], totals 1 within
    :data:`PROBABILITY_TOLERANCE`, every successor has actions) and frozen into
    read-only mappings whose distributions are tuples of pairs.  Two games are equal
    when their tables are.
    """

    initial: S
    transitions: Mapping[S, Mapping[str, Any]]
    labels: Mapping[S, Iterable[str]] = field(default_factory=dict)
    proposition_names: frozenset[str] = None  # type: ignore[assignment]
    event_transitions: Mapping[tuple[S, str, frozenset[str]], Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        table: dict[Any, Mapping[str, Distribution]] = {}
        for state, acts in self.transitions.items():
            if not isinstance(acts, Mapping) or not acts:
                raise GameError(
                    f"state {state!r}: needs a non-empty mapping action -> "
                    f"distribution, got {acts!r}"
                )
            row: dict[str, Distribution] = {}
            for action, dist in acts.items():
                if not isinstance(action, str):
                    raise GameError(f"state {state!r}: action {action!r} is not a string")
                row[action] = _freeze_distribution(dist, f"state {state!r}, action {action!r}")
            table[state] = MappingProxyType(row)
        if self.initial not in table:
            raise GameError(f"initial state {self.initial!r} has no transitions")

        overrides: dict[tuple[Any, str, frozenset[str]], Distribution] = {}
        for key, dist in self.event_transitions.items():
            try:
                state, action, events = key
            except (TypeError, ValueError):
                raise GameError(
                    f"event_transitions: key must be (state, action, events), got {key!r}"
                ) from None
            if state not in table or action not in table[state]:
                raise GameError(
                    f"event_transitions: state {state!r}, action {action!r} is not in transitions"
                )
            if isinstance(events, str) or not all(isinstance(e, str) for e in events):
                raise GameError(f"event_transitions: events must be a set of names, got {events!r}")
            events = frozenset(events)
            where = f"state {state!r}, action {action!r}, events {sorted(events)}"
            overrides[state, action, events] = _freeze_distribution(dist, where)

        rows = [((s, a), d) for s, row in table.items() for a, d in row.items()]
        rows += [((s, a), d) for (s, a, _), d in overrides.items()]
        for (state, action), dist in rows:
            for nxt, _ in dist:
                if nxt not in table:
                    raise GameError(
                        f"state {state!r}, action {action!r}: successor {nxt!r} has no transitions"
                    )

        labels: dict[Any, frozenset[str]] = {}
        for state, props in self.labels.items():
            if isinstance(props, str) or not all(isinstance(p, str) for p in props):
                raise GameError(
                    f"labels: state {state!r} needs a set of proposition names, got {props!r}"
                )
            labels[state] = frozenset(props)
        used = frozenset().union(*labels.values())
        if self.proposition_names is None:
            names = used
        else:
            names = frozenset(self.proposition_names)
            if not used <= names:
                raise GameError(
                    f"labels use propositions {sorted(used - names)} that are not "
                    "in proposition_names"
                )

        object.__setattr__(self, "transitions", MappingProxyType(table))
        object.__setattr__(self, "labels", MappingProxyType(labels))
        object.__setattr__(self, "proposition_names", names)
        object.__setattr__(self, "event_transitions", MappingProxyType(overrides))

    def __reduce__(self) -> tuple[Any, ...]:
        # The frozen tables are read-only views (which do not pickle): rebuild the game
        # from plain copies of them, validating again.
        return (
            ExplicitGame,
            (
                self.initial,
                {s: dict(row) for s, row in self.transitions.items()},
                dict(self.labels),
                self.proposition_names,
                dict(self.event_transitions),
            ),
        )

    def _key(self) -> tuple[Any, ...]:
        return (
            self.initial,
            frozenset((s, frozenset(row.items())) for s, row in self.transitions.items()),
            frozenset((s, p) for s, p in self.labels.items() if p),
            self.proposition_names,
            frozenset(self.event_transitions.items()),
        )

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, ExplicitGame):
            return NotImplemented
        return self._key() == other._key()

    def __hash__(self) -> int:
        return hash(self._key())

    @property
    def states(self) -> tuple[S, ...]:
        """Every state of the tables, in the order given."""
        return tuple(self.transitions)

    @property
    def n_states(self) -> int:
        """The number of states of the tables."""
        return len(self.transitions)

    @property
    def event_names(self) -> frozenset[str]:
        """The events ``event_transitions`` reacts to."""
        return frozenset().union(*(events for _, _, events in self.event_transitions))

    def actions(self, state: S) -> tuple[str, ...]:
        """The actions listed for ``state``, in table order."""
        try:
            return tuple(self.transitions[state])
        except KeyError:
            raise GameError(f"unknown state {state!r}") from None

    def successors(
        self, state: S, action: str, events: frozenset[str]
    ) -> tuple[tuple[S, float], ...]:
        """The override for exactly ``events`` if there is one, else the default row."""
        override = self.event_transitions.get((state, action, events))
        if override is not None:
            return override
        try:
            return self.transitions[state][action]
        except KeyError:
            raise GameError(f"state {state!r} has no action {action!r}") from None

    def propositions(self, state: S) -> frozenset[str]:
        """The labels of ``state`` (empty if not listed)."""
        return cast(frozenset[str], self.labels.get(state, _NO_PROPS))


# --------------------------------------------------------------------------- checking


@dataclass(frozen=True, slots=True)
class GameCheck:
    """What :func:`check_game` explored.

    Attributes:
        states: number of reachable states.
        choices: number of (state, action) pairs.
        transitions: number of (state, action, events, next state) entries.
        actions: every action name seen.
        propositions: every robot proposition seen on a reachable state.
    """

    states: int
    choices: int
    transitions: int
    actions: frozenset[str]
    propositions: frozenset[str]


def _subsets(events: frozenset[str]) -> tuple[frozenset[str], ...]:
    items = sorted(events)
    return tuple(frozenset(c) for r in range(len(items) + 1) for c in combinations(items, r))


def _check_labels(game: Game[Any], state: Any, names: frozenset[str]) -> frozenset[str]:
    """``propositions(state)``: a frozenset within ``names``."""
    props = game.propositions(state)
    if not isinstance(props, frozenset):
        raise GameError(f"state {state!r}: propositions must be a frozenset, got {props!r}")
    if not props <= names:
        raise GameError(
            f"state {state!r}: propositions {sorted(props - names)} are not in "
            "proposition_names"
        )
    return props


def _check_actions(game: Game[Any], state: Any) -> tuple[str, ...]:
    """``actions(state)``: a non-empty tuple of distinct strings."""
    acts = game.actions(state)
    if not isinstance(acts, tuple) or not acts:
        raise GameError(f"state {state!r}: actions must be a non-empty tuple, got {acts!r}")
    if not all(isinstance(a, str) for a in acts) or len(set(acts)) != len(acts):
        raise GameError(f"state {state!r}: actions must be distinct strings, got {acts!r}")
    return acts


def _check_distribution(dist: Any, where: str, tolerance: float) -> tuple[Any, ...]:
    """One ``successors`` answer: a non-empty tuple of ``(next, p)`` pairs with distinct
    hashable next states and ``p`` in (0, 1] summing to 1 within ``tolerance``.
    Returns the next states in order."""
    if not isinstance(dist, tuple) or not dist:
        raise GameError(f"{where}: successors must be a non-empty tuple, got {dist!r}")
    nexts: dict[Any, None] = {}
    total = 0.0
    for item in dist:
        if not isinstance(item, tuple) or len(item) != 2:
            raise GameError(f"{where}: expected (next_state, probability), got {item!r}")
        nxt, p = item
        if not is_real(p) or not (0.0 < float(p) <= 1.0):
            raise GameError(f"{where}: probability of {nxt!r} must be in (0, 1], got {p!r}")
        try:
            fresh = nxt not in nexts
        except TypeError:
            raise GameError(f"{where}: next state {nxt!r} is not hashable") from None
        if not fresh:
            raise GameError(f"{where}: next state {nxt!r} is listed twice")
        nexts[nxt] = None
        total += float(p)
    if abs(total - 1.0) > tolerance:
        raise GameError(f"{where}: probabilities sum to {total!r}, not 1")
    return tuple(nexts)


def check_game(
    game: Game[Any],
    events: Iterable[str] = (),
    max_states: int = 1_000_000,
    tolerance: float = PROBABILITY_TOLERANCE,
) -> GameCheck:
    """Explore the states reachable from ``game.initial`` and check the game contract.

    Every reachable state is expanded under every action and every subset of ``events``
    (the environment may choose any of them; pass the specification's events to check
    event-dependent dynamics).  Checked: the initial state and successors are hashable;
    ``actions`` is a non-empty tuple of distinct strings; each successor distribution
    is non-empty, has distinct next states and probabilities in (0, 1] summing to 1
    within ``tolerance``; ``propositions`` is a frozenset within ``proposition_names``.

    Raises :class:`GameError` naming the state (and action and events) at fault, or
    when more than ``max_states`` states are reachable.
    """
    names = game.proposition_names
    if not isinstance(names, frozenset) or not all(isinstance(n, str) for n in names):
        raise GameError(f"proposition_names must be a frozenset of strings, got {names!r}")
    event_sets = _subsets(frozenset(events))
    start = game.initial
    try:
        hash(start)
    except TypeError:
        raise GameError(f"initial state {start!r} is not hashable") from None
    seen: set[Any] = {start}
    stack = [start]
    choices = transitions = 0
    all_actions: set[str] = set()
    all_props: set[str] = set()
    while stack:
        state = stack.pop()
        all_props |= _check_labels(game, state, names)
        acts = _check_actions(game, state)
        all_actions.update(acts)
        for action in acts:
            choices += 1
            for ev in event_sets:
                where = place(state, action, ev)
                nexts = _check_distribution(game.successors(state, action, ev), where, tolerance)
                transitions += len(nexts)
                for nxt in nexts:
                    if nxt not in seen:
                        if len(seen) >= max_states:
                            raise GameError(
                                f"more than {max_states} reachable states (reached {nxt!r})"
                            )
                        seen.add(nxt)
                        stack.append(nxt)
    return GameCheck(
        states=len(seen),
        choices=choices,
        transitions=transitions,
        actions=frozenset(all_actions),
        propositions=frozenset(all_props),
    )
