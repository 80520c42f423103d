"""The controller's moves of an information-state product, kept as arrays
(:class:`Moves`): ``moves[(state, action)][obs]`` is made when asked for, so a product of
a million transitions does not hold a million Python observations it may never use."""

from __future__ import annotations

from collections.abc import Hashable, Iterator, Mapping, Sequence
from typing import Any

import numpy as np

from mitld_lp.sensing.info import Obs

__all__ = ["Moves"]


class Moves(Mapping[tuple[int, str], Mapping[Obs, Any]]):
    """``moves[(i, action)]``: for an information state ``i`` and one of its world
    state's actions, each observation's successor (a state's index, or an absorbing
    record when nothing undecided is left with it: :class:`~mitld_lp.sensing.info.Belief`).

    Built from one row per (choice, observation): ``choice`` the MDP's choice row,
    ``world``, ``occurred`` and ``new`` the observation's world state, unsensed events
    and new reports as indices into ``worlds``, ``unsensed_sets`` and ``sensed_sets``,
    ``target`` a state's index, or ``-1 - r`` for ``records[r]``.  ``row_groups``: each
    state's first choice row; ``state_world``: each state's world index (-1 for an
    absorbing state); ``world_actions``: each world index's action names in choice
    order."""

    def __init__(self, row_groups: np.ndarray, state_world: np.ndarray,
                 world_actions: Mapping[int, Sequence[str]], worlds: Sequence[Hashable],
                 unsensed_sets: Sequence[frozenset[str]],
                 sensed_sets: Sequence[frozenset[str]], records: Sequence[Hashable],
                 choice: np.ndarray, world: np.ndarray, occurred: np.ndarray,
                 new: np.ndarray, target: np.ndarray) -> None:
        order = np.argsort(choice, kind="stable")
        self.ptr = np.zeros(int(row_groups[-1]) + 1, np.int64)
        np.cumsum(np.bincount(choice, minlength=len(self.ptr) - 1), out=self.ptr[1:])
        self.world, self.occurred = world[order], occurred[order]
        self.new, self.target = new[order], target[order]
        self.row_groups, self.state_world = row_groups, state_world
        self.world_actions = {w: {a: k for k, a in enumerate(acts)}
                              for w, acts in world_actions.items()}
        self.names = world_actions
        self.worlds, self.records = worlds, records
        self.unsensed_sets, self.sensed_sets = unsensed_sets, sensed_sets
        self.made: dict[int, dict[Obs, Any]] = {}
        used, times = np.unique(state_world[state_world >= 0], return_counts=True)
        self.size = sum(len(world_actions[w]) * k for w, k in zip(
            used.tolist(), times.tolist(), strict=True))

    def choice(self, key: tuple[int, str]) -> int | None:
        try:
            i, action = key
            w = int(self.state_world[i]) if 0 <= i < len(self.state_world) else -1
        except (TypeError, ValueError):
            return None
        k = self.world_actions.get(w, {}).get(action) if w >= 0 else None
        return None if k is None else int(self.row_groups[i]) + k

    def __getitem__(self, key: tuple[int, str]) -> Mapping[Obs, Any]:
        c = self.choice(key)
        if c is None:
            raise KeyError(key)
        table = self.made.get(c)
        if table is None:
            lo, hi = int(self.ptr[c]), int(self.ptr[c + 1])
            table = self.made[c] = {
                (self.worlds[w], self.unsensed_sets[o], self.sensed_sets[n]):
                    (j if j >= 0 else self.records[-1 - j])
                for w, o, n, j in zip(self.world[lo:hi].tolist(),
                                      self.occurred[lo:hi].tolist(),
                                      self.new[lo:hi].tolist(),
                                      self.target[lo:hi].tolist(), strict=True)}
        return table

    def __iter__(self) -> Iterator[tuple[int, str]]:
        for i, w in enumerate(self.state_world.tolist()):
            if w >= 0:
                for action in self.names[w]:
                    yield (i, action)

    def __len__(self) -> int:
        return self.size

    def __contains__(self, key: object) -> bool:
        return isinstance(key, tuple) and self.choice(key) is not None  # type: ignore[arg-type]

