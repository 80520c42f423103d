"""fixed-82: the quotient's rows read by the compiled kernel
(:mod:`mitld_lp.solvers.quotient_kernels`) where a kernel's load is paid, against the
NumPy slices and against a plain Python reading of the rows written here: the same
entries, columns and row pointers, and every sum the same to the bit (the rows'
entries into each set's states added in stored order from 0.0, as a loop over Python
floats adds them), with entries into removed states dropped or kept as zeros, groups of
one mask or of several, and sums kept as whether they are above 0."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.solvers import quotient_rows as qr
from mitld_lp.util import kernel_loader

pytest.importorskip("numba")


def _case(seed: int, n: int = 300):
    rng = np.random.default_rng(seed)
    rows = 2 * n
    nnz_row = rng.integers(0, 6, size=rows)
    indptr = np.concatenate([[0], np.cumsum(nnz_row)]).astype(np.int32)
    indices = np.concatenate([np.sort(rng.choice(n, k, replace=False)) for k in nnz_row]
                             ).astype(np.int32)
    data = rng.random(indices.size) * 10.0 ** rng.integers(-12, 1, size=indices.size)
    m = sp.csr_array((data, indices, indptr), shape=(rows, n))
    removed = rng.random(n) < 0.4
    state_map = np.full(n, -1, dtype=np.int32)
    n_red = int((~removed).sum())
    state_map[~removed] = np.arange(n_red)
    # up to five masks, each among the removed states (may overlap)
    masks = [removed & (rng.random(n) < 0.5) for _ in range(5)]
    kept = np.sort(rng.choice(rows, rows // 2, replace=False))
    return m, kept, state_map, n_red, masks


def _plain(m, kept, state_map, n_red, groups, drop, positive):
    """Each kept row read entry by entry in Python: its entries into kept states (or,
    not dropping, a zero in column 0 for the others) and per mask the sum of the values
    into its states, added in stored order from 0.0."""
    flat = [g for group in groups for g in (group if isinstance(group, list) else [group])]
    data, cols, ptr = [], [], [0]
    sums = np.zeros((kept.size, len(flat)))
    for r, row in enumerate(kept):
        acc = [0.0] * len(flat)
        for e in range(m.indptr[row], m.indptr[row + 1]):
            c, d = int(m.indices[e]), float(m.data[e])
            if state_map[c] >= 0:
                data.append(d)
                cols.append(int(state_map[c]))
                continue
            for j, mask in enumerate(flat):
                if mask[c]:
                    acc[j] = acc[j] + d
            if not drop:
                data.append(0.0)
                cols.append(0)
        sums[r] = acc
        ptr.append(len(data))
    out, j = [], 0
    for g, group in enumerate(groups):
        k = len(group) if isinstance(group, list) else 0
        s = sums[:, j:j + k] if k else sums[:, j]
        out.append(s > 0 if g in positive else s)
        j += max(k, 1)
    return np.array(data), np.array(cols), np.array(ptr), out


def _run(compiled: bool, monkeypatch, *args, **kwargs):
    with monkeypatch.context() as mp:
        mp.setattr(kernel_loader, "compiled_paid", lambda: compiled)
        mp.setattr(qr, "COMPILED_MIN_ENTRIES", 0)
        mp.setattr(qr, "SLICE", 97)  # the NumPy path over many slices
        return qr.quotient_rows(*args, **kwargs)


@pytest.mark.parametrize("drop", [True, False])
@pytest.mark.parametrize("shape", ["lists", "masks", "mixed"])
@pytest.mark.parametrize("seed", range(5))
def test_compiled_rows_are_the_numpy_rows_and_the_plain_reading(
        seed: int, shape: str, drop: bool, monkeypatch: pytest.MonkeyPatch) -> None:
    m, kept, state_map, n_red, masks = _case(seed)
    groups = {"lists": [masks[:2], masks[2:3], masks[3:5]],
              "masks": [masks[0], masks[1]],
              "mixed": [masks[:2], masks[2], masks[3:5]]}[shape]
    positive = (len(groups) - 1,)
    calls = []
    from mitld_lp.solvers import quotient_kernels
    inner = quotient_kernels.quotient_entries
    monkeypatch.setattr(quotient_kernels, "quotient_entries",
                        lambda *a: calls.append(1) or inner(*a))
    got = {c: _run(c, monkeypatch, m, kept, state_map, n_red, groups, np.int32, drop=drop,
                   positive=positive) for c in (True, False)}
    assert calls == [1]  # the compiled run called the kernel, the NumPy one did not
    data, cols, ptr, sums = _plain(m, kept, state_map, n_red, groups, drop, positive)
    for c, q in got.items():
        assert q.data.tobytes() == data.tobytes(), c
        assert np.array_equal(q.indices, cols) and q.indices.dtype == np.int32, c
        assert np.array_equal(q.indptr, ptr), c
        assert len(q.sums) == len(sums)
        for a, b in zip(q.sums, sums, strict=True):
            assert a.shape == b.shape and a.dtype == b.dtype, c
            assert a.tobytes() == b.tobytes(), c


def test_below_the_threshold_or_unpaid_the_numpy_slices_run(
        monkeypatch: pytest.MonkeyPatch) -> None:
    m, kept, state_map, n_red, masks = _case(7)
    from mitld_lp.solvers import quotient_kernels
    calls = []
    monkeypatch.setattr(quotient_kernels, "quotient_entries", lambda *a: calls.append(1))
    monkeypatch.setattr(kernel_loader, "compiled_paid", lambda: True)
    monkeypatch.setattr(qr, "COMPILED_MIN_ENTRIES", 10**9)
    qr.quotient_rows(m, kept, state_map, n_red, [masks[:2]], np.int32)
    monkeypatch.setattr(qr, "COMPILED_MIN_ENTRIES", 0)
    monkeypatch.setattr(kernel_loader, "compiled_paid", lambda: False)
    qr.quotient_rows(m, kept, state_map, n_red, [masks[:2]], np.int32)
    assert not calls
