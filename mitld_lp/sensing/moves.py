"""The controller's moves of an information-state product, kept as arrays
(:class:`Moves`): ``moves[(state, action)][obs]`` is made when asked for, so a product of
a million transitions does not hold a million Python observations it may never use."""

from __future__ import annotations

import zlib
from collections.abc import Hashable, Iterator, Mapping, Sequence
from typing import Any

import numpy as np

from mitld_lp.sensing import compiled
from mitld_lp.sensing.info import Obs
from mitld_lp.sensing.rows import groups, narrow, ordered_groups

__all__ = ["Moves", "PackedRuns", "level_moves"]


class PackedRuns:
    """A level's runs of rows (each run some narrow integer columns) kept as one zlib
    stream (level 1) until a controller first reads one of the level's choices
    (:meth:`Moves.level`): the moves are read only after the solve, which they would
    otherwise sit through.  On issue 45's sensed case the moves' 8.2 bytes a transition
    pack into 1.4 (some 45 ms CPU in the build); :meth:`unpack` gives the columns back
    to the bit, read-only."""

    __slots__ = ("blob", "layout")

    def __init__(self, runs: Sequence[Sequence[np.ndarray]]) -> None:
        cols = [[np.ascontiguousarray(x) for x in run] for run in runs]
        self.layout = tuple(tuple((x.dtype.str, len(x)) for x in run) for run in cols)
        self.blob = zlib.compress(b"".join(x.tobytes() for run in cols for x in run), 1)

    def unpack(self) -> tuple[tuple[np.ndarray, ...], ...]:
        data, at, out = zlib.decompress(self.blob), 0, []
        for run in self.layout:
            cols = []
            for dtype, n in run:
                x = np.frombuffer(data, dtype, n, at) if n else np.zeros(0, dtype)
                at += x.nbytes
                cols.append(x)
            out.append(tuple(cols))
        return tuple(out)

    def __iter__(self) -> Iterator[tuple[np.ndarray, ...]]:
        """The runs unpacked, as a level's plain sequence of runs iterates."""
        return iter(self.unpack())

    def __len__(self) -> int:
        return len(self.layout)


