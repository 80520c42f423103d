"""``kernels.take_rows`` / ``kernels.put_rows``: the rows of a 2-D array gathered and
written by ``take`` and by a 1-D view whose items are rows, checked against a loop
over the rows written in the test (each row read or written by itself), to the bit,
for the index types and shapes the interval iteration hands them (int32 and int64,
unsorted, repeated, empty, one column and several, a non-contiguous array and a
boolean mask through NumPy's own indexing)."""

from __future__ import annotations

import numpy as np
import pytest

from mitld_lp.solvers.kernels import put_rows, take_rows


def _looped_take(a: np.ndarray, index) -> np.ndarray:
    out = np.empty((len(index), *a.shape[1:]), dtype=a.dtype)
    for i, r in enumerate(index):
        out[i] = a[int(r)]
    return out


def _looped_put(a: np.ndarray, index, rows: np.ndarray) -> None:
    for i, r in enumerate(index):
        a[int(r)] = rows[i]


def _bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a).view(np.uint8)


@pytest.mark.parametrize("dtype", [np.int32, np.int64])
@pytest.mark.parametrize("columns", [1, 2, 4])
def test_take_rows_is_the_rows_in_the_index_order(dtype, columns) -> None:
    rng = np.random.default_rng(columns)
    a = rng.standard_normal((50, columns))
    a[3, 0] = -0.0  # a sign bit kept
    a[7, -1] = np.nan
    for index in (rng.permutation(50), rng.integers(0, 50, 80), np.arange(0),
                  np.array([49, 0, 49])):
        index = index.astype(dtype)
        got = take_rows(a, index)
        want = _looped_take(a, index)
        assert got.shape == want.shape and got.dtype == a.dtype
        assert got.flags.c_contiguous
        assert np.array_equal(_bits(got), _bits(want))


@pytest.mark.parametrize("dtype", [np.int32, np.int64])
@pytest.mark.parametrize("columns", [1, 2, 6])
def test_put_rows_writes_each_row_where_its_index_says(dtype, columns) -> None:
    rng = np.random.default_rng(10 + columns)
    base = rng.standard_normal((40, columns))
    for index in (rng.permutation(40)[:25], np.arange(0), np.array([5, 9, 5])):
        index = index.astype(dtype)
        rows = rng.standard_normal((index.size, columns))
        rows[:1, :1] = -0.0
        got, want = base.copy(), base.copy()
        put_rows(got, index, rows)
        _looped_put(want, index, rows)  # a repeated index: the last row written wins
        assert np.array_equal(_bits(got), _bits(want))


def test_other_layouts_and_masks_go_through_numpys_indexing() -> None:
    rng = np.random.default_rng(3)
    wide = rng.standard_normal((30, 6))
    view = wide[:, ::2]  # not C-contiguous
    index = np.array([4, 1, 29], dtype=np.int64)
    assert np.array_equal(take_rows(view, index), _looped_take(view, index))
    rows = rng.standard_normal((3, 3))
    want = wide.copy()
    _looped_put(want[:, ::2], index, rows)
    put_rows(view, index, rows)
    assert np.array_equal(wide, want)
    mask = np.zeros(30, dtype=bool)
    mask[[2, 7]] = True
    assert np.array_equal(take_rows(wide, mask), _looped_take(wide, [2, 7]))
    other = wide.copy()
    put_rows(other, mask, np.zeros((2, 6)))
    assert not other[[2, 7]].any() and np.array_equal(other[~mask], wide[~mask])
    narrow = np.zeros((5, 2), dtype=np.float32)  # another dtype: NumPy casts it
    put_rows(narrow, np.array([1]), np.ones((1, 2)))
    assert narrow[1].tolist() == [1.0, 1.0] and narrow.sum() == 2.0
