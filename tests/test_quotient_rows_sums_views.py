"""sensed-83: the compiled quotient rows' sums are handed out as views of the kernel's
one sums array, not copied group by group (the copies and that array were held at once:
1.1-1.4 bytes a transition off the sensed solve's peak, docs/results.md).  The call's
traced peak is bounded by what it must hold (counted here from the sizes), and the sums
are the NumPy slices' to the bit."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.solvers import quotient_rows as qr
from mitld_lp.util import kernel_loader

pytest.importorskip("numba")


def _case(rows: int = 40_000, n: int = 5_000, seed: int = 3):
    rng = np.random.default_rng(seed)
    per = rng.integers(1, 5, size=rows)
    indptr = np.concatenate([[0], np.cumsum(per)]).astype(np.int32)
    indices = rng.integers(0, n, size=int(indptr[-1])).astype(np.int32)
    m = sp.csr_array((rng.random(indices.size), indices, indptr), shape=(rows, n))
    m.sum_duplicates()
    removed = rng.random(n) < 0.3
    state_map = np.full(n, -1, dtype=np.int32)
    n_red = int((~removed).sum())
    state_map[~removed] = np.arange(n_red, dtype=np.int32)
    masks = [removed & (rng.random(n) < 0.5) for _ in range(4)]
    return m, np.arange(rows), state_map, n_red, [masks[:2], masks[2:]]


def _call(compiled: bool, monkeypatch, m, kept, state_map, n_red, groups):
    with monkeypatch.context() as mp:
        mp.setattr(kernel_loader, "compiled_paid", lambda: compiled)
        mp.setattr(qr, "COMPILED_MIN_ENTRIES", 0)
        return qr.quotient_rows(m, kept, state_map, n_red, groups, np.int32, positive=(1,))


def test_compiled_sums_held_once(monkeypatch: pytest.MonkeyPatch) -> None:
    m, kept, state_map, n_red, groups = _case()
    _call(True, monkeypatch, m, kept, state_map, n_red, groups)  # the kernel's load
    tracemalloc.start()
    try:
        start = tracemalloc.get_traced_memory()[0]
        got = _call(True, monkeypatch, m, kept, state_map, n_red, groups)
        peak = tracemalloc.get_traced_memory()[1] - start
    finally:
        tracemalloc.stop()
    rows = kept.size
    # what the call must hold: the entries' arrays at the kept rows' size (cut after),
    # the row pointers, the kernel's sums (four float64 a row), the positive group's
    # bools, each state's column; a row's float64 (8 bytes) as slack for the rest.
    # Copying each group's sums as well adds 32 bytes a row (two float64 columns kept,
    # two more made before their comparison).
    need = m.nnz * 12 + (rows + 1) * 4 + rows * 4 * 8 + rows * 2 + state_map.size * 4
    assert peak <= need + rows * 8, (peak, need)
    plain = _call(False, monkeypatch, m, kept, state_map, n_red, groups)
    for a, b in zip(got.sums, plain.sums, strict=True):
        assert a.shape == b.shape and a.dtype == b.dtype
        assert a.tobytes() == b.tobytes()
    assert got.data.tobytes() == plain.data.tobytes()
    assert np.array_equal(got.indices, plain.indices)
    assert np.array_equal(got.indptr, plain.indptr)
