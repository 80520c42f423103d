"""The decision tree of a controller that acts on sensor reports (the ``sensed`` and
``sensed-constrained`` routes): a finite-memory controller whose memory is what the
robot has observed.

Such a controller's memory is its information state (the hypotheses of when the sensed
events happened, :mod:`mitld_lp.sensing.belief`), a number its tables move at every
observation; its decision is a function of that memory.  The tree written here decides
on the world's variables (as :mod:`mitld_lp.running.tree`) and the memory, a category,
grown until it takes the controller's own decision on every (world state, memory) pair
the controller can reach -- found from the memory's table, from the initial memory by
every move the table lists, so every pair of the controlled chain
(:mod:`mitld_lp.running.sensed_chain`) is among them.  The memory's update is the
controller's own table and is written with the tree
(:class:`~mitld_lp.running.tree_format.Memory`: the ``memory`` key of the JSON, the
``INITIAL``, ``MOVES`` and ``update`` of the ``.py``), so the file is a whole
controller: the tree does not replace the tables that move the memory, it replaces the
table of decisions.

:func:`sensed_tree_controller` runs it (the tree's decisions, the original memory), and
the controlled chain of that controller (``sensed_chain_of(result, controller=...)``)
is the controller's: Storm's ``P=? [F "accept"]`` on it is at least ``lower``.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Hashable
from enum import Enum
from typing import Any

import numpy as np

from mitld_lp.controllers.kinds import ControllerLike, PlanController
from mitld_lp.controllers.stepper import Decision
from mitld_lp.running.tree_format import (
    Memory,
    Tree,
    decision_label,
    fresh_name,
    identifier,
    label_decision,
)
from mitld_lp.running.tree_grow import grow
from mitld_lp.worlds.names import state_fields, state_values

__all__ = ["sensed_tree_of", "sensed_tree_controller", "reached_memories"]


def reached_memories(plan: Any, start: Hashable) -> list[tuple[Hashable, int]]:
    """The (world state, memory) pairs a sensed ``plan`` can reach from world state
    ``start``: its initial memory there, then every move its table lists from a memory
    reached (ends, strings, are not acting memories and are left out), in order."""
    first = plan.start(start)
    seen: set[tuple[Hashable, Any]] = set()
    out: list[tuple[Hashable, int]] = []
    todo: deque[tuple[Hashable, Any]] = deque([(start, first)])
    by_memory: dict[Any, list[tuple[str, Any]]] = {}
    for (m, action), table in plan.moves.items():
        by_memory.setdefault(m, []).append((action, table))
    while todo:
        g, m = todo.popleft()
        if (g, m) in seen or isinstance(m, str) or m < 0:
            continue
        seen.add((g, m))
        out.append((g, int(m)))
        for _, table in by_memory.get(m, ()):
            for obs, nxt in table.items():
                todo.append((obs[0], nxt))
    return out


def sensed_tree_of(result: Any, controller: ControllerLike | None = None) -> Tree:
    """The tree of the module docstring for a sensed ``result``'s controller (or
    ``controller``, one of the same model)."""
    c = controller or result.controller
    if c is None:
        raise ValueError(f"no controller: the synthesis is {result.status}")
    plan: Any = c.plan
    game = result.model.game
    world = state_fields(game)
    taken = set(world) | {identifier(f) for f in world}
    names = (*world, fresh_name("memory", taken))
    randomised = bool(plan.randomised)
    rows, allowed = [], []
    pairs = reached_memories(plan, game.initial)
    for g, m in pairs:
        label = decision_label(plan.decision(g, m), randomised)
        if label == "fallback":
            label = plan.fallback(g)
        rows.append((*state_values(game, g), m))
        allowed.append(frozenset({label}))
    nodes: list[Any] = []
    grow(rows, allowed, list(range(len(rows))), nodes, frozenset({len(names) - 1}))
    moves = tuple(
        (_value(m), action, tuple(state_values(game, obs[0])), tuple(sorted(obs[1])),
         tuple(sorted(obs[2])), _value(nxt))
        for (m, action), table in sorted(plan.moves.items(), key=lambda kv: repr(kv[0]))
        for obs, nxt in table.items())
    return Tree(names, (), tuple(nodes), randomised, len(rows), True,
                memory=Memory(_value(plan.initial), moves))


def _value(memory: Any) -> int | str:
    """A memory as the files write it: a number, or an end by its name."""
    if isinstance(memory, Enum):
        return str(memory.value)
    return memory if isinstance(memory, str) else int(memory)


class _SensedTreePlan:
    """A sensed controller's plan with its decisions read from the tree (the memory's
    moves, verdicts and fallback are the plan's own)."""

    def __init__(self, plan: Any, tree: Tree, game: Any) -> None:
        self._plan, self.tree, self.game = plan, tree, game

    def __getattr__(self, name: str) -> Any:
        return getattr(self._plan, name)

    @property
    def randomised(self) -> bool:
        return self.tree.randomised

    def decision(self, state: Hashable, memory: Any) -> Decision:
        if isinstance(memory, str) or memory < 0:
            return Decision(())
        label = self.tree.decide((*state_values(self.game, state), memory))
        return label_decision(label, self.tree.randomised)


class SensedTreeController(PlanController):
    """The tree run as a sensed controller (the memory of the original); not saved (the
    tree is written by :func:`mitld_lp.running.tree.write_tree`)."""

    kind = "sensed-tree"
    sensed = True

    def __init__(self, plan: _SensedTreePlan, seed: int | None = 0) -> None:
        self._begin(plan, np.random.default_rng(seed))


def sensed_tree_controller(result: Any, tree: Tree, controller: ControllerLike | None = None
                           ) -> SensedTreeController:
    """A controller that decides by ``tree`` and moves its memory as ``result``'s
    controller (or ``controller``) does."""
    c = controller or result.controller
    return SensedTreeController(_SensedTreePlan(c.plan, tree, result.model.game))
