"""A controller as plain tables: what :meth:`mitld_lp.Controller.save` writes and
:meth:`mitld_lp.Controller.load` reads back.

The file is a NumPy ``.npz`` archive of plain arrays (integers, booleans, and UTF-8
JSON text stored as bytes), read with ``allow_pickle=False``: loading parses numbers and
JSON and never runs code from the file, so a foreign or damaged file can only be
refused (:class:`ControllerFileError`).  It holds everything the controller needs to
run, and nothing of the world's Python objects, so a robot's process loads it without
the world's class (and without any solver):

* ``meta`` (JSON): the format tag and version, the automaton's atoms, the task's
  events, the action names, the automaton (its initial, accepting and rejecting states
  and, per state, its transition function as a decision diagram over the atoms, see
  :mod:`mitld_lp.automata.dta`), and the clock rule (per event its cap and truncation
  point, :func:`mitld_lp.automata.sta.advance_clock`);
* ``states`` (JSON): the world states the controller may observe, in the encoding of
  :func:`encode_state`; position ``g`` in this list is the state's number ``g``;
* ``props`` (int64, per state ``g``): its robot propositions, as a bit mask over the atoms;
* ``fallback`` (int32, per ``g``): its first action (taken where the policy has none);
* ``keys`` (int64, sorted), ``policy`` (int32) and ``hopeless`` (bool), one entry per
  ordinary product state ``(g, q, pending, clock)`` with key
  ``((g * n_q + q) * 2**n_events + pending_mask) * n_clock + clock``: the policy's
  action (-1: none, the value there is 0) and whether the task is lost there.

The world states listed are every state the world reaches from its initial one (under
any action and any events): the product's game states and those reached past a
truncation point, where the controller goes on (:func:`tabulate` explores them).

Pickling a controller in memory (to hand it to another process of the same program)
still works; pickle is never a file format here.
"""

from __future__ import annotations

import io
import itertools
import json
import math
from collections.abc import Callable, Hashable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from mitld_lp import files
from mitld_lp.automata.dta import Diagram, _walk
from mitld_lp.automata.sta import STA, ClockStep, advance_clock
from mitld_lp.game import Game
from mitld_lp.mdp import MDP
from mitld_lp.product import ProductState
from mitld_lp.text import printable

__all__ = [
    "ControllerFileError",
    "FORMAT",
    "VERSION",
    "SavedPlan",
    "decode_state",
    "encode_state",
    "read_plan",
    "tabulate",
]

FORMAT = "mitld_lp.controller"
VERSION = 1
"""The file format's version; a file of another version is refused by name."""

_ARRAYS = {  # member -> dtype of its 1-D array
    "meta": np.uint8,
    "states": np.uint8,
    "props": np.int64,
    "fallback": np.int32,
    "keys": np.int64,
    "policy": np.int32,
    "hopeless": np.bool_,
}
_QUOTE = 80  # characters of a foreign value quoted in an error


class ControllerFileError(ValueError):
    """A file that is not a controller this version of mitld_lp saved: foreign,
    damaged, truncated or of another format version.  The message names the file and
    what is wrong."""


class _Bad(Exception):
    """Internal: what is wrong with the file being read (becomes ControllerFileError)."""


def _clip(text: str) -> str:
    """``text`` as one printable line of at most ``_QUOTE`` characters."""
    text = printable(text)
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


def _encoded_states(states: Sequence[Hashable]) -> bytes:
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


# --------------------------------------------------------------------------- the tables


