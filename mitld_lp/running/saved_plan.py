"""A saved controller's tables and their file, with NumPy alone: the reader of the
format :mod:`mitld_lp.running.controller_file` writes (described there), the tables' answers
(:class:`SavedPlan`) and the one clock rule.  Imported by :mod:`mitld_lp.runtime` (and
through it by the full package), so it imports only the standard library and NumPy."""

from __future__ import annotations

import io
import json
import math
from collections.abc import Hashable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from mitld_lp.files import rules as file_rules

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
    "read_plan",
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


def read_plan(path: str | Path) -> SavedPlan:
    """The tables saved in ``path``; :class:`ControllerFileError` naming the file and
    the fault if it is not a controller file of a version this module reads."""
    source = Path(path)
    try:
        return _plan(_read_arrays(source))
    except _Sensed as bad:
        raise SensedControllerFile(f"{source}: cannot load the controller: {bad}") from None
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
        with file_rules.open_archive(source) as handle:  # a regular file, sizes checked
            head = handle.read(6)
            if head[:4] not in _ZIP_MAGIC:
                raise _Bad(f"not a controller file: {_kind(head)}")
            handle.seek(0)
            loaded = np.load(handle, allow_pickle=False)
            with loaded:
                names = set(loaded.files)
                if names == {"meta", "states", "first", "policy", "moves"}:
                    raise _Sensed("a controller that acts on sensor reports (mitld_lp."
                                  "load_controller loads it; mitld-lp run and "
                                  "mitld_lp.runtime do not serve it yet)")
                if not any(names == set(_members(k, v)) for k in MEMBERS for v in READS):
                    raise _Bad(f"not a controller archive (members {_short(loaded.files)}, "
                               f"expected {', '.join(_DETERMINISTIC)} or "
                               f"{', '.join(_RANDOMISED)})")
                arrays = {name: loaded[name] for name in names}
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
    for name in _COMMON:
        dtype = _COMMON[name]
        a = raw[name]
        _need(a.dtype == dtype and a.ndim == 1,
              f"{name}: expected a 1-D {np.dtype(dtype).name} array, got {a.dtype} {a.shape}")
    meta = _json(raw["meta"], "meta")
    _need(isinstance(meta, dict), "meta: not a JSON object")
    _need(meta.get("format") == FORMAT,
          f"not a controller file (format {_short(meta.get('format'))})")
    version = meta.get("version")
    _need(_is_int(version) and version in READS,
          f"format version {_short(version)}; this mitld_lp reads versions "
          f"{', '.join(map(str, READS))} (save the controller again with it)")
    base = {"format", "version", "atoms", "events", "actions", "automaton", "clock"}
    keys = base if version == 1 else base | {"kind", "variables"}
    _need(set(meta) == keys, f"meta: unexpected keys {_short(sorted(meta))}")
    kind = meta.get("kind", "deterministic")
    _need(kind in MEMBERS, f"meta.kind: {_short(kind)} is not a controller kind")
    members = _members(kind, version)
    _need(set(raw) == set(members), f"not a {kind} controller archive of format version "
          f"{version} (members {_short(sorted(raw))})")
    for name, dtype in members.items():
        a = raw[name]
        _need(a.dtype == dtype and a.ndim == 1,
              f"{name}: expected a 1-D {np.dtype(dtype).name} array, got {a.dtype} {a.shape}")
    variables = meta.get("variables")
    if variables is not None:
        variables = _names(variables, "meta.variables", ordered=False)
    atoms = _names(meta["atoms"], "meta.atoms", ordered=True)
    events = _names(meta["events"], "meta.events", ordered=True)
    actions = _names(meta["actions"], "meta.actions", ordered=False)
    _need(len(atoms) <= 62 and len(events) <= 30, "meta: too many atoms or events")
    initial, verdicts, delta = _automaton(meta["automaton"], atoms, kind)
    caps, truncations = _clock(meta["clock"], events)

    encoded = _json(raw["states"], "states")
    _need(isinstance(encoded, list), "states: not a JSON list")
    try:
        states = tuple(decode_state(v) for v in encoded)
    except (ValueError, RecursionError) as exc:
        raise _Bad(f"states: {_clip(str(exc))}") from None
    _need(len(set(states)) == len(states), "states: a world state appears twice")
    _need(variables is None or all(isinstance(s, tuple) and len(s) == len(variables)
                                   for s in states),
          "states: not tuples of the world's variables")
    n_g, n_q = len(states), len(delta)
    props, fallback = raw["props"], raw["fallback"]
    _need(props.size == n_g and fallback.size == n_g,
          f"props and fallback: expected {n_g} entries (one per world state)")
    _need(bool(np.all((props >= 0) & (props < 1 << len(atoms)))), "props: not atom masks")
    _need(bool(np.all((fallback >= 0) & (fallback < len(actions)))),
          "fallback: an action number out of range")
    keys_ = raw["keys"]
    n_clock = max(caps.values(), default=0) + 1
    bound = n_g * n_q * (1 << len(events)) * n_clock
    _need(bound < 1 << 63, "keys: the key space exceeds 64 bits")
    _need(bool(np.all(np.diff(keys_) > 0)), "keys: not strictly increasing")
    _need(keys_.size == 0 or (int(keys_[0]) >= 0 and int(keys_[-1]) < bound),
          "keys: a product state out of range")
    tables = {k: raw[k] for k in members if k not in _COMMON}
    if kind == "randomised" and "keep" not in tables:  # version 2: no keep choice
        tables.update({k: np.zeros(raw["choices"].size, dtype=np.bool_) for k in _KEEPS})
    (_deterministic_tables if kind == "deterministic" else _randomised_tables)(
        tables, keys_.size, len(actions))
    return SavedPlan(
        kind=kind, atoms=atoms, events=frozenset(events), actions=actions, initial=initial,
        verdicts=verdicts, delta=delta, caps=caps, truncations=truncations, states=states,
        props=props, fallback_action=fallback, keys=keys_, tables=tables,
        variables=variables,
    )


