"""The controller file: its layout for every kind and version, and the one writer.

What :meth:`Controller.save <mitld_lp.Controller.save>` (and the randomised and sensed
controllers' ``save``) writes and :func:`mitld_lp.controllers.reader.read` reads.  The
file is a NumPy ``.npz`` archive of plain arrays (integers, floats, booleans, and UTF-8
JSON text stored as bytes), read with ``allow_pickle=False``: loading parses numbers
and JSON and never runs code from the file, so a foreign or damaged file can only be
refused (:class:`ControllerFileError`).  It holds everything the controller needs to
run and nothing of the world's Python objects, so a robot's process loads it without
the world's class (and without any solver).

Every file has these members:

* ``meta`` (JSON): the format tag (:data:`FORMAT`) and version (:data:`VERSION`; the
  versions in :data:`READS` are read), the ``kind`` (``"deterministic"``,
  ``"randomised"``, ``"sensed"`` or ``"sensed-randomised"``), the world's ``variables``
  (their names when a world state is a tuple of them, as in a PRISM world; else null),
  the task's ``events``
  (sorted) and the ``actions`` (names; an action is stored as its number in this list),
  and what its kind adds below;
* ``states`` (JSON): the world states the controller may observe, in the encoding of
  :func:`encode_state`; position ``g`` in this list is the state's number ``g``: every
  state the world reaches from its initial one under any action and any events;
* ``fallback`` (int32, per ``g``): its first action (taken where the policy has none).

A deterministic or randomised controller follows the task's automaton and a clock:

* ``meta`` adds the automaton's ``atoms``, the ``automaton`` (its initial state, per
  state its transition function as a decision diagram over the atoms, see
  :mod:`mitld_lp.automata.dta`, and its accepting and rejecting states -- for a
  randomised controller instead per state the ``verdicts`` of the task and of each
  constraint's formula: 1 accepted, 0 rejected, -1 undecided), and the ``clock`` rule
  (per event its cap and truncation point, :func:`mitld_lp.automata.sta.advance_clock`);
* ``props`` (int64, per ``g``): its robot propositions, as a bit mask over the atoms;
* ``keys`` (int64, sorted), one entry per ordinary product state ``(g, q, pending,
  clock)`` with key ``((g * n_q + q) * 2**n_events + pending_mask) * n_clock + clock``;
* deterministic: ``policy`` (int32) and ``hopeless`` (bool) per key: the policy's
  action (-1: none, the value there is 0) and whether the task is lost there;
* randomised: ``offsets`` (int64, one more than the keys): the key ``i``'s choices are
  entries ``offsets[i]:offsets[i + 1]`` of ``choices`` (int32 action numbers),
  ``weights`` (float64, their probabilities) and ``inside`` (bool: the choice keeps
  the run in its end component), ``keep`` (bool: the choice is the *keep* choice of a
  task with a safety part, stored as action -1: from then on the run plays the end
  component of persistent task states for ever) and ``kept`` (bool: the choice stays in
  that component; what a run that has kept draws from, uniformly); ``stay`` (float64 per
  key: the probability of drawing *stay*, keeping to the end component for ever) and
  ``charged`` (bool per key: a step here counts towards E(steps)).

A sensed controller (kind ``"sensed"``) follows what the robot knows, its information
state (:mod:`mitld_lp.sensing.belief`):

* ``meta`` adds the ``sensed`` events, the ``ignored`` ones (sensed events whose
  reports come too late to matter, :mod:`mitld_lp.sensing.horizon`: the controller drops
  them) and the ``initial`` information state (a number, or ``"accepted"`` /
  ``"rejected"`` / ``"decided"`` when the task is decided at step 0);
* ``policy`` (int32 per information state): the action, -1 where nothing is left to do;
* ``moves`` (int64, one row of 5 per move): ``(state, action, world state seen, events
  seen as a bit mask over events, next)``, ``next`` an information state, or -1 (every
  hypothesis left accepted), -2 (every one rejected), -3 (decided, unknown which).

A randomised sensed controller (kind ``"sensed-randomised"``, version 5: the
``sensed-constrained`` route's) has the sensed kind's ``meta`` and ``moves`` (the moves
of every action it may take) and, instead of ``policy``, per information state ``i``
the entries ``offsets[i]:offsets[i + 1]`` of ``choices`` (int32 action numbers),
``weights`` (float64) and ``inside`` (bool): first its actions with their weights, then
(flagged ``inside``, weight 0) the actions of its end component, drawn uniformly once
the run stays; ``stay`` (float64 per state): the probability of drawing *stay*.  An
empty entry with ``stay`` 0: nothing to do there.

Older files still read (:data:`READS`, :data:`SENSED_READS`): version 1 (deterministic
controllers; no ``kind`` nor ``variables``), version 2 (randomised controllers without
``keep`` and ``kept``: no keep choice), version 3 (no sensed kind), version 4 (no
randomised sensed kind), and the sensed
controller's own format of old, tag :data:`SENSED_FORMAT` (version 1 without
``ignored``, version 2; no ``kind`` nor ``variables``; its ``fallback`` named ``first``).

Pickling a controller in memory (to hand it to another process of the same program)
still works; pickle is never a file format here.  Imports NumPy and the standard
library only (:mod:`mitld_lp.runtime` reads files with it).
"""

