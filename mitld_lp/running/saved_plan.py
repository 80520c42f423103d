"""A saved controller's tables, with NumPy alone: the format's names and members (the
file is described in :mod:`mitld_lp.running.controller_file`, read by
:mod:`mitld_lp.running.plan_reader`), the tables' answers (:class:`SavedPlan`) and the one
clock rule.  Imported by :mod:`mitld_lp.runtime` (and
through it by the full package), so it imports only the standard library and NumPy."""

from __future__ import annotations

import io
import json
import math
from collections.abc import Hashable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = [
    "ACCEPTED",
    "ControllerFileError",
    "Decision",
    "FORMAT",
    "KEEP",
    "MEMBERS",
    "READS",
    "REJECTED",
    "SavedPlan",
    "UNDECIDED",
    "VERSION",
    "advance",
    "decode_state",
    "encode_state",
    "encoded_states",
    "key",
]

FORMAT = "mitld_lp.running.controller"
VERSION = 3
"""The file format's version.  Version 1 (deterministic controllers, no world variables)
and version 2 (randomised controllers without *keep* choices) are still read; any other
version is refused by name."""
READS = (1, 2, 3)

ACCEPTED, REJECTED, UNDECIDED = 1, 0, -1
"""A component's verdict in an automaton state (the task is component 0)."""

KEEP = "keep"
"""A *keep* choice's name in a decision (told apart by :attr:`Decision.keep`)."""

Diagram = int | tuple[str, Any, Any]
"""An automaton state's transition function: a leaf (the next state) or ``(atom, low,
high)``: ``high`` when the letter holds the atom."""

_COMMON = {  # member -> dtype of its 1-D array, in every file
    "meta": np.uint8,
    "states": np.uint8,
    "props": np.int64,
    "fallback": np.int32,
    "keys": np.int64,
}
_DETERMINISTIC = {**_COMMON, "policy": np.int32, "hopeless": np.bool_}
_RANDOMISED = {**_COMMON, "offsets": np.int64, "choices": np.int32, "weights": np.float64,
               "inside": np.bool_, "stay": np.float64, "charged": np.bool_,
               "keep": np.bool_, "kept": np.bool_}
MEMBERS = {"deterministic": _DETERMINISTIC, "randomised": _RANDOMISED}
_KEEPS = ("keep", "kept")  # randomised members new in version 3 (version 2: no keeps)


def _members(kind: str, version: int) -> dict[str, Any]:
    """The members of a file of ``kind`` written in format ``version``."""
    members = MEMBERS[kind]
    if kind == "randomised" and version < 3:
        return {k: v for k, v in members.items() if k not in _KEEPS}
    return members
_QUOTE = 80  # characters of a foreign value quoted in an error


class ControllerFileError(ValueError):
    """A file that is not a controller this version of mitld_lp saved: foreign,
    damaged, truncated or of another format version.  The message names the file and
    what is wrong."""


class SensedControllerFile(ControllerFileError):
    """The file holds a controller that acts on sensor reports
    (:mod:`mitld_lp.sensing.saved`), which :func:`read_plan` does not read;
    :func:`mitld_lp.load_controller` loads it."""


class _Bad(Exception):
    """Internal: what is wrong with the file being read (becomes ControllerFileError)."""


class _Sensed(_Bad):
    """Internal: a sensed controller's archive (becomes SensedControllerFile)."""


def _printable(text: str) -> str:
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


def _clip(text: str) -> str:
    text = _printable(text)
    return text if len(text) <= _QUOTE else text[: _QUOTE - 3] + "..."


def _short(value: object) -> str:
    return _clip(repr(value))


# --------------------------------------------------------------------------- world states


def encode_state(state: Hashable) -> Any:
    """``state`` as a JSON value that :func:`decode_state` turns back into an equal state.

    ``None``, booleans, integers, finite floats and strings stand for themselves; a
    tuple becomes a list of its encoded items (states are hashable, so no state is a
    list, and a list read back is a tuple).  NumPy scalars are stored as the Python
    number they equal.  Anything else raises ``ValueError`` naming the state.
    """
    if state is None or isinstance(state, bool | str):
        return state
    if isinstance(state, np.bool_):
        return bool(state)
    if isinstance(state, int | np.integer):
        return int(state)
    if isinstance(state, float | np.floating):
        if not math.isfinite(state):
            raise ValueError(f"world state {_short(state)}: a non-finite number cannot be saved")
        return float(state)
    if isinstance(state, tuple):
        return [encode_state(s) for s in state]
    raise ValueError(
        f"world state {_short(state)}: cannot be saved ({type(state).__name__}); a saved "
        "controller keeps states made of None, booleans, numbers, strings and tuples"
    )


