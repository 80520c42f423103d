"""A controller small enough to read: an exact decision tree over named features.

The features of a state the controller acts in are the world's own (a grid cell's
``x`` and ``y``, a PRISM world's variables, else the world ``state`` itself), the
controller's memory -- the automaton state ``q``, one ``pending_<event>`` flag per event
(true while the event has not happened), the ``clock`` -- and nothing else.  A memory
feature whose name a world variable already has gets ``_`` appended until it is new
(a PRISM world with variables ``q`` and ``clock``: ``q_`` and ``clock_``), and the
``.py`` function's arguments are distinct Python names.  The tree
is grown top-down (the split of highest information gain, as CART and dtControl do)
until every leaf holds one decision, over exactly the states the controller can reach
(the controlled chain, :mod:`mitld_lp.running.chain`), so it picks the controller's own
decision in each of them: the action, or ``null`` where the task is lost and the
controller stops.  A randomised controller's leaf holds its distribution (the actions
with their probabilities, the probability of *stay* and, for a task with a safety
part, of *keep* with the actions a run that drew it plays for ever).

:func:`tree_controller` runs the tree in place of the controller's table and
:func:`tree_value` evaluates it exactly on its Markov chain (a sparse solve): it equals
the synthesis's ``lower``.

Written as JSON (``.json``: ``{"format", "features", "nodes", ...}``, a node either
``{"id", "feature", "op", "value", "yes", "no"}`` or a leaf ``{"id", "action"}``), as
Graphviz DOT (``.dot``) or as a plain Python function (``.py``) by :func:`write_tree`.
"""

from __future__ import annotations

import os
from collections.abc import Hashable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from mitld_lp.controllers.format import UNDECIDED
from mitld_lp.controllers.kinds import ControllerLike, PlanController
from mitld_lp.controllers.stepper import AutomatonMemory, Decision
from mitld_lp.files import write as files
from mitld_lp.product import ProductState
from mitld_lp.running.band_chain import band_chain_of, is_band
from mitld_lp.running.chain import chain_of, world_of
from mitld_lp.running.sensed_chain import is_sensed
from mitld_lp.running.tree_format import (
    Node,
    Tree,
    decision_label,
    fresh_name,
    identifier,
    label_decision,
)
from mitld_lp.running.tree_grow import grow
from mitld_lp.util.traversal import breadth_first_order
from mitld_lp.worlds.names import state_fields, state_values

__all__ = ["Tree", "TREE_SUFFIXES", "tree_of", "tree_controller", "tree_value", "write_tree"]

TREE_SUFFIXES = (".json", ".dot", ".py")


# --------------------------------------------------------------------------- features


def _features(result: Any, controller: ControllerLike) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """The world's features, then the memory's (``q``, ``pending_<event>``, ``clock``,
    each with ``_`` appended while a world feature has its name, or its Python name)."""
    game = world_of(result, controller)
    events = tuple(sorted(controller.events))
    world = state_fields(game)
    taken = set(world) | {identifier(f) for f in world}
    memory = ("q", *(f"pending_{e}" for e in events), "clock")
    return (*world, *(fresh_name(name, taken) for name in memory)), events


def _values(game: Any, rec: ProductState, events: tuple[str, ...]) -> tuple[Any, ...]:
    return (*state_values(game, rec.game), rec.automaton, *(e in rec.pending for e in events),
            rec.clock)


def _acting(result: Any, controller: ControllerLike) -> list[int]:
    """The product states the controller reaches and acts in (undecided ones)."""
    chain = (band_chain_of(result, controller) if is_band(result) else
             chain_of(result, controller))  # a band: the states reached under any law
    plan: Any = controller.plan
    out = []
    for i in sorted({int(i) for i in chain.origin if i >= 0}):
        rec = result.mdp.states[i]
        if isinstance(rec, ProductState) and UNDECIDED in plan.verdicts[rec.automaton]:
            out.append(i)
    return out


def _strict(result: Any, controller: ControllerLike, i: int) -> Hashable:
    """The controller's own decision at product state ``i``."""
    plan: Any = controller.plan
    rec = result.mdp.states[i]
    label = decision_label(plan.decide(rec.game, rec.automaton, rec.pending, rec.clock),
                   controller.randomised)
    return plan.fallback(rec.game) if label == "fallback" else label


_TIE = 1e-12
"""Two values closer than this, relative to the larger, are equal when the tree may pick
among actions (relative: two choices worth 1e-30 and 2.6e-30 are not tied)."""