from __future__ import annotations

import io
import json
import math
from collections.abc import Hashable, Sequence
from typing import Any

import numpy as np

__all__ = [
    "ACCEPTED",
    "ControllerFileError",
    "Diagram",
    "END_NAMES",
    "ENDS",
    "FORMAT",
    "KEEP",
    "KINDS",
    "READS",
    "REJECTED",
    "SENSED_FORMAT",
    "SENSED_READS",
    "UNDECIDED",
    "VERSION",
    "clipped",
    "decode_state",
    "encode_state",
    "encoded_states",
    "layout",
    "layouts",
    "meta_keys",
    "quoted",
    "to_bytes",
]

FORMAT = "mitld_lp.running.controller"
VERSION = 5
"""The version every file is written in (module docs for what older ones lack)."""
READS = (1, 2, 3, 4, 5)
SENSED_FORMAT = "mitld-lp-sensed-controller"
"""The tag of the sensed controller's own format of old (versions 1 and 2), still read."""
SENSED_READS = (1, 2)

KINDS = ("deterministic", "randomised", "sensed", "sensed-randomised")

ACCEPTED, REJECTED, UNDECIDED = 1, 0, -1
"""A component's verdict in an automaton state (the task is component 0)."""

KEEP = "keep"
"""A *keep* choice's name in a decision (told apart by ``Decision.keep``)."""

ENDS = {"target": -1, "sink": -2, "truncated": -3}
"""A sensed controller's ends (``mitld_lp.product.Absorbing``'s values) as ``moves``
codes; ``initial`` writes them by :data:`END_NAMES`."""
END_NAMES = {"target": "accepted", "sink": "rejected", "truncated": "decided"}

Diagram = int | tuple[str, Any, Any]
"""An automaton state's transition function: a leaf (the next state) or ``(atom, low,
high)``: ``high`` when the letter holds the atom."""

_QUOTE = 80  # characters of a foreign value quoted in an error


class ControllerFileError(ValueError):
    """A file that is not a controller this version of mitld_lp saved: foreign,
    damaged, truncated or of another format version.  The message names the file and
    what is wrong."""


# --------------------------------------------------------------------------- layouts

Member = tuple[Any, int]  # dtype, number of dimensions

_COMMON: dict[str, Member] = {"meta": (np.uint8, 1), "states": (np.uint8, 1),
                              "fallback": (np.int32, 1)}
