"""A synthesis's model as a controller's plan, and its tables for saving.

:class:`LivePlan` (a deterministic policy on the product) and :class:`LiveRandomPlan`
(a constrained synthesis's randomised policy on its merged model) answer the one step
rule (:class:`~mitld_lp.controllers.stepper.Stepper`) from the world, the STA and the
product themselves; :func:`tabulate` and :func:`tabulate_randomised` turn them into a
:class:`~mitld_lp.controllers.tables.SavedPlan`, :func:`tabulate_sensed` a sensed
plan made by the synthesis into one that lists its world states: what the file holds
(:mod:`mitld_lp.controllers.format`).

The world states listed are every state the world reaches from its initial one (under
any action and any events): the product's game states and those reached past a
truncation point, where the controller goes on.
"""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Callable, Hashable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mitld_lp.automata.joint import Joint
from mitld_lp.automata.sta import STA
from mitld_lp.controllers.format import ACCEPTED, KEEP, REJECTED, UNDECIDED
from mitld_lp.controllers.stepper import AutomatonMemory, Decision
from mitld_lp.controllers.tables import SavedPlan, SensedPlan, key
from mitld_lp.mdp import MDP
from mitld_lp.product import ProductState, ProductStates
from mitld_lp.worlds.game import Game, world_members
from mitld_lp.worlds.names import world_variables

__all__ = ["LivePlan", "LiveRandomPlan", "tabulate", "tabulate_randomised", "tabulate_sensed"]


def _position(mdp: MDP, record: ProductState, index: dict[Hashable, int]) -> int | None:
    states = mdp.states
    return states.position(record) if isinstance(states, ProductStates) else index.get(record)


class _OnTheModel(AutomatonMemory):
    """What the synthesis's plans share: the automaton ``dta`` read on the world
    ``game``'s labels, the clock of the ``sta``, the world's first action."""

    __slots__ = ()

    game: Any
    sta: STA

    @property
    def dta(self) -> Any:
        raise NotImplementedError

    @property
    def events(self) -> frozenset[str]:
        return self.sta.events

    @property
    def initial(self) -> int:
        return self.dta.initial

    def read(self, q: int, state: Hashable, events: frozenset[str]) -> int:
        return self.dta.step(q, self.game.propositions(state) | events)

    def advance(self, pending: frozenset[str], clock: int) -> tuple[int, bool]:
        step = self.sta.advance(pending, clock)
        return step.clock, step.truncated

    def fallback(self, state: Hashable) -> str:
        return self.game.actions(state)[0]


_VERDICTS: dict[int, tuple[Any, tuple[tuple[int, ...], ...]]] = {}


def _once(source: Any, make: Callable[[], tuple[tuple[int, ...], ...]]
          ) -> tuple[tuple[int, ...], ...]:
    """The verdicts of each automaton state of ``source`` (an automaton, fixed once
    built), made on the first call for it: a controller reads them twice a step."""
    got = _VERDICTS.get(id(source))
    if got is None or got[0] is not source:
        if len(_VERDICTS) >= 256:
            _VERDICTS.clear()
        got = _VERDICTS[id(source)] = (source, make())
    return got[1]


@dataclass(frozen=True, slots=True, eq=False)
class LivePlan(_OnTheModel):
    """The synthesised model itself: the world, the STA, the product MDP, the policy
    (a choice per state, -1 where there is none) and the optional hopeless mask."""

    game: Game[Any]
    sta: STA
    mdp: MDP
    policy: np.ndarray
    hopeless: np.ndarray | None
    _index: dict[Hashable, int] = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        if not isinstance(self.mdp.states, ProductStates):  # a hand-made MDP: index it
            self._index.update((s, i) for i, s in enumerate(self.mdp.states))

    @property
    def randomised(self) -> bool:
        return False

    @property
    def dta(self) -> Any:
        return self.sta.dta

    @property
    def verdicts(self) -> tuple[tuple[int, ...], ...]:
        dta = self.sta.dta
        return _once(dta, lambda: tuple(
            (ACCEPTED,) if q == dta.accepting else (REJECTED,) if q == dta.rejecting
            else (UNDECIDED,) for q in range(dta.n_states)))

    def decide(self, state: Hashable, q: int, pending: frozenset[str], clock: int) -> Decision:
        i = _position(self.mdp, ProductState(state, q, pending, clock), self._index)
        if i is None:
            return Decision(())
        lost = self.hopeless is not None and bool(self.hopeless[i])
        c = int(self.policy[i])
        return Decision(() if c < 0 else (self.mdp.action_name(c),), lost=lost)

    def lookup(
        self, state: Hashable, q: int, pending: frozenset[str], clock: int
    ) -> tuple[str | None, bool]:
        d = self.decide(state, q, pending, clock)
        return (d.actions[0] if d.actions else None), d.lost

    def tables(self, max_states: int) -> SavedPlan:
        return tabulate(self.game, self.sta, self.mdp, self.policy, self.hopeless,
                        max_states=max_states)


