"""The hash index's growth a slice at a time (:class:`mitld_lp.util.arrays.Index`).

Independent routes: a Python dictionary for what every key finds, across rehashes and
the move from the dense array, with slices of a few keys (so that every slice's edge is
crossed); tracemalloc, in a child process, for what a rehash holds beside the new table:
the entries it moves (12 bytes each) and a slice's work arrays, not a copy of every entry,
their hashes and the probes of all of them at once.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mitld_lp.util.arrays import Index

ROOT = Path(__file__).resolve().parents[1]


def _check(index: Index, truth: dict[int, int], rng, spread: int) -> None:
    probe = np.concatenate([np.fromiter(truth, dtype=np.int64, count=len(truth)),
                            rng.integers(-spread, spread, size=300)])
    want = [truth.get(k, -7) for k in probe.tolist()]
    assert index.find(probe, absent=-7).tolist() == want
    assert index.size == len(truth)


@pytest.mark.parametrize("chunk", [1, 7, 64, 1 << 16])
@pytest.mark.parametrize("seed", [0, 1])
def test_slices_find_every_key_a_dictionary_holds(monkeypatch, chunk, seed):
    monkeypatch.setattr(Index, "_CHUNK", chunk)
    rng = np.random.default_rng(seed)
    index, truth = Index(), {}
    for _ in range(12):  # batches past 2^15 entries: rehashes from 2^16 slots up
        keys = np.unique(rng.integers(-(1 << 62), 1 << 62, size=int(rng.integers(1, 9000))))
        keys = keys[[int(k) not in truth for k in keys]]
        ids = rng.integers(0, 1 << 31, size=keys.size).astype(np.int32)
        if seed:  # in no order of key
            order = rng.permutation(keys.size)
            keys, ids = keys[order], ids[order]
        index.insert(keys, ids)
        truth.update(zip(keys.tolist(), ids.tolist(), strict=True))
        _check(index, truth, rng, 1 << 62)
    assert index.bits > 16  # it grew
    assert 2 * index.size <= (1 << index.bits)  # load at most 1/2


@pytest.mark.parametrize("chunk", [1, 5, 1 << 16])
def test_the_move_from_the_dense_array_keeps_every_id(monkeypatch, chunk):
    monkeypatch.setattr(Index, "_CHUNK", chunk)
    rng = np.random.default_rng(3)
    index, truth = Index(dense=1 << 18), {}
    keys = np.unique(rng.integers(0, 1 << 12, size=2000))  # dense: the plain array
    ids = rng.integers(0, 1 << 31, size=keys.size).astype(np.int32)
    index.insert(keys, ids)
    truth.update(zip(keys.tolist(), ids.tolist(), strict=True))
    assert index.dense is not None
    # keys past the bound: to the hash table, with everything the array held
    more = np.unique(rng.integers(1 << 20, 1 << 40, size=70_000))
    more_ids = rng.integers(0, 1 << 31, size=more.size).astype(np.int32)
    index.insert(more, more_ids)
    truth.update(zip(more.tolist(), more_ids.tolist(), strict=True))
    assert index.dense is None
    _check(index, truth, rng, 1 << 40)


def test_colliding_homes_probe_past_each_slice(monkeypatch):
    # keys that share their home slots, found by hashing many: runs of linear probes
    # across slices of 3 keys
    monkeypatch.setattr(Index, "_CHUNK", 3)
    index = Index()
    pool = np.unique(np.random.default_rng(5).integers(0, 1 << 62, size=400_000))
    homes = index._home(pool)
    slots, counts = np.unique(homes, return_counts=True)
    crowded = slots[np.argsort(counts)[-6:]]
    keys = pool[np.isin(homes, crowded)]
    assert keys.size >= 6 * 8  # each of the six homes shared by 8 keys or more
    ids = np.arange(keys.size, dtype=np.int32) * 3 + 1
    index.insert(keys, ids)
    assert index.find(keys).tolist() == ids.tolist()
    others = pool[~np.isin(homes, crowded)][:50]
    assert index.find(others).tolist() == [-1] * others.size


_CHILD = r"""
import json, sys, tracemalloc
import numpy as np
from mitld_lp.util.arrays import Index
rng = np.random.default_rng(1)
n = 600_000
keys = rng.choice(1 << 40, size=n, replace=False).astype(np.int64)
ids = np.arange(n, dtype=np.int64)
index = Index(1 << 22)
tracemalloc.start()
lo, b, worst = 0, 1000, 0
while lo < n:
    bits, before = index.bits, index.size
    tracemalloc.reset_peak()
    start = tracemalloc.get_traced_memory()[0]
    index.insert(keys[lo:lo + b], ids[lo:lo + b])
    peak = tracemalloc.get_traced_memory()[1] - start
    if index.bits != bits and index.dense is None:  # a rehash in this insert
        table = (1 << index.bits) * 12
        old = (1 << bits) * 12 if before else 0
        worst = max(worst, peak - (table - old) - 12 * before)
    lo += b
    b = int(b * 1.3)
assert (index.find(keys) == ids).all()
print(json.dumps({"over": worst, "table": (1 << index.bits) * 12}))
"""


def test_a_rehash_holds_the_entries_and_a_slice_beside_the_new_table(tmp_path):
    # The growth of a rehash over the old table is the new table's bytes less the old's;
    # beyond that, at most the entries it moves (12 bytes each, counted above) and a
    # slice's probes. Before, a copy of every entry, their hashes and the probes of all
    # of them: over 15 MB more at 600,000 keys.
    out = subprocess.run([sys.executable, "-c", _CHILD], cwd=ROOT, capture_output=True,
                         text=True, check=True, env={"PATH": "", "PYTHONPATH": str(ROOT),
                                                     "NUMBA_CACHE_DIR": str(tmp_path)})
    got = json.loads(out.stdout)
    assert got["table"] >= 12 << 20  # 2^20 slots: the rehashes measured were large
    assert got["over"] <= 4 << 20, got  # a 64K slice's work arrays, not the batch's
