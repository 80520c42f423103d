"""The LP stage's arrays made smaller at its peak (the greedy check of
``mitld_lp.solvers.greedy_block`` and the bounds of ``mitld_lp.solvers.lp``):

* a batch's long double scores (``greedy_block._scores``: only the values its rows read
  widened) against each row summed in a Python loop in long double, in stored order
  from 0, and against the whole matrix and value vector widened first (the sum it
  replaces), to the bit;
* each choice's state from the states' first choices without the total after them;
* the reduced bounds gathered where a block indexes them (``lp.OnReduced``) against a
  bound per reduced state written out member by member;
* a block the greedy policy does not settle (its exit rewards summed into the block's
  target column first) gets scipy linprog's values through the LP and its crossover,
  which read the block's target column again.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.solvers import greedy_block, lp_blocks
from mitld_lp.solvers.greedy_block import _owners, _rows, _scores
from mitld_lp.solvers.iteration import interval_iteration
from mitld_lp.solvers.lp import _reduced_bounds, solve_lp
from mitld_lp.solvers.quotient import reduce
from tests.test_greedy_block import linprog_max, tied_mdp


def _random_rows(rng: np.random.Generator, m: int, n: int, *,
                 shuffled: bool) -> sp.csr_array:
    """``m`` rows over ``n`` columns, some empty, no column twice in a row, its columns
    sorted or (``shuffled``) in no particular order."""
    counts = np.minimum(rng.integers(0, 5, size=m), n)
    counts[rng.random(m) < 0.2] = 0
    indptr = np.concatenate([[0], np.cumsum(counts)])
    cols = [np.sort(rng.choice(n, size=k, replace=False)) for k in counts.tolist()]
    if shuffled:
        cols = [rng.permutation(c) for c in cols]
    indices = np.concatenate(cols + [np.zeros(0, dtype=np.int64)]).astype(np.int32)
    return sp.csr_array((rng.uniform(0.0, 1.0, indices.size) ** 3, indices, indptr),
                        shape=(m, n))


@pytest.mark.parametrize("shuffled", [False, True])
@pytest.mark.parametrize("seed", range(8))
def test_scores_are_each_rows_long_double_sum(seed: int, shuffled: bool) -> None:
    """Each row summed in a loop in long double from 0, over its entries in column order
    (a row's stored order when sorted; SciPy's ``astype`` sorts a row that is not)."""
    rng = np.random.default_rng(seed)
    m, n = int(rng.integers(1, 60)), int(rng.integers(1, 30))
    rows = _random_rows(rng, m, n, shuffled=shuffled)
    values = rng.uniform(-1.0, 1.0, n) * 10.0 ** rng.integers(-20, 1, n)
    want = []
    for i in range(m):
        at = slice(int(rows.indptr[i]), int(rows.indptr[i + 1]))
        total = np.longdouble(0.0)
        pairs = zip(rows.indices[at].tolist(), rows.data[at].tolist(), strict=True)
        for col, val in sorted(pairs):
            total += np.longdouble(val) * np.longdouble(values[col])
        want.append(total)
    whole = rows.copy().astype(np.longdouble) @ values.astype(np.longdouble)
    for a in range(0, m, 7):  # batches of the rows, as the check takes them
        z = min(a + 7, m)
        got = _scores(_rows(rows, a, z), values, np.int32)
        assert got.dtype == np.longdouble
        for i in range(a, z):
            assert got[i - a] == want[i], (i, got[i - a], want[i])
        np.testing.assert_array_equal(got, whole[a:z])


def test_scores_of_rows_without_entries() -> None:
    rows = sp.csr_array((np.zeros(0), np.zeros(0, dtype=np.int32),
                         np.zeros(4, dtype=np.int32)), shape=(3, 5))
    got = _scores(rows, np.ones(5), np.int32)
    assert got.dtype == np.longdouble and got.tolist() == [0.0, 0.0, 0.0]


@pytest.mark.parametrize("seed", range(10))
def test_owners_from_the_first_choices_alone(seed: int) -> None:
    rng = np.random.default_rng(seed)
    counts = rng.integers(1, 6, size=int(rng.integers(1, 30)))
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
    m = int(counts.sum())
    want = [s for s, k in enumerate(counts.tolist()) for _ in range(k)]
    for a in range(m):
        for z in {a + 1, min(m, a + 4), m}:
            assert _owners(starts, a, z, np.int64).tolist() == want[a:z]


@pytest.mark.parametrize("seed", range(4))
def test_bounds_read_on_the_reduced_states(seed: int) -> None:
    mdp = tied_mdp(seed)
    q = reduce(mdp, mdp.target)
    it = interval_iteration(mdp, mdp.target, gap="max", progress=False)
    lo, hi = _reduced_bounds(q, (it.lower, it.upper))
    # a reduced state's bounds: those of its members, which agree (a collapsed end
    # component's members share their value and their bounds)
    want_lo, want_hi = np.full(q.n_states, np.nan), np.full(q.n_states, np.nan)
    for s, r in enumerate(q.state_map.tolist()):
        if r >= 0:
            assert np.isnan(want_lo[r]) or (want_lo[r], want_hi[r]) == (it.lower[s],
                                                                         it.upper[s])
            want_lo[r], want_hi[r] = it.lower[s], it.upper[s]
    every = np.arange(q.n_states)
    np.testing.assert_array_equal(lo[every], want_lo)
    np.testing.assert_array_equal(hi[every], want_hi)
    some = every[::3][::-1]
    np.testing.assert_array_equal(lo[some], want_lo[some])
    assert lo[some].dtype == np.float64
    with pytest.raises(ValueError, match="bounds: expected two arrays"):
        _reduced_bounds(q, (it.lower[:-1], it.upper))


@pytest.mark.parametrize("seed", range(4))
def test_block_left_to_the_lp_after_the_greedy_gets_linprogs_values(
        seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """The greedy check runs (summing the exit rewards into the block's target column)
    and is then refused; the LP, its pruning and its crossover solve the block and
    must read the target's column, not the rewards."""
    monkeypatch.setattr(lp_blocks, "GREEDY_MIN_CHOICES", 0)
    calls = []

    def refused(*args, **kwargs):
        calls.append(greedy_block.certified_greedy(*args, **kwargs))
        return None

    mdp = tied_mdp(seed)
    q = reduce(mdp, mdp.target)
    polish = lp_blocks.polish
    polished = []

    def checked(block, *args, **kwargs):
        # the block the crossover reads: its target column the quotient's there
        np.testing.assert_array_equal(block.to_target, q.to_target[block.choices])
        polished.append(block.states.size)
        return polish(block, *args, **kwargs)

    monkeypatch.setattr(lp_blocks, "certified_greedy", refused)
    monkeypatch.setattr(lp_blocks, "polish", checked)
    want = linprog_max(mdp)
    it = interval_iteration(mdp, mdp.target, gap="max", progress=False)
    got = solve_lp(mdp, mdp.target, everywhere=True, bounds=(it.lower, it.upper))
    assert calls, "no block went through the greedy check"
    assert len(polished) == len(calls)
    assert got.status.value == "optimal" and got.values is not None
    assert "by the bounds' greedy policy" not in got.message
    np.testing.assert_allclose(got.values, want, atol=1e-8)