@dataclass(frozen=True, slots=True, eq=False)
class LiveRandomPlan(_OnTheModel):
    """The constrained synthesis's model: the world, the STA of the joint automaton,
    the product, the merged model and the randomised policy on it."""

    game: Any
    sta: STA
    joint: Joint
    merged: Any  # mitld_lp.solvers.constrained_model.Merged
    mdp: MDP
    prob: np.ndarray
    stay: np.ndarray

    @property
    def randomised(self) -> bool:
        return True

    @property
    def dta(self) -> Any:
        return self.joint.dta

    @property
    def verdicts(self) -> tuple[tuple[int, ...], ...]:
        joint = self.joint
        return _once(joint, lambda: tuple(tuple(v) for v in joint.verdicts))

    def decide(self, state: Hashable, q: int, pending: frozenset[str], clock: int) -> Decision:
        i = _position(self.mdp, ProductState(state, q, pending, clock), {})
        m = self.merged
        s = -1 if i is None else int(m.of_product[i])
        if s < 0 or m.absorbing[s]:
            return Decision((), np.zeros(0))
        lo, hi = int(m.mdp.row_groups[s]), int(m.mdp.row_groups[s + 1])
        names = tuple(KEEP if m.keep[c] else m.mdp.action_name(c) for c in range(lo, hi))
        inside = tuple(n for n, flag in zip(names, m.internal[lo:hi], strict=True) if flag)
        kept = tuple(n for n, flag in zip(names, m.keep_internal[lo:hi], strict=True) if flag)
        keep = tuple(bool(k) for k in m.keep[lo:hi])
        return Decision(names, np.asarray(self.prob[lo:hi]), float(self.stay[s]), inside,
                        charged=bool(m.undecided[s]), keep=keep if any(keep) else (),
                        kept=kept)

    def tables(self, max_states: int) -> SavedPlan:
        m = self.merged
        return tabulate_randomised(
            self.game, self.sta, self.joint.verdicts, self.mdp, m.of_product, m.mdp,
            self.prob, self.stay, m.internal, m.undecided, m.absorbing,
            keep=m.keep, kept=m.keep_internal, max_states=max_states)


# --------------------------------------------------------------------------- tabulating


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
    (:func:`~mitld_lp.controllers.format.encode_state`).
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


def tabulate_sensed(plan: SensedPlan, max_states: int) -> SensedPlan:
    """``plan`` (a sensed controller's, made by the synthesis with its world) as a plan
    that lists its world states and their first actions instead, as a file holds it:
    every state reachable under every action and every set of the events the world
    reacts to.  Budget and errors as :func:`tabulate`."""
    game = plan.game
    if game is None:
        return plan
    index: dict[Hashable, int] = {}
    states: list[Hashable] = []

    def number(s: Hashable) -> int:
        g = index.get(s)
        if g is None:
            _check_budget(len(states) + 1, max_states)
            g = index[s] = len(states)
            states.append(s)
        return g

    number(game.initial)
    _close(game, states, number, sorted(world_members(game).event_names))
    return dataclasses.replace(plan, game=None, first={s: plan.fallback(s) for s in states},
                               variables=world_variables(game))


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
