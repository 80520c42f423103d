"""Reading a saved controller's file, with NumPy alone: the archive parsed with
``allow_pickle=False`` (nothing in it is executed), every member and table checked, the
:class:`~mitld_lp.running.saved_plan.SavedPlan` returned; a foreign, damaged or
truncated file, or one of another format version, is refused by name
(:class:`~mitld_lp.running.saved_plan.ControllerFileError`).  The format is described
in :mod:`mitld_lp.running.controller_file`.  Imported by :mod:`mitld_lp.runtime`, so it
imports only the standard library, NumPy and the package's NumPy-only modules."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from mitld_lp.files import rules as file_rules
from mitld_lp.running.saved_plan import (
    _COMMON,
    _DETERMINISTIC,
    _KEEPS,
    _RANDOMISED,
    ACCEPTED,
    FORMAT,
    MEMBERS,
    READS,
    REJECTED,
    UNDECIDED,
    ControllerFileError,
    Diagram,
    SavedPlan,
    SensedControllerFile,
    _Bad,
    _clip,
    _members,
    _Sensed,
    _short,
    decode_state,
)

__all__ = ["read_plan"]

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

