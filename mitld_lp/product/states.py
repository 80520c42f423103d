"""The records of a product's states and the one code of a state as an integer.

During the construction a product state is an int64, its *key*: for an ordinary state
``(g, q, sid)`` -- the game state's number, the automaton state, the situation's number
(pending events and clock) -- the key ``(g * n_q + q) * n_sit + sid`` (:class:`KeyCodec`,
the only place that formula is written); an absorbing state is a negative code
(:data:`CODE`).  :class:`ProductStates` makes a state's record (:class:`ProductState`
or an :class:`Absorbing` member) from its key when asked.
"""

from __future__ import annotations

import enum
from collections.abc import Hashable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, overload

import numpy as np

from mitld_lp.mdp import MDP
from mitld_lp.util.arrays import unique

__all__ = [
    "Absorbing",
    "ProductState",
    "ProductStates",
    "KeyCodec",
    "CODE",
    "ABSORBING_OF_CODE",
    "MASK_OF_CODE",
    "component_counts",
]


class Absorbing(enum.StrEnum):
    """The three absorbing product states (each a single self-loop in the MDP).

    A ``StrEnum`` so that the states print as their DRN labels (``target``, ...).
    """

    TARGET = "target"  # the automaton accepted
    SINK = "sink"  # the automaton rejected
    TRUNCATED = "truncated"  # an event clock ran past its truncation point


@dataclass(frozen=True, slots=True)
class ProductState:
    """A non-absorbing product state.

    ``clock`` counts the steps taken, capped where no pending event's hazard changes
    any more (:meth:`mitld_lp.automata.sta.STA.advance`).
    """

    game: Hashable
    automaton: int
    pending: frozenset[str]
    clock: int


CODE: Mapping[Absorbing, int] = {Absorbing.TARGET: -1, Absorbing.SINK: -2, Absorbing.TRUNCATED: -3}
"""The key of each absorbing state (ordinary states have non-negative keys)."""
ABSORBING_OF_CODE: Mapping[int, Absorbing] = {code: a for a, code in CODE.items()}
MASK_OF_CODE: Mapping[int, int] = {-1: 1, -2: 2, -3: 3}
"""Code -> the MDP mask it sets (1 target, 2 sink, 3 truncated)."""

_KEY_BITS = 62  # keys stay below 2^62: int64 with room for the codes


@dataclass(frozen=True, slots=True)
class KeyCodec:
    """The key of an ordinary product state: ``(g * n_q + q) * n_sit + sid`` for game
    state ``g``, automaton state ``q < n_q`` and situation ``sid < n_sit``.  The methods
    take ints or integer arrays alike."""

    n_q: int
    n_sit: int

    def key(self, g: Any, q: Any, sid: Any) -> Any:
        """The key of ``(g, q, sid)``."""
        return (g * self.n_q + q) * self.n_sit + sid

    def unkey(self, keys: Any) -> tuple[Any, Any, Any]:
        """``(g, q, sid)`` of keys (non-negative: an ordinary state's).  An array is split
        with shifts and masks where a factor is a power of two (one situation, no event:
        the plain PRISM task), else by division; the same numbers either way, new arrays."""
        if not isinstance(keys, np.ndarray):
            rest, sid = divmod(keys, self.n_sit)
            g, q = divmod(rest, self.n_q)
            return g, q, sid
        rest, sid = _split(keys, self.n_sit)
        g, q = _split(rest, self.n_q)
        return g, q, sid

    def fits(self, n_games: int) -> bool:
        """Whether the keys of ``n_games`` game states stay below ``2^62``."""
        return n_games * self.n_q * self.n_sit < 1 << _KEY_BITS