_AUTOMATON: dict[str, Member] = {**_COMMON, "props": (np.int64, 1), "keys": (np.int64, 1)}
_LAYOUTS: dict[str, dict[str, Member]] = {
    "deterministic": {**_AUTOMATON, "policy": (np.int32, 1), "hopeless": (np.bool_, 1)},
    "randomised": {**_AUTOMATON, "offsets": (np.int64, 1), "choices": (np.int32, 1),
                   "weights": (np.float64, 1), "inside": (np.bool_, 1),
                   "stay": (np.float64, 1), "charged": (np.bool_, 1),
                   "keep": (np.bool_, 1), "kept": (np.bool_, 1)},
    "sensed": {**_COMMON, "policy": (np.int32, 1), "moves": (np.int64, 2)},
    "sensed-randomised": {**_COMMON, "moves": (np.int64, 2), "offsets": (np.int64, 1),
                          "choices": (np.int32, 1), "weights": (np.float64, 1),
                          "inside": (np.bool_, 1), "stay": (np.float64, 1)},
}
_KEEPS = ("keep", "kept")  # randomised members new in version 3
# the version that added the kind
_FIRST = {"deterministic": 1, "randomised": 2, "sensed": 4, "sensed-randomised": 5}


def layout(tag: str, kind: str, version: int) -> dict[str, Member] | None:
    """The members (dtype, dimensions) of a ``kind`` file of format ``tag`` and
    ``version``, None when no such file exists; a sensed file of old names its
    ``fallback`` member ``first``."""
    if tag == SENSED_FORMAT:
        if kind != "sensed" or version not in SENSED_READS:
            return None
        return {("first" if k == "fallback" else k): v for k, v in _LAYOUTS[kind].items()}
    if tag != FORMAT or kind not in _LAYOUTS or version not in READS or version < _FIRST[kind]:
        return None
    members = _LAYOUTS[kind]
    if kind == "randomised" and version < 3:
        return {k: v for k, v in members.items() if k not in _KEEPS}
    return members


def layouts() -> list[tuple[str, str, int, dict[str, Member]]]:
    """Every (tag, kind, version, members) a file may have."""
    out = []
    for tag, versions in ((FORMAT, READS), (SENSED_FORMAT, SENSED_READS)):
        for kind in KINDS:
            for v in versions:
                members = layout(tag, kind, v)
                if members is not None:
                    out.append((tag, kind, v, members))
    return out


def meta_keys(tag: str, kind: str, version: int) -> frozenset[str]:
    """The keys of ``meta`` in such a file."""
    common = {"format", "version", "events", "actions"}
    if kind.startswith("sensed"):
        keys = common | {"sensed", "initial"}
        if tag == SENSED_FORMAT:
            return frozenset(keys | ({"ignored"} if version > 1 else set()))
        return frozenset(keys | {"ignored", "kind", "variables"})
    keys = common | {"atoms", "automaton", "clock"}
    return frozenset(keys if version == 1 else keys | {"kind", "variables"})


# --------------------------------------------------------------------------- quoting


def _printable(text: str) -> str:
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


def clipped(text: str) -> str:
    """``text`` printable and at most 80 characters, for an error message."""
    text = _printable(text)
    return text if len(text) <= _QUOTE else text[: _QUOTE - 3] + "..."