@dataclass(frozen=True, slots=True, eq=False)
class SavedPlan:
    """What a controller needs to run, as tables (see the module docstring).

    Answers the controller's questions: :meth:`read` (the automaton after a labelled
    step), :meth:`advance` (the clock rule), :meth:`lookup` (the policy's action and
    whether the task is lost) and :meth:`fallback`.
    """

    atoms: tuple[str, ...]
    events: frozenset[str]
    actions: tuple[str, ...]
    initial: int
    accepting: int | None
    rejecting: int | None
    delta: tuple[Diagram, ...]
    caps: Mapping[str, int]
    truncations: Mapping[str, int]
    states: tuple[Hashable, ...]
    props: np.ndarray
    fallback_action: np.ndarray
    keys: np.ndarray
    policy: np.ndarray
    hopeless: np.ndarray
    _index: dict[Hashable, int] = field(default_factory=dict, repr=False)
    _event_bit: dict[str, int] = field(default_factory=dict, repr=False)
    _letters: dict[int, frozenset[str]] = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        self._index.update((s, g) for g, s in enumerate(self.states))
        self._event_bit.update((e, 1 << i) for i, e in enumerate(sorted(self.events)))
        for a in (self.props, self.fallback_action, self.keys, self.policy, self.hopeless):
            a.flags.writeable = False

    def key(self, g: int, q: int, pending: Iterable[str], clock: int) -> int:
        """The key of the product state ``(g, q, pending, clock)`` (module docstring)."""
        mask = sum(self._event_bit[e] for e in pending)
        n_clock = max(self.caps.values(), default=0) + 1
        return _key(g, q, mask, clock, len(self.delta), len(self.events), n_clock)

    def _number(self, state: Hashable) -> int:
        g = self._index.get(state)
        if g is None:
            raise ValueError(
                f"world state {_short(state)}: not a state the saved controller knows "
                "(the world it was saved from does not reach it)"
            )
        return g

    def read(self, q: int, state: Hashable, events: frozenset[str]) -> int:
        """The automaton state after ``q`` reads the label of ``state`` plus ``events``."""
        mask = int(self.props[self._number(state)])
        props = self._letters.get(mask)
        if props is None:
            props = self._letters[mask] = frozenset(
                a for i, a in enumerate(self.atoms) if mask >> i & 1)
        return _walk(self.delta[q], props | events)

    def advance(self, pending: frozenset[str], clock: int) -> ClockStep:
        return advance_clock(pending, clock, self.caps, self.truncations)

    def lookup(
        self, state: Hashable, q: int, pending: frozenset[str], clock: int
    ) -> tuple[str | None, bool]:
        """The policy's action at the product state (None: no record, or no policy
        there) and whether the task is lost there."""
        key = self.key(self._number(state), q, pending, clock)
        at = int(np.searchsorted(self.keys, key))
        if at == self.keys.size or int(self.keys[at]) != key:
            return None, False
        a = int(self.policy[at])
        return (None if a < 0 else self.actions[a]), bool(self.hopeless[at])

    def fallback(self, state: Hashable) -> str:
        return self.actions[int(self.fallback_action[self._number(state)])]

    def tables(self, max_states: int) -> SavedPlan:
        return self

    def to_bytes(self) -> bytes:
        """The ``.npz`` archive of these tables."""
        nodes: list[list[Any]] = []
        done: dict[int, int] = {}  # shared: the diagrams of several states share nodes
        roots = [_flatten(d, self.atoms, nodes, done) for d in self.delta]
        meta = {
            "format": FORMAT,
            "version": VERSION,
            "atoms": list(self.atoms),
            "events": sorted(self.events),
            "actions": list(self.actions),
            "automaton": {
                "initial": self.initial,
                "accepting": self.accepting,
                "rejecting": self.rejecting,
                "roots": roots,
                "nodes": nodes,
            },
            "clock": {
                "caps": dict(sorted(self.caps.items())),
                "truncations": dict(sorted(self.truncations.items())),
            },
        }
        text = json.dumps(meta, allow_nan=False, separators=(",", ":")).encode("utf-8")
        buffer = io.BytesIO()
        np.savez_compressed(
            buffer,
            meta=np.frombuffer(text, dtype=np.uint8),
            states=np.frombuffer(_encoded_states(self.states), dtype=np.uint8),
            props=np.asarray(self.props, dtype=np.int64),
            fallback=np.asarray(self.fallback_action, dtype=np.int32),
            keys=np.asarray(self.keys, dtype=np.int64),
            policy=np.asarray(self.policy, dtype=np.int32),
            hopeless=np.asarray(self.hopeless, dtype=np.bool_),
        )
        return buffer.getvalue()


def _key(g: int, q: int, pending: int, clock: int, n_q: int, n_events: int, n_clock: int) -> int:
    """The key of product state ``(g, q, pending mask, clock)``; ``clock < n_clock``."""
    return ((g * n_q + q) << n_events | pending) * n_clock + clock


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


# --------------------------------------------------------------------------- from a synthesis