def _deterministic_tables(t: dict[str, np.ndarray], n: int, n_actions: int) -> None:
    _need(t["policy"].size == n and t["hopeless"].size == n,
          "keys, policy and hopeless: not of one length")
    _need(bool(np.all((t["policy"] >= -1) & (t["policy"] < n_actions))),
          "policy: an action number out of range")


def _randomised_tables(t: dict[str, np.ndarray], n: int, n_actions: int) -> None:
    off = t["offsets"]
    _need(off.size == n + 1 and t["stay"].size == n and t["charged"].size == n,
          "keys, offsets, stay and charged: not of matching lengths")
    _need(int(off[0]) == 0 and bool(np.all(np.diff(off) >= 0))
          and int(off[-1]) == t["choices"].size,
          "offsets: not a partition of the choices")
    _need(all(t[k].size == t["choices"].size for k in ("weights", "inside", *_KEEPS)),
          "choices, weights, inside, keep and kept: not of one length")
    _need(bool(np.all(np.where(t["keep"], t["choices"] == -1,
                               (t["choices"] >= 0) & (t["choices"] < n_actions)))),
          "choices: an action number out of range (-1 only for a keep choice)")
    _need(not bool(np.any(t["keep"] & (t["kept"] | t["inside"]))),
          "keep: a keep choice is not itself an action of an end component")
    for name in ("weights", "stay"):
        v = t[name]
        _need(bool(np.all(np.isfinite(v) & (v >= 0) & (v <= 1))),
              f"{name}: not probabilities")


def _automaton(
    a: object, atoms: tuple[str, ...], kind: str
) -> tuple[int, tuple[tuple[int, ...], ...], tuple[Diagram, ...]]:
    names = {"initial", "roots", "nodes"} | (
        {"verdicts"} if kind == "randomised" else {"accepting", "rejecting"})
    _need(isinstance(a, dict) and set(a) == names, "meta.automaton: unexpected keys")
    assert isinstance(a, dict)
    roots, nodes = a["roots"], a["nodes"]
    _need(isinstance(roots, list) and len(roots) > 0 and all(_is_int(r) for r in roots),
          "meta.automaton.roots: expected a list of integers")
    n_q = len(roots)
    _need(_is_int(a["initial"]) and 0 <= a["initial"] < n_q,
          "meta.automaton.initial: not a state")
    if kind == "randomised":
        v = a["verdicts"]
        _need(isinstance(v, list) and len(v) == n_q and all(
            isinstance(x, list) and len(x) == len(v[0]) > 0
            and all(_is_int(y) and y in (ACCEPTED, REJECTED, UNDECIDED) for y in x)
            for x in v), "meta.automaton.verdicts: expected one list of verdicts per state")
        verdicts = tuple(tuple(x) for x in v)
    else:
        for k in ("accepting", "rejecting"):
            _need(a[k] is None or (_is_int(a[k]) and 0 <= a[k] < n_q),
                  f"meta.automaton.{k}: not a state")
        verdicts = tuple((ACCEPTED,) if q == a["accepting"] else (REJECTED,)
                         if q == a["rejecting"] else (UNDECIDED,) for q in range(n_q))
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
    return a["initial"], verdicts, delta


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

