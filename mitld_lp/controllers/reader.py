"""The one reader of controller files, with NumPy alone: the archive parsed with
``allow_pickle=False`` (nothing in it is executed), its layout found from its members
and ``meta`` (:mod:`mitld_lp.controllers.format`: every kind, every version read), every
member and table checked against the others, and the plan returned
(:class:`~mitld_lp.controllers.tables.SavedPlan` or
:class:`~mitld_lp.controllers.tables.SensedPlan`).  A foreign, damaged or truncated file,
or one of another format version, is refused by name
(:class:`~mitld_lp.controllers.format.ControllerFileError`, naming the file and the
fault).  Imports the standard library, NumPy and the package's NumPy-only modules."""

from __future__ import annotations

import json
from collections.abc import Hashable
from pathlib import Path
from typing import Any

import numpy as np

from mitld_lp.controllers.format import (
    ACCEPTED,
    END_NAMES,
    ENDS,
    FORMAT,
    READS,
    REJECTED,
    SENSED_FORMAT,
    SENSED_READS,
    UNDECIDED,
    ControllerFileError,
    Diagram,
    clipped,
    decode_state,
    layout,
    layouts,
    meta_keys,
    quoted,
)
from mitld_lp.controllers.stepper import Decision
from mitld_lp.controllers.tables import MixedSensedPlan, Obs, SavedPlan, SensedPlan
from mitld_lp.files import rules as file_rules

__all__ = ["read"]


class _Bad(Exception):
    """What is wrong with the file being read (becomes ControllerFileError)."""


def read(path: str | Path) -> SavedPlan | SensedPlan:
    """The controller saved in ``path``; :class:`ControllerFileError` naming the file and
    the fault if it is not a controller file of a version this module reads."""
    source = Path(path)
    try:
        return _plan(_read_arrays(source))
    except _Bad as bad:
        raise ControllerFileError(f"{source}: cannot load the controller: {bad}") from None


# --------------------------------------------------------------------------- the archive

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
    """The archive's arrays, parsed with ``allow_pickle=False`` (nothing is executed),
    if its members are those of some controller file."""
    try:
        with file_rules.open_archive(source) as handle:  # a regular file, sizes checked
            head = handle.read(6)
            if head[:4] not in _ZIP_MAGIC:
                raise _Bad(f"not a controller file: {_kind(head)}")
            handle.seek(0)
            loaded = np.load(handle, allow_pickle=False)
            with loaded:
                names = set(loaded.files)
                if not any(names == set(members) for *_, members in layouts()):
                    raise _Bad(f"not a controller archive (members {quoted(sorted(names))}, "
                               "which no kind of controller file has)")
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
        raise _Bad(f"a damaged or foreign archive ({clipped(detail)})") from None