def tabulate(
    game: Game[Any],
    sta: STA,
    mdp: MDP,
    policy: np.ndarray,
    hopeless: np.ndarray | None,
    *,
    max_states: int,
) -> SavedPlan:
    """The tables of the controller that runs ``policy`` on ``mdp`` (the product of
    ``game`` with ``sta``).

    The world states kept are every state reachable from the initial one under any
    action and any set of the task's events: the product's game states and those the
    world reaches past a truncation point, where the product stopped and the controller
    goes on.  Raises ``ValueError`` (naming the numbers) when there are more than
    ``max_states`` of them, or when a world state cannot be encoded
    (:func:`encode_state`).
    """
    dta = sta.dta
    atom_bit = {a: 1 << i for i, a in enumerate(dta.atoms)}
    events = sorted(sta.events)
    event_bit = {e: 1 << i for i, e in enumerate(events)}
    actions = list(mdp.action_names)
    action_id = {a: i for i, a in enumerate(actions)}
    index: dict[Hashable, int] = {}
    states: list[Hashable] = []
    props: list[int] = []
    fallback: list[int] = []

    def number(s: Hashable) -> int:
        g = index.get(s)
        if g is None:
            _check_budget(len(states) + 1, max_states)
            g = index[s] = len(states)
            states.append(s)
            held = game.propositions(s)
            props.append(sum(bit for a, bit in atom_bit.items() if a in held))
            first = game.actions(s)[0]
            if first not in action_id:
                action_id[first] = len(actions)
                actions.append(first)
            fallback.append(action_id[first])
        return g

    n_q, n_clock = dta.n_states, max((c.cap for c in sta.clocks.values()), default=0) + 1
    keys: list[int] = []
    chosen: list[int] = []
    lost: list[bool] = []
    number(game.initial)
    for i, record in enumerate(mdp.states):
        if not isinstance(record, ProductState):
            continue
        if not 0 <= record.clock < n_clock:
            raise ValueError(f"product state {i}: clock {record.clock} beyond the STA's caps")
        pending = sum(event_bit[e] for e in record.pending)
        keys.append(_key(number(record.game), record.automaton, pending, record.clock, n_q,
                         len(events), n_clock))
        c = int(policy[i])  # a choice of an ordinary state: never ABSORB (-1, "none")
        chosen.append(int(mdp.choice_actions[c]) if c >= 0 else -1)
        lost.append(bool(hopeless[i]) if hopeless is not None else False)
    _close(game, states, number, events)

    order = np.argsort(np.asarray(keys, dtype=np.int64), kind="stable")
    return SavedPlan(
        atoms=dta.atoms,
        events=sta.events,
        actions=tuple(actions),
        initial=dta.initial,
        accepting=dta.accepting,
        rejecting=dta.rejecting,
        delta=tuple(dta.delta),
        caps={a: c.cap for a, c in sta.clocks.items()},
        truncations=dict(sta.truncation_points),
        states=tuple(states),
        props=np.asarray(props, dtype=np.int64),
        fallback_action=np.asarray(fallback, dtype=np.int32),
        keys=np.asarray(keys, dtype=np.int64)[order],
        policy=np.asarray(chosen, dtype=np.int32)[order],
        hopeless=np.asarray(lost, dtype=np.bool_)[order],
    )


def _close(
    game: Game[Any], states: list[Hashable], number: Callable[[Hashable], int],
    events: list[str],
) -> None:
    """Number every world state reachable from ``states`` under every action and every
    subset of ``events`` (``number`` appends the new ones to ``states``)."""
    subsets = [frozenset(c) for k in range(len(events) + 1)
               for c in itertools.combinations(events, k)]
    g = 0
    while g < len(states):
        s = states[g]
        for a in game.actions(s):
            for occurred in subsets:
                for t, p in game.successors(s, a, occurred):
                    if p > 0:
                        number(t)
        g += 1


def _check_budget(states: int, max_states: int) -> None:
    if states > max_states:
        raise ValueError(
            f"the controller's world has more than {max_states:,} states reachable from its "
            "initial one; pass a larger max_states to save it"
        )


# --------------------------------------------------------------------------- reading a file


def read_plan(path: str | Path) -> SavedPlan:
    """The tables saved in ``path``; :class:`ControllerFileError` naming the file and
    the fault if it is not a controller file of this format version."""
    source = Path(path)
    try:
        raw = _read_arrays(source)
        return _plan(raw)
    except _Bad as bad:
        raise ControllerFileError(f"{source}: cannot load the controller: {bad}") from None