class Moves(Mapping[tuple[int, str], Mapping[Obs, Any]]):
    """``moves[(i, action)]``: for an information state ``i`` and one of its world
    state's actions, each observation's successor (a state's index, or an absorbing
    record when nothing undecided is left with it: :class:`~mitld_lp.sensing.info.Belief`).

    Built from one row per (choice, observation), the rows of each level of the build
    apart (``levels``: each level's first choice row, non-decreasing, and its runs of
    rows, each run five arrays): ``choice`` the MDP's choice row less the level's first
    (below the next level's first: int16 where a level has fewer than 32,768 choices),
    ``world``, ``occurred`` and ``new`` the observation's
    world state, unsensed events and new reports as indices into ``worlds``,
    ``unsensed_sets`` and ``sensed_sets``, ``target`` a state's index, or ``-1 - r`` for
    ``records[r]``.  A choice's rows are those of its level's runs in their order
    (run by run, each run's in its own order).  A level's rows are put in choice order
    when one of its choices is first asked for, not while the product is built.
    ``row_groups``: each state's first choice row; ``state_world``: each state's world
    index (-1 for an absorbing state); ``world_actions``: each world index's action
    names in choice order."""

    def __init__(self, row_groups: np.ndarray, state_world: np.ndarray,
                 world_actions: Mapping[int, Sequence[str]], worlds: Sequence[Hashable],
                 unsensed_sets: Sequence[frozenset[str]],
                 sensed_sets: Sequence[frozenset[str]], records: Sequence[Hashable],
                 levels: Sequence[tuple[int, Sequence[tuple[np.ndarray, ...]] | PackedRuns]]
                 ) -> None:
        self.bases = np.array([b for b, _ in levels], np.int64)
        self.levels = [runs for _, runs in levels]
        self.indexed: dict[int, tuple[np.ndarray, np.ndarray, list[np.ndarray]]] = {}
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

    def level(self, k: int) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
        """Level ``k``'s rows in choice order (a stable sort of its runs' rows): each of
        its choices' first row in that order (from the level's first choice on), the
        order, and the columns ``world``, ``occurred``, ``new``, ``target``."""
        found = self.indexed.get(k)
        if found is None:
            runs = self.levels[k] if k < len(self.levels) else ()
            if isinstance(runs, PackedRuns):
                runs = runs.unpack()
            cols = [np.concatenate([r[j] for r in runs]) if runs else np.zeros(0, np.int64)
                    for j in range(5)]
            local = cols[0].astype(np.int64)  # each row's choice less the level's first
            order = np.argsort(local, kind="stable")
            ptr = np.zeros(int(local.max(initial=-1)) + 2, np.int64)
            np.cumsum(np.bincount(local, minlength=len(ptr) - 1), out=ptr[1:])
            found = self.indexed[k] = (ptr, order, cols[1:])
        return found

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
            k = int(np.searchsorted(self.bases, c, side="right")) - 1  # its level
            ptr, order, (world, occurred, new, target) = self.level(max(k, 0))
            at = c - int(self.bases[k]) if k >= 0 else -1
            rows = order[ptr[at]:ptr[at + 1]] if 0 <= at < len(ptr) - 1 else order[:0]
            table = self.made[c] = {
                (self.worlds[w], self.unsensed_sets[o], self.sensed_sets[n]):
                    (j if j >= 0 else self.records[-1 - j])
                for w, o, n, j in zip(world[rows].tolist(), occurred[rows].tolist(),
                                      new[rows].tolist(), target[rows].tolist(),
                                      strict=True)}
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


def level_moves(fb: Any, base: int, grouped: tuple[np.ndarray, ...], target: np.ndarray,
                ended: tuple[np.ndarray, ...], trunc: int) -> tuple[int, PackedRuns]:
    """The controller's moves of a level's choices in :class:`Moves`' form (``base``:
    its first choice's row; ``fb`` the frontier builder, for the kernels): each
    observation ``grouped`` its successor state ``target``, or, when nothing undecided
    is left with it (the rows ``ended``), the verdict: the one record its hypotheses
    ended in, or ``trunc`` (:attr:`Absorbing.TRUNCATED`'s record) when they disagree
    (the robot cannot tell which).  Each column in the narrowest integer type that
    holds it (:func:`~mitld_lp.sensing.rows.narrow`), packed (:class:`PackedRuns`): kept
    until the controller is made."""
    found = compiled.decided_alone(fb, ended, grouped)
    if found is not None:  # by the kernels: one pass
        pick, one = found
        c, w2, occ, new, _ = ended
        code = -1 - np.where(one >= 0, one, trunc)
    else:
        _, once = ordered_groups(*ended)  # each (observation, record) once
        c, w2, occ, new, end = (x[once] for x in ended)
        obs, first = ordered_groups(c, w2, occ, new)
        kinds = np.bincount(obs)
        n = len(grouped[0])
        both, _ = groups(*(np.concatenate([g, e[first]]) for g, e in
                            zip(grouped, (c, w2, occ, new), strict=True)))
        alone = ~np.isin(both[n:], both[:n])  # no undecided hypothesis left with it
        pick = first[alone]
        code = -1 - np.where(kinds[alone] == 1, end[pick], trunc)
    gc, gw, go, gn = grouped
    # the choices as rows of the level (from ``base``): int16 where the level's choices
    # are fewer than 32,768, not the product's row numbers in int32
    return base, PackedRuns((tuple(narrow(x) for x in (gc, gw, go, gn, target)),
                             tuple(narrow(x) for x in (c[pick], w2[pick], occ[pick],
                                                       new[pick], code))))
