"""A controller as plain tables: what :meth:`mitld_lp.Controller.save` and
:meth:`mitld_lp.ConstrainedController.save` write; :mod:`mitld_lp.running.saved_plan` reads it
(with NumPy alone) for :meth:`~mitld_lp.Controller.load` and ``mitld-lp run``.

The file is a NumPy ``.npz`` archive of plain arrays (integers, floats, booleans, and
UTF-8 JSON text stored as bytes), read with ``allow_pickle=False``: loading parses
numbers and JSON and never runs code from the file, so a foreign or damaged file can
only be refused (:class:`ControllerFileError`).  It holds everything the controller
needs to run, and nothing of the world's Python objects, so a robot's process loads it
without the world's class (and without any solver):

* ``meta`` (JSON): the format tag and version (3; versions 1 and 2 are still read), the
  ``kind`` (``"deterministic"`` or ``"randomised"``), the world's ``variables`` (their
  names when a world state is a tuple of them, as in a PRISM world; else null), the
  automaton's atoms, the task's events, the action names, the automaton (its initial
  state, per state its transition function as a decision diagram over the atoms, see
  :mod:`mitld_lp.automata.dta`, and its accepting and rejecting states -- for a
  randomised controller instead per state the ``verdicts`` of the task and of each
  constraint's formula: 1 accepted, 0 rejected, -1 undecided), and the clock rule (per
  event its cap and truncation point, :func:`mitld_lp.automata.sta.advance_clock`);
* ``states`` (JSON): the world states the controller may observe, in the encoding of
  :func:`encode_state`; position ``g`` in this list is the state's number ``g``;
* ``props`` (int64, per state ``g``): its robot propositions, as a bit mask over the atoms;
* ``fallback`` (int32, per ``g``): its first action (taken where the policy has none);
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
  ``charged`` (bool per key: a step here counts towards E(steps)).  A version 2 file has
  no ``keep`` and ``kept``: it has no keep choice.

The world states listed are every state the world reaches from its initial one (under
any action and any events): the product's game states and those reached past a
truncation point, where the controller goes on (:func:`tabulate` explores them).

Pickling a controller in memory (to hand it to another process of the same program)
still works; pickle is never a file format here.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Hashable
from typing import Any

import numpy as np

from mitld_lp.automata.sta import STA
from mitld_lp.mdp import MDP
from mitld_lp.product import ProductState
from mitld_lp.running.plan_reader import read_plan
from mitld_lp.running.saved_plan import (
    FORMAT,
    UNDECIDED,
    VERSION,
    ControllerFileError,
    SavedPlan,
    decode_state,
    encode_state,
    key,
)
from mitld_lp.worlds.game import Game
from mitld_lp.worlds.names import world_variables

__all__ = [
    "ControllerFileError",
    "FORMAT",
    "VERSION",
    "SavedPlan",
    "decode_state",
    "encode_state",
    "read_plan",
    "tabulate",
    "tabulate_randomised",
]


class _World:
    """The world states a controller may observe, numbered as it meets them, with their
    propositions (a mask over ``atoms``) and first action."""

    def __init__(self, game: Game[Any], atoms: tuple[str, ...], actions: list[str],
                 max_states: int) -> None:
        self.game, self.actions, self.max_states = game, actions, max_states
        self.atom_bit = {a: 1 << i for i, a in enumerate(atoms)}
        self.action_id = {a: i for i, a in enumerate(actions)}
        self.index: dict[Hashable, int] = {}
        self.states: list[Hashable] = []
        self.props: list[int] = []
        self.fallback: list[int] = []
        self.number(game.initial)

    def number(self, s: Hashable) -> int:
        g = self.index.get(s)
        if g is None:
            _check_budget(len(self.states) + 1, self.max_states)
            g = self.index[s] = len(self.states)
            self.states.append(s)
            held = self.game.propositions(s)
            self.props.append(sum(bit for a, bit in self.atom_bit.items() if a in held))
            self.fallback.append(self.action(self.game.actions(s)[0]))
        return g

    def action(self, name: str) -> int:
        i = self.action_id.get(name)
        if i is None:
            i = self.action_id[name] = len(self.actions)
            self.actions.append(name)
        return i

    def close(self, events: list[str]) -> None:
        """Number every world state reachable under every action and every subset of
        ``events``."""
        _close(self.game, self.states, self.number, events)


def _product_keys(world: _World, sta: STA, n_q: int, mdp: MDP, rows: list[int]) -> list[int]:
    """The keys of the product states ``rows`` of ``mdp``."""
    events = sorted(sta.events)
    event_bit = {e: 1 << i for i, e in enumerate(events)}
    n_clock = max((c.cap for c in sta.clocks.values()), default=0) + 1
    out = []
    for i in rows:
        record = mdp.states[i]
        assert isinstance(record, ProductState)
        if not 0 <= record.clock < n_clock:
            raise ValueError(f"product state {i}: clock {record.clock} beyond the STA's caps")
        pending = sum(event_bit[e] for e in record.pending)
        out.append(key(world.number(record.game), record.automaton, pending, record.clock,
                       n_q, len(events), n_clock))
    return out


def _plan(kind: str, game: Game[Any], sta: STA, world: _World, verdicts: Any,
          keys: list[int], tables: dict[str, np.ndarray]) -> SavedPlan:
    dta = sta.dta
    return SavedPlan(
        kind=kind, atoms=dta.atoms, events=sta.events, actions=tuple(world.actions),
        initial=dta.initial, verdicts=tuple(tuple(v) for v in verdicts),
        delta=tuple(dta.delta), caps={a: c.cap for a, c in sta.clocks.items()},
        truncations=dict(sta.truncation_points), states=tuple(world.states),
        props=np.asarray(world.props, dtype=np.int64),
        fallback_action=np.asarray(world.fallback, dtype=np.int32),
        keys=np.asarray(keys, dtype=np.int64), tables=tables,
        variables=world_variables(game))


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
    world = _World(game, dta.atoms, list(mdp.action_names), max_states)
    rows = [i for i, r in enumerate(mdp.states) if isinstance(r, ProductState)]
    keys = _product_keys(world, sta, dta.n_states, mdp, rows)
    # a choice of an ordinary state: never ABSORB (-1, "none")
    chosen = [int(mdp.choice_actions[c]) if (c := int(policy[i])) >= 0 else -1 for i in rows]
    lost = [bool(hopeless[i]) if hopeless is not None else False for i in rows]
    world.close(sorted(sta.events))
    order = np.argsort(np.asarray(keys, dtype=np.int64), kind="stable")
    verdicts = [(1,) if q == dta.accepting else (0,) if q == dta.rejecting else (UNDECIDED,)
                for q in range(dta.n_states)]
    return _plan("deterministic", game, sta, world, verdicts,
                 np.asarray(keys, dtype=np.int64)[order].tolist(), {
                     "policy": np.asarray(chosen, dtype=np.int32)[order],
                     "hopeless": np.asarray(lost, dtype=np.bool_)[order]})


def tabulate_randomised(
    game: Game[Any],
    sta: STA,
    verdicts: Any,
    mdp: MDP,
    merged_of: np.ndarray,
    merged: MDP,
    prob: np.ndarray,
    stay: np.ndarray,
    inside: np.ndarray,
    charged: np.ndarray,
    skip: np.ndarray,
    *,
    keep: np.ndarray | None = None,
    kept: np.ndarray | None = None,
    max_states: int,
) -> SavedPlan:
    """The tables of a randomised controller on the product ``mdp`` of ``game`` with
    ``sta`` (whose automaton has per state the component ``verdicts``): product state
    ``i`` is state ``merged_of[i]`` of ``merged`` (-1: none), whose choice ``c`` is
    drawn with probability ``prob[c]`` (``inside[c]``: it stays in its end component),
    *stay* with ``stay[s]``; ``charged[s]``: steps there count; ``skip[s]``: no
    decision there (an absorbing state); ``keep[c]``: choice ``c`` is the *keep* choice
    (saved as action -1), ``kept[c]``: it stays in the end component of persistent task
    states (what a run plays once it has kept; both all false when None).  Budget and
    errors as :func:`tabulate`."""
    dta = sta.dta
    world = _World(game, dta.atoms, list(mdp.action_names), max_states)
    rows = [i for i, r in enumerate(mdp.states) if isinstance(r, ProductState)
            and merged_of[i] >= 0 and not skip[int(merged_of[i])]]
    keys = _product_keys(world, sta, dta.n_states, mdp, rows)
    order = np.argsort(np.asarray(keys, dtype=np.int64), kind="stable")
    offsets, choices, weights, inner, stays, charge = [0], [], [], [], [], []
    keeps: list[bool] = []
    plays: list[bool] = []
    none = np.zeros(merged.n_choices, dtype=bool)
    keep = none if keep is None else keep
    kept = none if kept is None else kept
    groups = merged.row_groups
    for j in order.tolist():
        s = int(merged_of[rows[j]])
        lo, hi = int(groups[s]), int(groups[s + 1])
        for c in range(lo, hi):
            choices.append(-1 if keep[c] else world.action(merged.action_name(c)))
            weights.append(float(prob[c]))
            inner.append(bool(inside[c]))
            keeps.append(bool(keep[c]))
            plays.append(bool(kept[c]))
        offsets.append(len(choices))
        stays.append(float(stay[s]))
        charge.append(bool(charged[s]))
    world.close(sorted(sta.events))
    return _plan("randomised", game, sta, world, verdicts,
                 np.asarray(keys, dtype=np.int64)[order].tolist(), {
                     "offsets": np.asarray(offsets, dtype=np.int64),
                     "choices": np.asarray(choices, dtype=np.int32),
                     "weights": np.asarray(weights, dtype=np.float64),
                     "inside": np.asarray(inner, dtype=np.bool_),
                     "stay": np.asarray(stays, dtype=np.float64),
                     "charged": np.asarray(charge, dtype=np.bool_),
                     "keep": np.asarray(keeps, dtype=np.bool_),
                     "kept": np.asarray(plays, dtype=np.bool_)})


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
