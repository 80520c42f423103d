"""peak-1e6: the LP stage's choice that keeps a zero state at 0, made with less memory.

Checked against a plain loop over the states and their choices, written here from the
definition (the first choice with no target probability whose every stored successor is
a zero state; a state's first choice where none is), on random quotients with empty
choices, stored zero entries and states with no keeping choice."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.solvers.reduced import keeping_zero


def brute_keeping_zero(indptr, indices, zero, to_target, groups) -> list[int]:
    out = []
    for s in range(len(groups) - 1):
        pick = groups[s]
        for c in range(groups[s], groups[s + 1]):
            succ = indices[indptr[c]:indptr[c + 1]]
            if to_target[c] == 0.0 and all(zero[t] for t in succ):
                pick = c
                break
        out.append(pick)
    return out


@pytest.mark.parametrize("seed", range(8))
def test_keeping_zero_matches_a_loop(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 40))
    per_state = rng.integers(1, 5, size=n)
    groups = np.concatenate([[0], np.cumsum(per_state)])
    m = int(groups[-1])
    lens = rng.integers(0, 4, size=m)  # empty choices too
    indptr = np.concatenate([[0], np.cumsum(lens)]).astype(np.int32)
    indices = rng.integers(0, n, size=int(indptr[-1])).astype(np.int32)
    data = rng.random(indices.size)
    data[rng.random(indices.size) < 0.2] = 0.0  # stored zeros still count as moves
    matrix = sp.csr_array((data, indices, indptr), shape=(m, n))
    zero = rng.random(n) < 0.6
    to_target = np.where(rng.random(m) < 0.3, rng.random(m), 0.0)
    q = SimpleNamespace(matrix=matrix, zero=zero, to_target=to_target, row_groups=groups,
                        n_choices=m)
    got = keeping_zero(q)
    assert got.dtype == np.int64
    assert got.tolist() == brute_keeping_zero(indptr, indices, zero, to_target, groups)


def test_keeping_zero_without_entries() -> None:
    groups = np.array([0, 2, 3])
    matrix = sp.csr_array((np.zeros(0), np.zeros(0, np.int32), np.zeros(4, np.int32)),
                          shape=(3, 2))
    q = SimpleNamespace(matrix=matrix, zero=np.array([True, True]),
                        to_target=np.array([0.5, 0.0, 0.2]), row_groups=groups, n_choices=3)
    assert keeping_zero(q).tolist() == [1, 2]


@pytest.mark.parametrize("in_place_from", [0, 1 << 17])
@pytest.mark.parametrize("seed", range(6))
def test_gather_ranges_concatenates_the_ranges(seed: int, in_place_from: int,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    from mitld_lp.solvers import rows
    from mitld_lp.solvers.rows import gather_ranges

    monkeypatch.setattr(rows, "IN_PLACE_FROM", in_place_from)  # both ways of making it
    rng = np.random.default_rng(100 + seed)
    k = int(rng.integers(0, 30))
    starts = rng.integers(0, 1000, size=k)
    stops = starts + rng.integers(0, 6, size=k)  # empty ranges too, overlaps, any order
    expected = [i for a, b in zip(starts, stops, strict=True) for i in range(a, b)]
    got = gather_ranges(starts, stops)
    assert got.dtype == np.int64
    assert got.tolist() == expected


def test_gather_ranges_refuses_a_range_ending_before_its_start() -> None:
    from mitld_lp.solvers.rows import gather_ranges

    with pytest.raises(ValueError, match="gather_ranges"):
        gather_ranges(np.array([5, 2]), np.array([7, 1]))
    assert gather_ranges(np.array([], dtype=np.int64), np.array([], dtype=np.int64)).size == 0