# --------------------------------------------------------------------------- checks


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
    _need(raw.dtype == np.uint8 and raw.ndim == 1,
          f"{what}: expected a 1-D uint8 array, got {raw.dtype} {raw.shape}")
    try:
        return json.loads(raw.tobytes().decode("utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise _Bad(f"{what}: not JSON text ({clipped(str(exc))})") from None


def _in_range(a: np.ndarray, low: int, high: int) -> bool:
    """Every entry of ``a`` in ``low .. high - 1``."""
    return bool(np.all((a >= low) & (a < high)))


def _plan(raw: dict[str, np.ndarray]) -> SavedPlan | SensedPlan:
    """Find the file's layout from ``meta``, check every member and build the plan."""
    meta = _json(raw["meta"], "meta")
    _need(isinstance(meta, dict), "meta: not a JSON object")
    tag = meta.get("format")
    _need(tag in (FORMAT, SENSED_FORMAT), f"not a controller file (format {quoted(tag)})")
    reads = READS if tag == FORMAT else SENSED_READS
    version = meta.get("version")
    _need(_is_int(version) and version in reads,
          f"format version {quoted(version)}; this mitld_lp reads versions "
          f"{', '.join(map(str, reads))} (save the controller again with it)")
    kind = "sensed" if tag == SENSED_FORMAT else meta.get("kind", "deterministic")
    members = layout(tag, kind, version) if isinstance(kind, str) else None
    _need(members is not None, f"meta.kind: {quoted(kind)} is not a controller kind of "
          f"format version {version}")
    assert members is not None
    _need(set(meta) == meta_keys(tag, kind, version),
          f"meta: unexpected keys {quoted(sorted(meta))}")
    _need(set(raw) == set(members), f"not a {kind} controller archive of format version "
          f"{version} (members {quoted(sorted(raw))})")
    for name, (dtype, ndim) in members.items():
        a = raw[name]
        _need(a.dtype == dtype and a.ndim == ndim, f"{name}: expected a {ndim}-D "
              f"{np.dtype(dtype).name} array, got {a.dtype} {a.shape}")
    if "first" in raw:  # the sensed format of old
        raw = {("fallback" if k == "first" else k): v for k, v in raw.items()}

    variables = meta.get("variables")
    if variables is not None:
        variables = _names(variables, "meta.variables", ordered=False)
    events = _names(meta["events"], "meta.events", ordered=True)
    actions = _names(meta["actions"], "meta.actions", ordered=False)
    _need(len(events) <= 30, "meta: too many events")
    states = _states(raw["states"], variables)
    fallback = raw["fallback"]
    _need(fallback.size == len(states),
          f"fallback: expected {len(states)} entries (one per world state)")
    _need(_in_range(fallback, 0, len(actions)), "fallback: an action number out of range")
    if kind.startswith("sensed"):
        return _sensed(raw, meta, events, actions, states, variables)
    return _automaton(raw, meta, kind, events, actions, states, variables)


def _states(raw: np.ndarray, variables: tuple[str, ...] | None) -> tuple[Hashable, ...]:
    encoded = _json(raw, "states")
    _need(isinstance(encoded, list), "states: not a JSON list")
    try:
        states = tuple(decode_state(v) for v in encoded)
    except (ValueError, RecursionError) as exc:
        raise _Bad(f"states: {clipped(str(exc))}") from None
    _need(len(set(states)) == len(states), "states: a world state appears twice")
    _need(variables is None or all(isinstance(s, tuple) and len(s) == len(variables)
                                   for s in states),
          "states: not tuples of the world's variables")
    return states


# --------------------------------------------------------------------------- by kind


def _automaton(raw: dict[str, np.ndarray], meta: dict[str, Any], kind: str,
               events: tuple[str, ...], actions: tuple[str, ...],
               states: tuple[Hashable, ...], variables: tuple[str, ...] | None) -> SavedPlan:
    atoms = _names(meta["atoms"], "meta.atoms", ordered=True)
    _need(len(atoms) <= 62, "meta: too many atoms or events")
    initial, verdicts, delta = _diagrams(meta["automaton"], atoms, kind)
    caps, truncations = _clock(meta["clock"], events)
    n_g, n_q = len(states), len(delta)
    props, keys = raw["props"], raw["keys"]
    _need(props.size == n_g, f"props and fallback: expected {n_g} entries (one per world state)")
    _need(_in_range(props, 0, 1 << len(atoms)), "props: not atom masks")
    n_clock = max(caps.values(), default=0) + 1
    bound = n_g * n_q * (1 << len(events)) * n_clock
    _need(bound < 1 << 63, "keys: the key space exceeds 64 bits")
    _need(bool(np.all(np.diff(keys) > 0)), "keys: not strictly increasing")
    _need(keys.size == 0 or (int(keys[0]) >= 0 and int(keys[-1]) < bound),
          "keys: a product state out of range")
    tables = {k: v for k, v in raw.items()
              if k not in ("meta", "states", "fallback", "props", "keys")}
    if kind == "randomised":
        if "keep" not in tables:  # version 2: no keep choice
            none = np.zeros(raw["choices"].size, dtype=np.bool_)
            tables.update(keep=none, kept=none.copy())
        _randomised_tables(tables, keys.size, len(actions))
    else:
        _need(tables["policy"].size == keys.size and tables["hopeless"].size == keys.size,
              "keys, policy and hopeless: not of one length")
        _need(_in_range(tables["policy"], -1, len(actions)),
              "policy: an action number out of range")
    return SavedPlan(
        kind=kind, atoms=atoms, events=frozenset(events), actions=actions, initial=initial,
        verdicts=verdicts, delta=delta, caps=caps, truncations=truncations, states=states,
        props=props, fallback_action=raw["fallback"], keys=keys, tables=tables,
        variables=variables,
    )


def _randomised_tables(t: dict[str, np.ndarray], n: int, n_actions: int) -> None:
    off = t["offsets"]
    _need(off.size == n + 1 and t["stay"].size == n and t["charged"].size == n,
          "keys, offsets, stay and charged: not of matching lengths")
    _need(int(off[0]) == 0 and bool(np.all(np.diff(off) >= 0))
          and int(off[-1]) == t["choices"].size,
          "offsets: not a partition of the choices")
    _need(all(t[k].size == t["choices"].size for k in ("weights", "inside", "keep", "kept")),
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


_ENDS = {v: k for k, v in ENDS.items()}  # moves code -> end
_INITIAL_ENDS = {v: k for k, v in END_NAMES.items()}  # meta.initial -> end


def _sensed(raw: dict[str, np.ndarray], meta: dict[str, Any], events: tuple[str, ...],
            actions: tuple[str, ...], states: tuple[Hashable, ...],
            variables: tuple[str, ...] | None) -> SensedPlan:
    sensed = _names(meta["sensed"], "meta.sensed", ordered=False)
    _need(set(sensed) <= set(events), "meta.sensed: not among the events")
    ignored = _names(meta.get("ignored", []), "meta.ignored", ordered=False)
    _need(set(ignored) <= set(sensed), "meta.ignored: not among the sensed events")
    moves, n_act = raw["moves"], len(actions)
    randomised = "stay" in raw
    if randomised:
        decisions = _decisions(raw, actions)
        n_info = len(decisions)
    else:
        policy = raw["policy"]
        n_info = policy.size
        _need(_in_range(policy, -1, n_act), "policy: an action number out of range")
    _need(moves.shape[1] == 5, f"moves: expected rows of 5, got {moves.shape}")
    src, act, world, mask, dst = moves.T
    _need(_in_range(src, 0, n_info), "moves: a state out of range")
    _need(_in_range(act, 0, n_act), "moves: an action out of range")
    _need(_in_range(world, 0, len(states)), "moves: a world state out of range")
    _need(_in_range(mask, 0, 1 << len(events)), "moves: an event mask out of range")
    _need(_in_range(dst, -len(ENDS), n_info), "moves: a next state out of range")
    initial = meta["initial"]
    if isinstance(initial, str):
        _need(initial in _INITIAL_ENDS, "meta.initial: not a state nor a verdict")
        start: int | str = _INITIAL_ENDS[initial]
    else:
        _need(_is_int(initial) and 0 <= initial < n_info, "meta.initial: out of range")
        start = initial
    hidden = frozenset(sensed)
    table: dict[tuple[int, str], dict[Obs, int | str]] = {}
    for s, a, w, m, d in moves.tolist():
        seen = frozenset(e for i, e in enumerate(events) if m >> i & 1)
        obs = (states[w], seen - hidden, seen & hidden)
        table.setdefault((s, actions[a]), {})[obs] = _ENDS[d] if d < 0 else d
    first = {w: actions[a] for w, a in zip(states, raw["fallback"].tolist(), strict=True)}
    if randomised:
        return MixedSensedPlan(
            initial=start, actions=(None,) * n_info, moves=table, sensed=hidden,
            events=frozenset(events), ignored=frozenset(ignored), first=first,
            variables=variables, decisions=decisions)
    return SensedPlan(
        initial=start, actions=tuple(None if a < 0 else actions[a] for a in policy.tolist()),
        moves=table, sensed=hidden, events=frozenset(events), ignored=frozenset(ignored),
        first=first, variables=variables)


def _decisions(raw: dict[str, np.ndarray], actions: tuple[str, ...]
               ) -> tuple[Decision | None, ...]:
    """A randomised sensed controller's decision per information state: its weighted
    choices, and the actions inside its end component (flagged, weight 0)."""
    off, choices, weights, inside, stay = (raw[k] for k in (
        "offsets", "choices", "weights", "inside", "stay"))
    n = stay.size
    _need(off.size == n + 1, "offsets and stay: not of matching lengths")
    _need(int(off[0]) == 0 and bool(np.all(np.diff(off) >= 0))
          and int(off[-1]) == choices.size, "offsets: not a partition of the choices")
    _need(weights.size == choices.size and inside.size == choices.size,
          "choices, weights and inside: not of one length")
    _need(_in_range(choices, 0, len(actions)), "choices: an action number out of range")
    for name, v in (("weights", weights), ("stay", stay)):
        _need(bool(np.all(np.isfinite(v) & (v >= 0) & (v <= 1))), f"{name}: not probabilities")
    _need(not bool(np.any(inside & (weights > 0))), "inside: an end component's action "
          "with a weight")
    out: list[Decision | None] = []
    for s in range(n):
        lo, hi = int(off[s]), int(off[s + 1])
        flag = inside[lo:hi]
        names = tuple(actions[c] for c in choices[lo:hi][~flag].tolist())
        w = weights[lo:hi][~flag]
        _need(not names or float(w.sum()) > 0, f"weights: state {s}'s choices weigh 0")
        if lo == hi and float(stay[s]) == 0.0:
            out.append(None)
            continue
        out.append(Decision(names, np.array(w), float(stay[s]),
                            tuple(actions[c] for c in choices[lo:hi][flag].tolist())))
    return tuple(out)


def _diagrams(
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