def _choices(result: Any, controller: ControllerLike) -> dict[int, frozenset[Hashable]] | None:
    """Per product state, the actions that keep the controller's value exactly: with
    ``V`` the controller's exact values (``lower_model.policy_values``) and ``Q(s, a)``
    the value of ``a`` then ``V``, the actions with ``Q = V`` that, where ``V > 0``,
    move with positive probability closer to the goal in the graph of such actions (so
    no choice among them can loop away from it); in the goal (an accepting end
    component) only the controller's own action.  A controller that picks one of them
    in every state has the value ``V``: the Bellman equation holds, and no bottom
    component avoids the goal where ``V > 0``.  For a minimum solved as one
    (``result.sense == "min"``) every action with ``Q = V`` keeps it: a policy of them
    is worth at most ``V`` (its least fixed point), and at least the optimum ``V``.
    None for a randomised controller, whose decisions are kept."""
    if controller.randomised or result.lower_model is None:
        return None
    mdp = result.mdp
    v = np.asarray(result.lower_model.policy_values, dtype=np.float64)
    minimum = result.sense == "min"
    q = mdp.matrix @ v
    cs = mdp.choice_state()
    tight = np.abs(q - v[cs]) <= _TIE * np.maximum(np.abs(q), np.abs(v[cs]))
    goal = np.asarray(result.acceptance.goal, dtype=bool)
    # rank: steps to the goal along tight choices (a backward search over their edges)
    coo = mdp.matrix.tocoo()
    use = tight[coo.row] & (coo.data > 0) & ~goal[cs[coo.row]]
    src, dst = cs[coo.row[use]], coo.col[use]
    order = np.argsort(dst, kind="stable")
    src, dst = src[order], dst[order]
    starts = np.searchsorted(dst, np.arange(mdp.n_states + 1))
    rank = np.full(mdp.n_states, np.iinfo(np.int64).max, dtype=np.int64)
    frontier = np.flatnonzero(goal)
    rank[frontier] = 0
    step = 0
    while frontier.size:
        step += 1
        nxt = np.unique(np.concatenate([src[starts[j]:starts[j + 1]] for j in frontier]))
        nxt = nxt[rank[nxt] > step]
        rank[nxt] = step
        frontier = nxt
    out: dict[int, frozenset[Hashable]] = {}
    indptr, cols = mdp.matrix.indptr, mdp.matrix.indices
    for i, rec in enumerate(mdp.states):
        if not isinstance(rec, ProductState) or goal[i]:
            continue
        ok = set()
        for c in range(int(mdp.row_groups[i]), int(mdp.row_groups[i + 1])):
            if not tight[c]:
                continue
            succ = cols[indptr[c]:indptr[c + 1]]
            if v[i] <= 0 or minimum or (succ.size and int(rank[succ].min()) < int(rank[i])):
                ok.add(mdp.action_name(c))
        out[i] = frozenset(ok)
    return out


def _dataset(result: Any, controller: ControllerLike, states: Sequence[int],
             choices: dict[int, frozenset[Hashable]] | None
             ) -> tuple[list[tuple[Any, ...]], list[frozenset[Hashable]]]:
    """Per state, its features and the decisions the tree may take there."""
    game = world_of(result, controller)
    _, events = _features(result, controller)
    rows, allowed = [], []
    for i in states:
        rec = result.mdp.states[i]
        own = _strict(result, controller, i)
        extra = choices.get(i, frozenset()) if choices is not None else frozenset()
        rows.append(_values(game, rec, events))
        allowed.append(frozenset({own}) | extra)
    return rows, allowed


# --------------------------------------------------------------------------- growing


def tree_of(result: Any, controller: ControllerLike | None = None, *,
            same_actions: bool = False) -> Tree:
    """A decision tree for ``result``'s controller (or ``controller``, one of the same
    product), exact over the states it reaches (module docstring).

    By default the tree may pick, in a state, any action that keeps the controller's
    value exactly (:func:`_choices`), which makes it much smaller; it is grown until it
    is exact on every state *its own* controller reaches.  ``same_actions`` asks for the
    controller's own action in every state the controller reaches (always for a law
    within a band: every state it reaches under some law; with constraints and a band
    the states it reaches at the middle law of the bands, which are those it reaches
    under some law, as every hazard there is inside its band).  Either way
    :func:`tree_value` is the controller's value, ``lower``.  A controller that acts on
    sensor reports gives a finite-memory controller's tree, over the world's variables
    and its memory (:func:`mitld_lp.running.sensed_tree.sensed_tree_of`)."""
    if is_sensed(result):  # a finite-memory controller: its memory is what it observed
        from mitld_lp.running.sensed_tree import sensed_tree_of

        return sensed_tree_of(result, controller)
    c = controller or result.controller
    if c is None:
        raise ValueError(f"no controller: the synthesis is {result.status}")
    names, events = _features(result, c)
    # a band: the controller's own actions (another may not keep a worst case)
    choices = None if same_actions or is_band(result) else _choices(result, c)
    states = _acting(result, c)
    for _ in range(_ROUNDS):
        rows, allowed = _dataset(result, c, states, choices)
        nodes: list[Node] = []
        grow(rows, allowed, list(range(len(rows))), nodes,
              frozenset({len(names) - len(events) - 2}))  # q: its states are categories
        tree = Tree(names, events, tuple(nodes), bool(c.randomised), len(rows),
                    choices is None, _automaton_texts(result))
        if choices is None:
            return tree
        more = set(_acting(result, tree_controller(result, tree, c))) - set(states)
        if not more:
            return tree
        states = sorted(set(states) | more)
    return tree_of(result, controller, same_actions=True)