def _split(keys: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """``divmod(keys, n)`` of non-negative integer ``keys``, as new arrays: a shift and a
    mask when ``n`` is a power of two (a copy and zeros when it is 1)."""
    if n == 1:
        return keys.copy(), np.zeros_like(keys)
    if n & (n - 1) == 0:
        bits = n.bit_length() - 1
        return keys >> bits, keys & (n - 1)
    quotient, remainder = np.divmod(keys, n)
    return quotient, remainder


class ProductStates(Sequence[Hashable]):
    """The records of a product's states, made on demand from their integer codes.

    Item ``i`` is a :class:`ProductState` or an :class:`Absorbing` member; a million
    records would cost more time and memory than the rest of the construction, and most
    are never looked at.  The codes are int32 when they all fit (the product's build
    narrows them), else int64.  :meth:`position` maps a record back to its state index.
    """

    __slots__ = ("_keys", "_games", "_situations", "_codec", "_sorted", "_where", "_bounds")

    def __init__(
        self,
        keys: np.ndarray,
        games: list[Hashable],
        situations: list[tuple[frozenset[str], int]],
        codec: KeyCodec,
    ) -> None:
        self._keys = keys
        self._keys.flags.writeable = False
        self._games, self._situations = games, situations
        self._codec = codec
        self._sorted: np.ndarray | None = None
        bounds = np.iinfo(keys.dtype)  # the keys are int32 where they all fit
        self._bounds = (int(bounds.min), int(bounds.max))
        self._where: tuple[dict[Hashable, int], dict[tuple[frozenset[str], int], int]] | None
        self._where = None

    def __len__(self) -> int:
        return int(self._keys.size)

    def _record(self, key: int) -> Hashable:
        if key < 0:
            return ABSORBING_OF_CODE[key]
        g, q, sid = self._codec.unkey(key)
        pending, clock = self._situations[sid]
        return ProductState(self._games[g], q, pending, clock)

    @overload
    def __getitem__(self, i: int) -> Hashable: ...
    @overload
    def __getitem__(self, i: slice) -> tuple[Hashable, ...]: ...
    def __getitem__(self, i: int | slice) -> Hashable | tuple[Hashable, ...]:
        if isinstance(i, slice):
            return tuple(self._record(k) for k in self._keys[i].tolist())
        return self._record(int(self._keys[i]))

    def __iter__(self) -> Iterator[Hashable]:
        return (self._record(k) for k in self._keys.tolist())

    def __eq__(self, other: object) -> bool:
        if isinstance(other, ProductStates | tuple | list):
            return len(self) == len(other) and all(a == b for a, b in zip(self, other, strict=True))
        return NotImplemented

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        return f"ProductStates(<{len(self)} states>)"

    def __contains__(self, state: object) -> bool:
        return self.position(state) is not None

    def index(self, state: Any, start: int = 0, stop: int | None = None) -> int:
        """The index of ``state`` (its record) in ``[start, stop)``; ValueError if none."""
        i = self.position(state)
        if i is None or i < start or (stop is not None and i >= stop):
            raise ValueError(f"{state!r} is not a state of this product")
        return i

    def distinct_factors(self) -> tuple[int, int, int, int, int]:
        """Ordinary states, and the distinct game states, automaton states, pending sets
        and clock values among them."""
        keys = self._keys[self._keys >= 0]
        g, q, sid = self._codec.unkey(keys)
        sits = [self._situations[i] for i in unique(sid).tolist()]
        return (
            int(keys.size),
            int(unique(g).size),
            int(unique(q).size),
            len({p for p, _ in sits}),
            len({c for _, c in sits}),
        )

    def automaton_states(self) -> np.ndarray:
        """``(n_states,)`` int64: the automaton state of each state, -1 for the absorbing
        ones (from the integer codes, no records made)."""
        keys = self._keys
        out = np.full(keys.size, -1, dtype=np.int64)
        ordinary = keys >= 0
        out[ordinary] = self._codec.unkey(keys[ordinary])[1]
        return out

    def position(self, state: object) -> int | None:
        """The index of the state whose record is ``state``, None if there is none."""
        if isinstance(state, Absorbing):
            key = CODE[state]
        elif isinstance(state, ProductState):
            if self._where is None:
                self._where = (
                    {s: i for i, s in enumerate(self._games)},
                    {s: i for i, s in enumerate(self._situations)},
                )
            games, sits = self._where
            g = games.get(state.game)
            sid = sits.get((state.pending, state.clock))
            if g is None or sid is None or not 0 <= state.automaton < self._codec.n_q:
                return None
            key = self._codec.key(g, state.automaton, sid)
        else:
            return None
        if not self._bounds[0] <= key <= self._bounds[1]:
            return None
        if self._sorted is None:
            self._sorted = np.argsort(self._keys, kind="stable")
        at = int(np.searchsorted(self._keys, key, sorter=self._sorted))
        if at < self._sorted.size and self._keys[self._sorted[at]] == key:
            return int(self._sorted[at])
        return None


def component_counts(mdp: MDP) -> Mapping[str, int]:
    """Sizes for people: states by kind, distinct game states, automaton states, pending
    sets and clock values among the ordinary states."""
    states = mdp.states
    if isinstance(states, ProductStates):  # from the integer codes, no records made
        distinct = states.distinct_factors()
    else:
        ordinary = [s for s in states if isinstance(s, ProductState)]
        distinct = (
            len(ordinary),
            len({s.game for s in ordinary}),
            len({s.automaton for s in ordinary}),
            len({s.pending for s in ordinary}),
            len({s.clock for s in ordinary}),
        )
    return {
        "states": mdp.n_states,
        "choices": mdp.n_choices,
        "transitions": mdp.n_transitions,
        "ordinary_states": distinct[0],
        "target_states": int(mdp.target.sum()),
        "sink_states": int(mdp.sink.sum()),
        "truncated_states": int(mdp.truncated.sum()),
        "game_states": distinct[1],
        "automaton_states": distinct[2],
        "event_situations": distinct[3],
        "clock_values": distinct[4],
    }