_ZIP_MAGIC = (b"PK\x03\x04", b"PK\x05\x06")


def _kind(head: bytes) -> str:
    """What a file that is not a controller archive looks like, from its first bytes."""
    if not head:
        return "an empty file"
    if head.startswith(b"\x93NUMPY"):
        return "a single NumPy array"
    if head[:1] == b"\x80":
        return "a pickle, and pickled Python objects are never loaded"
    return "not a NumPy archive"


def _read_arrays(source: Path) -> dict[str, np.ndarray]:
    """The archive's arrays, parsed with ``allow_pickle=False`` (nothing is executed)."""
    try:
        with files.open_archive(source) as handle:
            head = handle.read(6)
            if head[:4] not in _ZIP_MAGIC:
                raise _Bad(f"not a controller file: {_kind(head)}")
            handle.seek(0)
            loaded = np.load(handle, allow_pickle=False)
            with loaded:
                if set(loaded.files) != set(_ARRAYS):
                    raise _Bad(f"not a controller archive (members {_short(loaded.files)}, "
                               f"expected {', '.join(_ARRAYS)})")
                arrays = {name: loaded[name] for name in _ARRAYS}
                for name, value in arrays.items():
                    if not isinstance(value, np.ndarray):  # a member that is no .npy
                        raise _Bad(f"{name}: not a NumPy array")
                return arrays
    except _Bad:
        raise
    except OSError as exc:
        raise _Bad(exc.strerror or type(exc).__name__) from None
    except Exception as exc:  # noqa: BLE001 - any parse failure of a foreign file
        detail = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise _Bad(f"a damaged or foreign archive ({_clip(detail)})") from None


def _need(condition: bool, what: str) -> None:
    if not condition:
        raise _Bad(what)


def _is_int(x: object) -> bool:
    return isinstance(x, int) and not isinstance(x, bool)


def _names(x: object, what: str, *, ordered: bool) -> tuple[str, ...]:
    _need(isinstance(x, list) and all(isinstance(v, str) for v in x),
          f"{what}: expected a list of names")
    assert isinstance(x, list)
    _need(len(set(x)) == len(x), f"{what}: a name appears twice")
    _need(not ordered or x == sorted(x), f"{what}: not sorted")
    return tuple(x)


