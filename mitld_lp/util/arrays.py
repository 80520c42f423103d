"""Array kernels shared by the product construction and the solvers: integer sets
(:func:`unique`), a growable array (:class:`Grow`), an index of ids by key
(:class:`Index`: a plain array while the keys are dense, else a hash table), a memo over
integer keys (:class:`Memo`), and the row helpers of a batched sparse build
(:func:`ranks`, :func:`merge`, :func:`concatenate`), and the solvers' per-choice
helpers (:func:`index_dtype`, :func:`spread`).  Each works on a whole batch of
keys or entries at once, in numpy."""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = [
    "unique",
    "Grow",
    "Index",
    "Memo",
    "MISSING",
    "DENSE_LIMIT",
    "ranks",
    "merge",
    "concatenate",
    "narrow_copy",
    "index_dtype",
    "spread",
    "SLICE_STATES",
]


def unique(values: np.ndarray) -> np.ndarray:
    """The sorted distinct entries of a 1-d integer array, as ``np.unique(values)``.

    By sorting: numpy 2.4's ``np.unique`` goes through a hash table that was measured
    10x slower on 2e6 keys (1.7 s against 0.17 s) and ~0.8 ms a call on tiny arrays,
    which the level-by-level loops of the product and the solvers call thousands of
    times.
    """
    flat = np.sort(np.asarray(values).ravel())
    if flat.size == 0:
        return flat
    keep = np.empty(flat.size, dtype=bool)
    keep[0] = True
    np.not_equal(flat[1:], flat[:-1], out=keep[1:])
    return flat[keep]


class Grow:
    """A numpy array that grows by doubling (amortised O(1) appends of blocks)."""

    def __init__(self, dtype: Any) -> None:
        self.data = np.empty(64, dtype=dtype)
        self.size = 0

    @classmethod
    def of(cls, values: np.ndarray) -> Grow:
        """A :class:`Grow` holding ``values`` (not copied when contiguous)."""
        out = cls(values.dtype)
        out.data = np.ascontiguousarray(values)
        out.size = out.data.size
        return out

    def extend(self, values: Any) -> None:
        values = np.asarray(values, dtype=self.data.dtype)
        need = self.size + values.size
        if need > self.data.size:
            bigger = np.empty(max(need, 2 * self.data.size), dtype=self.data.dtype)
            bigger[: self.size] = self.data[: self.size]
            self.data = bigger
        self.data[self.size : need] = values
        self.size = need

    @property
    def view(self) -> np.ndarray:
        return self.data[: self.size]


MISSING = np.iinfo(np.int64).min
DENSE_LIMIT = 1 << 22  # keys below this are memoised in a plain array (32 MB at most)


class Memo:
    """A memo ``key -> int`` for arrays of non-negative keys, filled on demand.

    ``compute(keys)`` gives the values of distinct, sorted, unknown keys.  While the
    keys stay below ``DENSE_LIMIT`` the memo is a plain array (one gather per call);
    beyond, a hash index (:class:`Index`), so that sparse keys cost no more memory than
    the entries stored.
    """

    def __init__(self, compute: Any, space: int = 0) -> None:
        self.compute = compute
        self.table: np.ndarray | None = None
        self.index: Index | None = None
        if space <= DENSE_LIMIT:
            self.table = np.full(max(space, min(64, DENSE_LIMIT)), MISSING)
        else:
            self.index = Index()

    def _grow(self, top: int) -> None:
        assert self.table is not None
        if top <= DENSE_LIMIT:
            bigger = np.full(max(top, 2 * self.table.size), MISSING)
            bigger[: self.table.size] = self.table
            self.table = bigger
        else:  # too sparse for an array: move the entries to a hash index
            known = np.flatnonzero(self.table != MISSING)
            self.index = Index()
            self.index.insert(known, self.table[known])
            self.table = None

    def __call__(self, keys: np.ndarray) -> np.ndarray:
        if self.table is not None:
            top = int(keys.max(initial=-1)) + 1
            if top > self.table.size:
                self._grow(top)
        if self.table is not None:
            vals = self.table[keys]
            miss = vals == MISSING
            if miss.any():
                new = unique(keys[miss])
                self.table[new] = self.compute(new)
                vals[miss] = self.table[keys[miss]]
            return vals
        assert self.index is not None
        uniq, inverse = np.unique(keys, return_inverse=True)
        vals = self.index.find(uniq, absent=MISSING)
        miss = vals == MISSING
        if miss.any():
            vals[miss] = self.compute(uniq[miss])
            self.index.insert(uniq[miss], vals[miss])
        return vals[inverse]


