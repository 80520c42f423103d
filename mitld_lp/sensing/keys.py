"""The information states of a build kept as arrays (:mod:`mitld_lp.sensing.frontier`):
their integer columns (:class:`Columns`) and the table that finds a state by its key
(:class:`Keys`), a dict of tuples or, once the compiled kernels run
(:func:`mitld_lp.sensing.rows.load_kernels`), an open-addressing hash table of packed
rows searched and filled by one kernel call a chunk
(:func:`mitld_lp.sensing.kernels.key_match`).  Either way a chunk's keys are numbered
as they come: a key met before gets its state, the ``k``-th key not met before
``-1 - k`` (the same for its repeats in the chunk), so both give the same arrays."""

from __future__ import annotations

from typing import Any

import numpy as np

from mitld_lp.sensing.rows import INT, Table, compiled_on, groups

__all__ = ["Columns", "Keys", "KeyedTable"]


class Columns:
    """``width`` integer columns grown by rows (by doubling): :meth:`col` and
    :meth:`rows` are views, no list converted."""

    def __init__(self, width: int) -> None:
        self.data = np.zeros((width, 1024), INT)
        self.n = 0

    def reserve(self, more: int) -> None:
        if self.n + more > self.data.shape[1]:
            grown = np.zeros((self.data.shape[0], max(self.n + more,
                                                     2 * self.data.shape[1])), INT)
            grown[:, :self.n] = self.data[:, :self.n]
            self.data = grown

    def append(self, values: tuple[int, ...]) -> None:
        """One row."""
        self.reserve(1)
        self.data[:, self.n] = values
        self.n += 1

    def extend(self, cols: tuple[np.ndarray, ...]) -> None:
        """Rows given as columns of equal length."""
        m = len(cols[0])
        self.reserve(m)
        for j, c in enumerate(cols):
            self.data[j, self.n:self.n + m] = c
        self.n += m

    def col(self, j: int) -> np.ndarray:
        return self.data[j, :self.n]

    def rows(self, a: int, b: int) -> list[np.ndarray]:
        """Every column's rows ``a .. b - 1`` (copies: the columns may grow)."""
        return [c.copy() for c in self.data[:, a:b]]


class Keys:
    """The states by their keys (rows of ``width`` integers; module docs)."""

    def __init__(self, width: int) -> None:
        self.width = width
        self.table: dict[tuple[int, ...], int] | None = {}
        self.keys = np.zeros((width, 0), INT)  # the compiled table's keys (a column
        # each) and states
        self.state = np.zeros(0, INT)
        self.slots = np.zeros(0, INT)
        self.n = 0
        self.fresh_at = 0  # where the last match's new keys begin
        self.pending: list[tuple[int, ...]] = []  # the dict's new keys

    def add(self, key: tuple[int, ...], state: int) -> None:
        """One key and its state."""
        self.match(tuple(np.array([v], INT) for v in key))
        self.settle(np.array([state], INT))

    def match(self, cols: tuple[np.ndarray, ...]) -> tuple[np.ndarray, np.ndarray]:
        """Each row's state (``-1 - k`` for the ``k``-th key not met before, the new
        keys entered as such until :meth:`settle`), and the first row of each new key."""
        kernels = compiled_on()
        m = len(cols[0])
        self.fresh_at = self.n
        if kernels and m:
            self.to_arrays()
            self.grow(m)
            self.fresh_at = self.n
            rows = np.stack([np.asarray(c, INT) for c in cols])  # a row per column
            out, reps, self.n = kernels.key_match(self.slots, self.keys, self.state,
                                                  self.n, rows)
            return out, reps
        assert self.table is not None or m == 0
        if m == 0:
            return np.zeros(0, INT), np.zeros(0, INT)
        # each distinct key looked up once, in the order of its first row (a level's
        # rows repeat few keys: 9,221 among 320,976 on the bus case's first levels)
        inverse, _ = groups(*cols)
        distinct, at = np.unique(inverse, return_index=True)  # each group's first row
        by_row = np.argsort(at, kind="stable")  # the groups as their first rows come
        rank = np.empty(len(distinct), INT)
        rank[by_row] = np.arange(len(distinct), dtype=INT)
        firsts = at[by_row]
        table = self.table
        values: list[int] = []
        reps: list[int] = []
        self.pending = []
        for i, key in zip(firsts.tolist(), zip(*(c[firsts].tolist() for c in cols),
                                                 strict=True), strict=True):
            v = table.get(key)
            if v is None:
                v = table[key] = -1 - len(reps)
                reps.append(i)
                self.pending.append(key)
            values.append(v)
        return np.asarray(values, INT)[rank[inverse]], np.asarray(reps, INT)

    def settle(self, states: np.ndarray) -> None:
        """The states of the last :meth:`match`'s new keys, in their order."""
        if self.table is None:
            self.state[self.fresh_at:self.n] = states
            return
        for key, state in zip(self.pending, states.tolist(), strict=True):
            self.table[key] = state
        self.pending = []

    def to_arrays(self) -> None:
        """The dict's keys moved into the compiled table (once, when the kernels come)."""
        if self.table is None:
            return
        items = list(self.table.items())
        self.table = None
        if items:
            self.grow(len(items))
            rows = np.array([k for k, _ in items], INT).reshape(len(items), self.width).T
            rows = np.ascontiguousarray(rows)
            _, _, self.n = compiled_on().key_match(self.slots, self.keys, self.state,
                                                   self.n, rows)
            self.state[:self.n] = [v for _, v in items]

    def grow(self, more: int) -> None:
        """Room for ``more`` keys: the rows' arrays by doubling, the slots kept at most
        half full (rehashed when grown)."""
        need = self.n + more
        if need > len(self.state):
            size = max(need, 2 * len(self.state), 1024)
            keys = np.zeros((self.width, size), INT)
            keys[:, :self.n] = self.keys[:, :self.n]
            state = np.zeros(size, INT)
            state[:self.n] = self.state[:self.n]
            self.keys, self.state = keys, state
        if 2 * need > len(self.slots):
            size = 1 << max(11, (4 * need - 1).bit_length())
            self.slots = np.full(size, -1, INT)
            compiled_on().key_rehash(self.slots, self.keys, self.n)


class KeyedTable(Table):
    """A :class:`~mitld_lp.sensing.rows.Table` whose keys are found by :class:`Keys`
    (compiled, once the kernels run) instead of a sort of the rows and a dict: the keys
    not met before are made in their lexicographic order, as :meth:`Table.find` makes
    them (the order numbers worlds, times and records), so the tables are the same."""

    def clear(self) -> None:
        super().clear()
        self.keyed: Keys | None = None

    def find(self, cols: tuple[np.ndarray, ...], make: Any) -> np.ndarray:
        if self.keyed is None:
            self.keyed = Keys(len(cols))
        target, reps = self.keyed.match(cols)
        if len(reps):
            new = list(zip(*(c[reps].tolist() for c in cols), strict=True))
            index = np.empty(len(new), INT)
            for k in sorted(range(len(new)), key=new.__getitem__):
                rows = make(new[k])
                index[k] = len(self.entries)
                self.entries.append(tuple(np.asarray([r[c] for r in rows], dtype=d)
                                          for c, d in enumerate(self.dtypes)))
            self.keyed.settle(index)
            fresh = target < 0
            target[fresh] = index[-1 - target[fresh]]
        return target