def quoted(value: object) -> str:
    """``repr(value)``, printable and clipped, for an error message."""
    return clipped(repr(value))


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
            raise ValueError(f"world state {quoted(state)}: a non-finite number cannot be saved")
        return float(state)
    if isinstance(state, tuple):
        return [encode_state(s) for s in state]
    raise ValueError(
        f"world state {quoted(state)}: cannot be saved ({type(state).__name__}); a saved "
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
    raise ValueError(f"{quoted(value)} is not an encoded world state")


def encoded_states(states: Sequence[Hashable]) -> bytes:
    """The JSON text of ``states``, checked to read back equal (and equally hashed)."""
    encoded = [encode_state(s) for s in states]
    text = json.dumps(encoded, allow_nan=False, separators=(",", ":"))
    for state, back in zip(states, json.loads(text), strict=True):
        again = decode_state(back)
        if not (again == state and state == again and hash(again) == hash(state)):
            raise ValueError(
                f"world state {quoted(state)}: does not read back equal to itself "
                f"({quoted(again)}); a saved controller keeps states made of None, "
                "booleans, numbers, strings and tuples"
            )
    return text.encode("utf-8")


# --------------------------------------------------------------------------- writing


def to_bytes(plan: Any) -> bytes:
    """The ``.npz`` archive of ``plan``'s tables (a
    :class:`~mitld_lp.controllers.tables.SavedPlan`, or a
    :class:`~mitld_lp.controllers.tables.SensedPlan` that lists its world states)."""
    meta: dict[str, Any] = {
        "format": FORMAT, "version": VERSION, "kind": plan.kind,
        "variables": None if plan.variables is None else list(plan.variables),
        "events": sorted(plan.events)}
    if plan.kind.startswith("sensed"):
        meta["actions"], arrays = _sensed(plan, meta)
    else:
        meta["actions"], arrays = list(plan.actions), _automaton(plan, meta)
    text = json.dumps(meta, allow_nan=False, separators=(",", ":")).encode("utf-8")
    members = _LAYOUTS[plan.kind]
    payload: dict[str, Any] = {
        "meta": np.frombuffer(text, dtype=np.uint8),
        "states": np.frombuffer(encoded_states(plan.states), dtype=np.uint8),
        **{k: np.asarray(arrays[k], dtype=members[k][0]) for k in members
           if k not in ("meta", "states")}}
    buffer = io.BytesIO()
    np.savez_compressed(buffer, **payload)
    return buffer.getvalue()


def _automaton(plan: Any, meta: dict[str, Any]) -> dict[str, Any]:
    nodes: list[list[Any]] = []
    done: dict[int, int] = {}  # shared: the diagrams of several states share nodes
    roots = [_flatten(d, plan.atoms, nodes, done) for d in plan.delta]
    automaton: dict[str, Any] = {"initial": plan.initial, "roots": roots, "nodes": nodes}
    if plan.randomised:
        automaton["verdicts"] = [list(v) for v in plan.verdicts]
    else:
        automaton["accepting"], automaton["rejecting"] = plan.accepting, plan.rejecting
    meta.update({
        "atoms": list(plan.atoms),
        "automaton": automaton,
        "clock": {"caps": dict(sorted(plan.caps.items())),
                  "truncations": dict(sorted(plan.truncations.items()))},
    })
    return {"props": plan.props, "fallback": plan.fallback_action, "keys": plan.keys,
            **plan.tables}


def _sensed(plan: Any, meta: dict[str, Any]) -> tuple[list[str], dict[str, Any]]:
    worlds = plan.states
    index = {w: i for i, w in enumerate(worlds)}
    bit = {e: 1 << i for i, e in enumerate(sorted(plan.events))}
    first = [plan.fallback(w) for w in worlds]
    n_info = len(plan.decisions) if plan.randomised else len(plan.actions)
    actions = sorted(set().union(*(plan.played(s) for s in range(n_info))) | set(first))
    number = {a: i for i, a in enumerate(actions)}
    rows = []
    for (src, act), table in plan.moves.items():
        if act not in plan.played(src):  # a move the policy never makes
            continue
        for (world, seen, new), dst in table.items():
            mask = sum(bit[e] for e in seen | new)
            rows.append((src, number[act], index[world], mask,
                         ENDS[dst] if isinstance(dst, str) else dst))
    initial = plan.initial
    meta.update({"sensed": sorted(plan.sensed), "ignored": sorted(plan.ignored),
                 "initial": END_NAMES[initial] if isinstance(initial, str) else int(initial)})
    arrays: dict[str, Any] = {"fallback": [number[a] for a in first],
                              "moves": np.array(rows, dtype=np.int64).reshape(-1, 5)}
    if not plan.randomised:
        arrays["policy"] = [-1 if a is None else number[a] for a in plan.actions]
        return actions, arrays
    # per information state: its weighted choices, then the actions inside its end
    # component (weight 0, flagged), in the live decision's orders (the same draws)
    offsets, choices, weights, inside, stay = [0], [], [], [], []
    for d in plan.decisions:
        if d is not None:
            w = [] if d.weights is None else d.weights.tolist()
            choices += [number[a] for a in (*d.actions, *d.inside)]
            weights += w + [0.0] * len(d.inside)
            inside += [False] * len(d.actions) + [True] * len(d.inside)
        offsets.append(len(choices))
        stay.append(0.0 if d is None else d.stay)
    arrays.update(offsets=offsets, choices=choices, weights=weights, inside=inside, stay=stay)
    return actions, arrays


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