def _json(raw: np.ndarray, what: str) -> Any:
    try:
        return json.loads(raw.tobytes().decode("utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise _Bad(f"{what}: not JSON text ({_clip(str(exc))})") from None


def _plan(raw: dict[str, np.ndarray]) -> SavedPlan:
    """Check every table against the others and build the plan."""
    for name, dtype in _ARRAYS.items():
        a = raw[name]
        _need(a.dtype == dtype and a.ndim == 1,
              f"{name}: expected a 1-D {np.dtype(dtype).name} array, got {a.dtype} {a.shape}")
    meta = _json(raw["meta"], "meta")
    _need(isinstance(meta, dict), "meta: not a JSON object")
    _need(meta.get("format") == FORMAT,
          f"not a controller file (format {_short(meta.get('format'))})")
    version = meta.get("version")
    _need(version == VERSION and _is_int(version),
          f"format version {_short(version)}; this mitld_lp reads version {VERSION} "
          "(save the controller again with it)")
    _need(set(meta) == {"format", "version", "atoms", "events", "actions", "automaton",
                        "clock"}, f"meta: unexpected keys {_short(sorted(meta))}")
    atoms = _names(meta["atoms"], "meta.atoms", ordered=True)
    events = _names(meta["events"], "meta.events", ordered=True)
    actions = _names(meta["actions"], "meta.actions", ordered=False)
    _need(len(atoms) <= 62 and len(events) <= 30, "meta: too many atoms or events")
    initial, accepting, rejecting, delta = _automaton(meta["automaton"], atoms)
    caps, truncations = _clock(meta["clock"], events)

    encoded = _json(raw["states"], "states")
    _need(isinstance(encoded, list), "states: not a JSON list")
    try:
        states = tuple(decode_state(v) for v in encoded)
    except (ValueError, RecursionError) as exc:
        raise _Bad(f"states: {_clip(str(exc))}") from None
    _need(len(set(states)) == len(states), "states: a world state appears twice")
    n_g, n_q = len(states), len(delta)
    props, fallback = raw["props"], raw["fallback"]
    _need(props.size == n_g and fallback.size == n_g,
          f"props and fallback: expected {n_g} entries (one per world state)")
    _need(bool(np.all((props >= 0) & (props < 1 << len(atoms)))), "props: not atom masks")
    _need(bool(np.all((fallback >= 0) & (fallback < len(actions)))),
          "fallback: an action number out of range")
    keys, policy, hopeless = raw["keys"], raw["policy"], raw["hopeless"]
    _need(policy.size == keys.size and hopeless.size == keys.size,
          "keys, policy and hopeless: not of one length")
    n_clock = max(caps.values(), default=0) + 1
    bound = n_g * n_q * (1 << len(events)) * n_clock
    _need(bound < 1 << 63, "keys: the key space exceeds 64 bits")
    _need(bool(np.all(np.diff(keys) > 0)), "keys: not strictly increasing")
    _need(keys.size == 0 or (int(keys[0]) >= 0 and int(keys[-1]) < bound),
          "keys: a product state out of range")
    _need(bool(np.all((policy >= -1) & (policy < len(actions)))),
          "policy: an action number out of range")
    return SavedPlan(
        atoms=atoms, events=frozenset(events), actions=actions, initial=initial,
        accepting=accepting, rejecting=rejecting, delta=delta, caps=caps,
        truncations=truncations, states=states, props=props, fallback_action=fallback,
        keys=keys, policy=policy, hopeless=hopeless,
    )


def _automaton(
    a: object, atoms: tuple[str, ...]
) -> tuple[int, int | None, int | None, tuple[Diagram, ...]]:
    _need(isinstance(a, dict) and set(a) == {"initial", "accepting", "rejecting", "roots",
                                             "nodes"}, "meta.automaton: unexpected keys")
    assert isinstance(a, dict)
    roots, nodes = a["roots"], a["nodes"]
    _need(isinstance(roots, list) and len(roots) > 0 and all(_is_int(r) for r in roots),
          "meta.automaton.roots: expected a list of integers")
    n_q = len(roots)
    _need(_is_int(a["initial"]) and 0 <= a["initial"] < n_q,
          "meta.automaton.initial: not a state")
    for k in ("accepting", "rejecting"):
        _need(a[k] is None or (_is_int(a[k]) and 0 <= a[k] < n_q),
              f"meta.automaton.{k}: not a state")
    _need(isinstance(nodes, list), "meta.automaton.nodes: expected a list")
    built: list[Diagram] = []

    def child(code: object, below: int, where: str) -> Diagram:
        _need(_is_int(code), f"{where}: not an integer")
        assert isinstance(code, int)
        if code >= 0:
            _need(code < n_q, f"{where}: no automaton state {code}")
            return code
        _need(-code - 1 < below, f"{where}: refers to node {-code - 1}, not an earlier one")
        return built[-code - 1]

    for i, node in enumerate(nodes):
        where = f"meta.automaton.nodes[{i}]"
        _need(isinstance(node, list) and len(node) == 3, f"{where}: expected [atom, low, high]")
        p, low, high = node
        _need(_is_int(p) and 0 <= p < len(atoms), f"{where}: not an atom number")
        built.append((atoms[p], child(low, i, where), child(high, i, where)))
    delta = tuple(child(r, len(built), f"meta.automaton.roots[{q}]")
                  for q, r in enumerate(roots))
    return a["initial"], a["accepting"], a["rejecting"], delta


def _clock(c: object, events: tuple[str, ...]) -> tuple[dict[str, int], dict[str, int]]:
    _need(isinstance(c, dict) and set(c) == {"caps", "truncations"},
          "meta.clock: unexpected keys")
    assert isinstance(c, dict)
    caps, cuts = c["caps"], c["truncations"]
    _need(isinstance(caps, dict) and set(caps) == set(events)
          and all(_is_int(v) and v >= 0 for v in caps.values()),
          "meta.clock.caps: expected one integer >= 0 per event")
    _need(isinstance(cuts, dict) and set(cuts) <= set(events)
          and all(_is_int(v) and v >= 1 for v in cuts.values()),
          "meta.clock.truncations: expected integers >= 1 for some events")
    return dict(caps), dict(cuts)