def decode_state(value: Any) -> Hashable:
    """The state :func:`encode_state` encoded as ``value`` (``ValueError`` if none)."""
    if value is None or isinstance(value, bool | int | str):
        return value
    if isinstance(value, float) and math.isfinite(value):
        return value
    if isinstance(value, list):
        return tuple(decode_state(v) for v in value)
    raise ValueError(f"{_short(value)} is not an encoded world state")


# --------------------------------------------------------------------------- the tables


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


@dataclass(frozen=True, slots=True)
class Decision:
    """What a controller does in one product state: draw *stay* with probability
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


@dataclass(frozen=True, slots=True, eq=False)
class SavedPlan:
    """What a controller needs to run, as tables (:mod:`mitld_lp.running.controller_file`).

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
            raise ValueError(
                f"world state {_short(state)}: not a state the saved controller knows "
                "(the world it was saved from does not reach it)"
            )
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
        if not self.randomised:
            if at < 0:
                return Decision(())
            a = int(t["policy"][at])
            return Decision(() if a < 0 else (self.actions[a],), lost=bool(t["hopeless"][at]))
        if at < 0:
            return Decision(())
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
        nodes: list[list[Any]] = []
        done: dict[int, int] = {}  # shared: the diagrams of several states share nodes
        roots = [_flatten(d, self.atoms, nodes, done) for d in self.delta]
        automaton: dict[str, Any] = {"initial": self.initial, "roots": roots, "nodes": nodes}
        if self.randomised:
            automaton["verdicts"] = [list(v) for v in self.verdicts]
        else:
            automaton["accepting"], automaton["rejecting"] = self.accepting, self.rejecting
        meta = {
            "format": FORMAT,
            "version": VERSION,
            "kind": self.kind,
            "variables": None if self.variables is None else list(self.variables),
            "atoms": list(self.atoms),
            "events": sorted(self.events),
            "actions": list(self.actions),
            "automaton": automaton,
            "clock": {
                "caps": dict(sorted(self.caps.items())),
                "truncations": dict(sorted(self.truncations.items())),
            },
        }
        text = json.dumps(meta, allow_nan=False, separators=(",", ":")).encode("utf-8")
        members = MEMBERS[self.kind]
        arrays = {"props": self.props, "fallback": self.fallback_action, "keys": self.keys,
                  **self.tables}
        buffer = io.BytesIO()
        np.savez_compressed(
            buffer,
            meta=np.frombuffer(text, dtype=np.uint8),
            states=np.frombuffer(encoded_states(self.states), dtype=np.uint8),
            **{k: np.asarray(arrays[k], dtype=members[k]) for k in members
               if k not in ("meta", "states")},
        )
        return buffer.getvalue()


def key(g: int, q: int, pending: int, clock: int, n_q: int, n_events: int, n_clock: int) -> int:
    """The key of product state ``(g, q, pending mask, clock)``; ``clock < n_clock``."""
    return ((g * n_q + q) << n_events | pending) * n_clock + clock


def encoded_states(states: Sequence[Hashable]) -> bytes:
    """The JSON text of ``states``, checked to read back equal (and equally hashed)."""
    encoded = [encode_state(s) for s in states]
    text = json.dumps(encoded, allow_nan=False, separators=(",", ":"))
    for state, back in zip(states, json.loads(text), strict=True):
        again = decode_state(back)
        if not (again == state and state == again and hash(again) == hash(state)):
            raise ValueError(
                f"world state {_short(state)}: does not read back equal to itself "
                f"({_short(again)}); a saved controller keeps states made of None, "
                "booleans, numbers, strings and tuples"
            )
    return text.encode("utf-8")


def _flatten(d: Diagram, atoms: tuple[str, ...], nodes: list[list[Any]],
             done: dict[int, int]) -> int:
    """Append the nodes of ``d`` below ``nodes`` (children first) and return its code:
    a leaf ``q >= 0`` is the automaton state, a node ``i`` is coded ``-i - 1``."""
    if isinstance(d, int):
        return d
    hit = done.get(id(d))
    if hit is None:
        p, low, high = d
        lo = _flatten(low, atoms, nodes, done)
        hi = _flatten(high, atoms, nodes, done)
        nodes.append([atoms.index(p), lo, hi])
        hit = done[id(d)] = -len(nodes)
    return hit


# --------------------------------------------------------------------------- reading a file