def _automaton_texts(result: Any) -> tuple[str, ...]:
    """What each automaton state stands for: the obligation left (a task's automaton)
    or the states of the task's and each constraint's automaton (a joint one)."""
    joint = getattr(result, "joint", None)
    if joint is not None:
        return tuple(" | ".join(str(part.states[k]) for part, k in zip(
            joint.parts, comp, strict=True)) for comp in joint.components)
    return tuple(str(s) for s in result.dta.states)


_ROUNDS = 20
"""Rounds of growing the tree on the states its controller reaches, before falling
back to the controller's own actions."""


# --------------------------------------------------------------------------- running it


class _TreePlan(AutomatonMemory):
    """A controller's tables with the policy replaced by the tree."""

    def __init__(self, plan: Any, tree: Tree, game: Any) -> None:
        self._plan, self.tree, self.game = plan, tree, game
        self.events, self.initial, self.verdicts = plan.events, plan.initial, plan.verdicts

    @property
    def randomised(self) -> bool:
        return self.tree.randomised

    def read(self, q: int, state: Hashable, events: frozenset[str]) -> int:
        return self._plan.read(q, state, events)

    def advance(self, pending: frozenset[str], clock: int) -> tuple[int, bool]:
        return self._plan.advance(pending, clock)

    def decide(self, state: Hashable, q: int, pending: frozenset[str], clock: int) -> Decision:
        rec = ProductState(state, q, pending, clock)
        label = self.tree.decide(_values(self.game, rec, self.tree.events))
        return label_decision(label, self.tree.randomised)

    def fallback(self, state: Hashable) -> str:
        return self._plan.fallback(state)


class TreeController(PlanController):
    """The tree run as a controller (the automaton and clock of the original); it is
    not saved (the tree is written by :func:`write_tree`)."""

    kind = "tree"

    def __init__(self, plan: _TreePlan, seed: int | None = 0) -> None:
        self._begin(plan, np.random.default_rng(seed))


def tree_controller(result: Any, tree: Tree, controller: ControllerLike | None = None
                    ) -> TreeController:
    """A controller that decides by ``tree`` (and tracks its memory as ``result``'s
    controller does)."""
    c = controller or result.controller
    if tree.memory is not None:  # a sensed controller's tree (running.sensed_tree)
        from mitld_lp.running.sensed_tree import sensed_tree_controller

        return sensed_tree_controller(result, tree, c)  # type: ignore[return-value]
    return TreeController(_TreePlan(c.plan, tree, world_of(result, c)))


def tree_value(result: Any, tree: Tree) -> float:
    """The exact probability that the tree's controller satisfies the task, in the
    lower model (truncation counts as failure): one sparse solve on its chain, over
    the states from which ``accept`` is reachable (the others have value 0)."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    from mitld_lp.running.band_mixture_chain import is_band_mixture

    if is_band(result) or is_band_mixture(result):
        raise ValueError("a band: the value is a worst case; Storm checks band_chain_of "
                         "(with constraints, band_mixture_chain.mixture_chain_drn)")
    chain = chain_of(result, tree_controller(result, tree))
    accept = chain.accepting()
    if accept[0]:
        return 1.0
    m = chain.matrix
    graph = sp.csr_array(m.T)  # who reaches accept: search the reversed edges
    reach = np.zeros(chain.n_states, dtype=bool)
    for j in np.flatnonzero(accept):
        if not reach[j]:
            reach[breadth_first_order(graph, int(j))] = True
    if not reach[0]:
        return 0.0
    u = np.flatnonzero(reach & ~accept)
    a = sp.identity(u.size, format="csr") - m[u][:, u]
    b = np.asarray(m[u][:, np.flatnonzero(accept)].sum(axis=1)).ravel()
    x = spla.spsolve(sp.csc_array(a), b)
    return float(np.atleast_1d(x)[int(np.searchsorted(u, 0))])


def write_tree(result: Any, path: str | os.PathLike[str], *, tree: Tree | None = None,
               overwrite: bool = False) -> Path:
    """Write the tree of ``result``'s controller (or ``tree``) to ``path`` in the format
    of its suffix: ``.json``, ``.dot`` or ``.py``."""
    out = files.writable_path(path, overwrite=overwrite, suffixes=TREE_SUFFIXES)
    t = tree or tree_of(result)
    suffix = out.suffix.lower()
    text = t.to_json() if suffix == ".json" else t.to_dot() if suffix == ".dot" else (
        t.to_python())
    return files.write_text(out, text, overwrite=True, suffixes=TREE_SUFFIXES)
