"""A controller that acts on sensor reports, as a file of plain tables.

:meth:`SensedController.save <mitld_lp.sensing.observe.SensedController.save>`
(:func:`mitld_lp.sensing.observe.save_sensed`) writes a NumPy ``.npz`` archive that
:func:`load_sensed` reads with ``allow_pickle=False`` (no code from the file is run; a
foreign or damaged file is refused with :class:`~mitld_lp.running.saved_plan.ControllerFileError`
naming it), in a process that needs neither the world's class nor a solver:

* ``meta`` (JSON): ``format`` ``"mitld-lp-sensed-controller"``, ``version`` 2, the
  task's ``events`` (sorted), the ``sensed`` ones, the ``ignored`` ones (sensed events
  whose reports come too late to matter, :mod:`mitld_lp.sensing.horizon`: the
  controller drops them; version 1 files, which have none, are read too), the
  ``actions`` (names), the ``initial`` information state (a number, or ``"accepted"`` /
  ``"rejected"`` / ``"decided"`` when the task is decided at step 0);
* ``states`` (JSON): the world states the robot can be in (every state the world reaches
  from its initial one), encoded as :func:`mitld_lp.running.saved_plan.encode_state` does;
* ``first`` (int32 per world state): its first action (played beyond the model);
* ``policy`` (int32 per information state): the action, -1 where nothing is left to do;
* ``moves`` (int64, one row per move): ``(state, action, world state seen, events
  seen as a bit mask over ``events``, next)``, ``next`` an information state, or -1
  (every hypothesis left accepted), -2 (every one rejected), -3 (decided, unknown
  which).
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from mitld_lp.files import rules as file_rules
from mitld_lp.product import Absorbing
from mitld_lp.running.saved_plan import ControllerFileError, decode_state
from mitld_lp.sensing.observe import _END, _NAMES, FORMAT, VERSION, SensedController

__all__ = ["load_sensed", "FORMAT", "VERSION", "MEMBERS"]

MEMBERS = frozenset({"meta", "states", "first", "policy", "moves"})


class _Bad(Exception):
    pass


def _need(ok: bool, what: str) -> None:
    if not ok:
        raise _Bad(what)


def load_sensed(path: str | os.PathLike[str]) -> SensedController:
    """The controller saved in ``path``; :class:`ControllerFileError` naming the file and
    the fault when it is not such a file."""
    source = Path(path)
    try:
        return _controller(_arrays(source))
    except _Bad as bad:
        raise ControllerFileError(f"{source}: cannot load the controller: {bad}") from None


def _arrays(source: Path) -> dict[str, np.ndarray]:
    try:
        with file_rules.open_archive(source) as handle:
            _need(handle.read(4) in (b"PK\x03\x04", b"PK\x05\x06"),
                  "not a NumPy archive")
            handle.seek(0)
            with np.load(handle, allow_pickle=False) as loaded:
                _need(set(loaded.files) == MEMBERS,
                      f"not a sensed controller (members {sorted(loaded.files)}, expected "
                      f"{', '.join(sorted(MEMBERS))})")
                return {name: loaded[name] for name in MEMBERS}
    except _Bad:
        raise
    except OSError as exc:
        raise _Bad(exc.strerror or type(exc).__name__) from None
    except Exception as exc:  # noqa: BLE001 - any parse failure of a foreign file
        raise _Bad(f"a damaged or foreign archive ({type(exc).__name__})") from None


def _json(raw: np.ndarray, what: str) -> Any:
    _need(raw.dtype == np.uint8 and raw.ndim == 1, f"{what}: expected JSON bytes")
    try:
        return json.loads(raw.tobytes().decode("utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError):
        raise _Bad(f"{what}: not JSON text") from None


def _names(x: Any, what: str) -> list[str]:
    _need(isinstance(x, list) and all(isinstance(v, str) for v in x)
          and len(set(x)) == len(x), f"{what}: expected a list of distinct names")
    return list(x)


def _controller(t: dict[str, np.ndarray]) -> SensedController:
    meta = _json(t["meta"], "meta")
    _need(isinstance(meta, dict) and meta.get("format") == FORMAT,
          "not a sensed controller (meta.format)")
    _need(meta.get("version") in (1, VERSION), f"version {meta.get('version')!r} is not "
                                               f"read (this module reads 1 and {VERSION})")
    events = _names(meta.get("events"), "meta.events")
    sensed = _names(meta.get("sensed"), "meta.sensed")
    _need(set(sensed) <= set(events), "meta.sensed: not among the events")
    ignored = _names(meta.get("ignored", []) if meta["version"] > 1 else [], "meta.ignored")
    _need(set(ignored) <= set(sensed), "meta.ignored: not among the sensed events")
    actions = _names(meta.get("actions"), "meta.actions")
    raw_states = _json(t["states"], "states")
    _need(isinstance(raw_states, list), "states: expected a list")
    try:
        worlds = [decode_state(v) for v in raw_states]
    except ValueError as exc:
        raise _Bad(f"states: {exc}") from None
    _need(len(set(worlds)) == len(worlds), "states: a world state appears twice")
    first, policy, moves = t["first"], t["policy"], t["moves"]
    _need(first.dtype == np.int32 and first.shape == (len(worlds),),
          "first: expected one int32 per world state")
    _need(policy.dtype == np.int32 and policy.ndim == 1, "policy: expected int32")
    n_info, n_act = policy.shape[0], len(actions)
    for name, arr in (("first", first), ("policy", policy)):
        _need(bool(np.all((arr >= -1 if name == "policy" else arr >= 0) & (arr < n_act))),
              f"{name}: an action number out of range")
    _need(moves.dtype == np.int64 and moves.ndim == 2 and moves.shape[1] == 5,
          "moves: expected int64 rows of 5")
    if moves.size:
        src, act, world, mask, dst = moves.T
        _need(bool(np.all((src >= 0) & (src < n_info))), "moves: a state out of range")
        _need(bool(np.all((act >= 0) & (act < n_act))), "moves: an action out of range")
        _need(bool(np.all((world >= 0) & (world < len(worlds)))),
              "moves: a world state out of range")
        _need(bool(np.all((mask >= 0) & (mask < (1 << len(events))))),
              "moves: an event mask out of range")
        _need(bool(np.all((dst >= -3) & (dst < n_info))), "moves: a next state out of range")
    initial = meta.get("initial")
    ends = {v: k for k, v in _NAMES.items()}
    if isinstance(initial, str):
        _need(initial in ends, "meta.initial: not a state nor a verdict")
        start: int | Absorbing = ends[initial]
    else:
        _need(isinstance(initial, int) and not isinstance(initial, bool)
              and 0 <= initial < n_info, "meta.initial: out of range")
        start = initial
    back = {v: k for k, v in _END.items()}
    sensed_set = frozenset(sensed)
    table: dict[tuple[int, str], dict[Any, int | Absorbing]] = {}
    for s, a, w, m, d in moves.tolist():
        seen = frozenset(e for i, e in enumerate(events) if m >> i & 1)
        obs = (worlds[w], seen - sensed_set, seen & sensed_set)
        table.setdefault((s, actions[a]), {})[obs] = back[d] if d < 0 else d
    return SensedController(
        initial=start, actions=[None if a < 0 else actions[a] for a in policy.tolist()],
        moves=table, sensed=sensed, events=events, ignored=ignored,
        first_actions={w: actions[a] for w, a in zip(worlds, first.tolist(), strict=True)})