class Index:
    """Ids (int32) by int64 key, probed for a whole batch of keys at once.

    With ``dense`` (a bound on the keys, e.g. :data:`DENSE_LIMIT`), while every key is
    in ``[0, dense)`` and they fill at least an eighth of ``[0, largest key]``, a plain
    array by key (4 bytes a key below the largest: one gather per batch, no hashing,
    no rehash); else, or once a key breaks either rule, open addressing over arrays
    (linear probing, load at most 1/2, Fibonacci hashing: 24 to 48 bytes an entry)."""

    _EMPTY = -(1 << 62)
    _SPARSE = 8  # the dense array holds at most this many slots per entry (past 64K)
    _CHUNK = 1 << 16  # entries placed (and slots moved in a rehash) at a time

    def __init__(self, dense: int = 0) -> None:
        self.dense_limit = dense
        self.dense: np.ndarray | None = np.full(64, -1, dtype=np.int32) if dense else None
        self.bits = 16
        self.keys = np.zeros(0, dtype=np.int64)  # the hash table's, made when needed
        self.ids = np.zeros(0, dtype=np.int32)
        self.size = 0
        if self.dense is None:
            self._empty_table()

    def _empty_table(self) -> None:
        self.keys = np.full(1 << self.bits, self._EMPTY, dtype=np.int64)
        self.ids = np.zeros(1 << self.bits, dtype=np.int32)

    def _home(self, keys: np.ndarray) -> np.ndarray:
        h = np.ascontiguousarray(keys, dtype=np.int64).view(np.uint64) * np.uint64(
            0x9E3779B97F4A7C15
        )
        return (h >> np.uint64(64 - self.bits)).view(np.int64)

    def find(self, keys: np.ndarray, absent: int = -1) -> np.ndarray:
        """The id of each key, ``absent`` where absent (keys may repeat)."""
        if self.dense is not None:
            out = np.full(keys.size, absent, dtype=np.int64)
            inside = np.flatnonzero((keys >= 0) & (keys < self.dense.size))
            got = self.dense[keys[inside]]
            known = got >= 0
            out[inside[known]] = got[known]
            return out
        at = self._home(keys)
        found = self.keys[at]
        hit = found == keys
        out = np.where(hit, self.ids[at], np.int64(absent)).astype(np.int64)
        todo = np.flatnonzero(~hit & (found != self._EMPTY))
        mask = (1 << self.bits) - 1
        at = at[todo]
        while todo.size:
            at = (at + 1) & mask
            found = self.keys[at]
            hit = found == keys[todo]
            out[todo[hit]] = self.ids[at[hit]]
            go_on = ~hit & (found != self._EMPTY)
            todo, at = todo[go_on], at[go_on]
        return out

    def insert(self, keys: np.ndarray, ids: np.ndarray) -> None:
        """Add distinct keys that are not in the index yet."""
        if keys.size == 0:
            return
        if self.dense is not None:
            top = int(keys.max()) + 1
            if (int(keys.min()) >= 0 and top <= self.dense_limit
                    and top <= max(1 << 16, self._SPARSE * (self.size + keys.size))):
                if top > self.dense.size:
                    bigger = np.full(min(max(top, 2 * self.dense.size), self.dense_limit), -1,
                                     dtype=np.int32)
                    bigger[: self.dense.size] = self.dense
                    self.dense = bigger
                self.dense[keys] = ids
                self.size += keys.size
                return
            dense, self.dense, self.size = self.dense, None, 0  # to a hash table, for good
            self._empty_table()
            self._grow(int(np.count_nonzero(dense >= 0)) + keys.size)
            for lo in range(0, dense.size, self._CHUNK):  # a slice at a time: no copy of all
                held = dense[lo : lo + self._CHUNK]
                known = np.flatnonzero(held >= 0)
                self._place(known + lo, held[known])
            del dense
        self._grow(self.size + keys.size)
        self._place(keys, ids)

    def _grow(self, need: int) -> None:
        """Make room for ``need`` entries at load at most 1/2: a table of twice the
        slots or more.  The old table's entries are gathered a slice at a time and the
        old table let go before the new one is made; each slice's entries are let go
        once placed (no hashes nor probes of all the entries at once)."""
        if 2 * need <= (1 << self.bits):
            return
        held = []
        for lo in range(0, self.keys.size, self._CHUNK):
            part = self.keys[lo : lo + self._CHUNK]
            full = np.flatnonzero(part != self._EMPTY)
            held.append((part[full], self.ids[lo : lo + self._CHUNK][full]))
        part = None  # a view: it would hold the old keys through the new table's making
        self.keys = self.ids = np.zeros(0, dtype=np.int64)
        while 2 * need > (1 << self.bits):
            self.bits += 1
        self._empty_table()
        self.size = 0
        held.reverse()
        while held:
            self._place(*held.pop())

    def _place(self, keys: np.ndarray, ids: np.ndarray) -> None:
        """Write distinct new keys into a table with room for them, ``_CHUNK`` keys at
        a time (the probes' work arrays bounded by a chunk, not by the batch)."""
        mask = (1 << self.bits) - 1
        for lo in range(0, keys.size, self._CHUNK):
            part, part_ids = keys[lo : lo + self._CHUNK], ids[lo : lo + self._CHUNK]
            pos = self._home(part)
            todo = np.arange(part.size)
            while todo.size:
                at = pos[todo]
                free = self.keys[at] == self._EMPTY
                # one winner per free slot; the others probe on
                _, first = np.unique(at[free], return_index=True)
                win = todo[free][first]
                self.keys[pos[win]] = part[win]
                self.ids[pos[win]] = part_ids[win]
                placed = np.zeros(part.size, dtype=bool)
                placed[win] = True
                todo = todo[~placed[todo]]
                pos[todo] = (pos[todo] + 1) & mask
            self.size += part.size


