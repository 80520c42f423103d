"""The array kernels (``mitld_lp.util.arrays``) against plain Python dictionaries and loops."""

from __future__ import annotations

import numpy as np
import pytest

from mitld_lp.util import arrays
from mitld_lp.util.arrays import Grow, Index, Memo, concatenate, merge, ranks


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_index_finds_what_was_inserted_across_growth(seed):
    rng = np.random.default_rng(seed)
    index, truth = Index(), {}
    for _ in range(20):  # batches that force several rehashes (start: 2^16 slots)
        keys = np.unique(rng.integers(-(1 << 60), 1 << 60, size=int(rng.integers(1, 9000))))
        keys = keys[[int(k) not in truth for k in keys]]
        ids = rng.integers(0, 1 << 31, size=keys.size).astype(np.int32)
        index.insert(keys, ids)
        truth.update(zip(keys.tolist(), ids.tolist(), strict=True))
        probe = np.concatenate([keys, rng.integers(-(1 << 60), 1 << 60, size=100)])
        want = [truth.get(k, -7) for k in probe.tolist()]
        assert index.find(probe, absent=-7).tolist() == want
    assert index.size == len(truth)



@pytest.mark.parametrize("seed, spread, moves", [
    (0, 1 << 12, False),      # dense keys: the plain array throughout
    (1, 1 << 20, True),       # past the bound (2^18): moved to the hash table
    (2, 1 << 17, True),       # within the bound, but an eighth of the range is not filled
])
def test_a_dense_index_finds_what_a_dictionary_holds(seed, spread, moves):
    rng = np.random.default_rng(seed)
    index, truth = Index(dense=1 << 18), {}
    for step in range(12):
        top = min(spread, 64 << step) if not moves else spread  # growing, as a BFS's
        keys = np.unique(rng.integers(0, top, size=int(rng.integers(1, 3000))))
        keys = keys[[int(k) not in truth for k in keys]]
        ids = rng.integers(0, 1 << 31, size=keys.size).astype(np.int32)
        index.insert(keys, ids)
        truth.update(zip(keys.tolist(), ids.tolist(), strict=True))
        probe = np.concatenate([keys, keys, rng.integers(-5, spread + 5, size=200)])
        want = [truth.get(k, -7) for k in probe.tolist()]
        assert index.find(probe, absent=-7).tolist() == want
    assert index.size == len(truth)
    assert (index.dense is None) == moves
    index.insert(np.array([-4, 1 << 40]), np.array([1, 2], dtype=np.int32))  # any int64 key
    assert index.dense is None and index.find(np.array([-4, 1 << 40, -5])).tolist() == [1, 2, -1]

@pytest.mark.parametrize("limit", [8, 1 << 22])
def test_memo_computes_each_key_once_dense_or_hashed(limit, monkeypatch):
    monkeypatch.setattr(arrays, "DENSE_LIMIT", limit)
    asked: list[int] = []

    def square(keys):
        asked.extend(keys.tolist())
        return keys * keys

    memo = Memo(square)
    rng = np.random.default_rng(3)
    for _ in range(10):
        keys = rng.integers(0, 5000, size=300)
        assert memo(keys).tolist() == [k * k for k in keys.tolist()]
    assert len(asked) == len(set(asked))  # never asked twice
    assert (memo.table is None) == (limit == 8)  # sparse keys moved to a hash index


def test_grow_and_concatenate():
    g = Grow(np.int64)
    for i in range(100):
        g.extend(np.arange(i))
    want = [k for i in range(100) for k in range(i)]
    assert g.view.tolist() == want
    parts = [np.arange(3), np.arange(0), np.arange(5)]
    assert concatenate(parts, np.int64).tolist() == [0, 1, 2, 0, 1, 2, 3, 4]
    assert parts == [None, None, None]  # each part freed once copied


def test_ranks_counts_within_each_group():
    assert ranks(np.array([2, 0, 3, 1])).tolist() == [0, 1, 0, 1, 2, 0]


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_merge_sums_in_stream_order_keeping_first_occurrence(seed):
    rng = np.random.default_rng(seed)
    n_choices = 30
    choice = np.sort(rng.integers(0, n_choices, size=400))
    cols = rng.integers(0, 12, size=choice.size).astype(np.int32)
    vals = rng.random(choice.size)
    got_cols, got_vals, lengths = merge(choice, cols, vals, n_choices)
    # by a loop: per choice, a dict in insertion order, summed left to right
    want_cols, want_vals, want_len = [], [], []
    for c in range(n_choices):
        row: dict[int, float] = {}
        for col, v in zip(cols[choice == c].tolist(), vals[choice == c].tolist(), strict=True):
            row[col] = row.get(col, 0.0) + v
        want_cols += list(row)
        want_vals += list(row.values())
        want_len.append(len(row))
    assert got_cols.tolist() == want_cols
    assert got_vals.tolist() == want_vals  # bit for bit: the same summation order
    assert lengths.tolist() == want_len