def ranks(counts: np.ndarray) -> np.ndarray:
    """``0 .. counts[i] - 1`` for each ``i``, concatenated."""
    total = int(counts.sum())
    starts = np.cumsum(counts) - counts
    return np.arange(total, dtype=np.int64) - np.repeat(starts, counts)


def merge(
    choice: np.ndarray, cols: np.ndarray, vals: np.ndarray, n_choices: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sum the entries of one choice that go to one state, in the order they come (so the
    sums are bit for bit those of a loop), keeping each row's first-occurrence order.
    Returns the merged cols, vals and the length of each choice's row."""
    key = choice * (int(cols.max(initial=0)) + 1) + cols
    order = np.argsort(key, kind="stable")
    sk = key[order]
    start = np.ones(sk.size, dtype=bool)
    start[1:] = sk[1:] != sk[:-1]
    if start.all():
        return cols, vals, np.bincount(choice, minlength=n_choices)
    group = np.cumsum(start) - 1
    heads = np.flatnonzero(start)
    rank = np.arange(sk.size) - heads[group]
    sv = vals[order]
    total = np.zeros(heads.size)
    for r in range(int(rank.max()) + 1):  # a handful of rounds: summation order kept
        at = rank == r
        total[group[at]] += sv[at]
    first = order[heads]  # each group's first entry in stream order
    keep = np.argsort(first, kind="stable")
    kept = first[keep]
    return cols[kept], total[keep], np.bincount(choice[kept], minlength=n_choices)


def concatenate(parts: list[Any], dtype: Any) -> np.ndarray:
    """``np.concatenate(parts)``, freeing each part once copied (peak: the result plus
    one part, not twice the result)."""
    out = np.empty(sum(p.size for p in parts), dtype=dtype)
    at = 0
    for i, part in enumerate(parts):
        out[at : at + part.size] = part
        at += part.size
        parts[i] = None
    return out


_INT32 = np.iinfo(np.int32)


def narrow_copy(values: np.ndarray) -> np.ndarray:
    """A copy of the integer array ``values`` as int32 when every entry fits (half the
    bytes of int64), else in its own type."""
    fits = values.size == 0 or (int(values.min()) >= _INT32.min
                                and int(values.max()) <= _INT32.max)
    return values.astype(np.int32 if fits else values.dtype, copy=True)


#: States a slice of a per-choice loop over :func:`spread`: each slice's gathered copies
#: are a few MB, not a float (and a mask) a choice of the whole product.
SLICE_STATES = 1 << 16


def index_dtype(largest: int) -> type:
    """``np.int32`` if every index up to ``largest`` (an array's length, a count) fits
    in it, else ``np.int64``: the solvers' state and choice arrays in half the bytes
    where the size allows, the wide type past 2**31 - 1 (never a wrapped index)."""
    if int(largest) < 0:
        raise ValueError(f"index_dtype: a size cannot be negative ({largest})")
    return np.int32 if int(largest) <= np.iinfo(np.int32).max else np.int64


def spread(per_state: np.ndarray, row_groups: np.ndarray, lo: int, hi: int) -> np.ndarray:
    """``per_state[s]`` repeated once for each choice of each state ``s`` in ``lo:hi``
    (state ``s`` owns the choices ``row_groups[s]:row_groups[s + 1]``): the gather
    ``per_state[choice_state]`` of those choices without the whole ``choice_state``
    (an int64 a choice of the product)."""
    return np.repeat(per_state[lo:hi], np.diff(row_groups[lo:hi + 1]))
