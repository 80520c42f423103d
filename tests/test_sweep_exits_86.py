"""The one-model sweeps' fast route (``sweep_two`` with ``listed``: the order not read,
it is the reversed range, and only the exit rows listed once a block read, every other
choice's sums started at 0.0; without ``loops``: no entry compared with its state, no
``leave`` read) against routes written apart:

* each sweep (plain, watched, verifying; compiled and ``py_func``) against one
  Gauss--Seidel sweep in Python floats (``tests/test_sweep_two_86.py``'s), to the bit,
  on random blocks with self-loops, choices that never leave and exits of ``-0.0``
  (listed: not +0.0 in every bit) and on the same blocks with their diagonal removed
  (``loops`` off and on);
* ``Prepared.exit_rows`` against the rows found by float tests (``!= 0`` or a sign bit);
  ``Prepared.reverse`` for the default order, a permuted one and a copy of the range;
* the whole kernel through ``kernels.compiled_sweeps`` a sweep a call, guesses made,
  verified and proven: the fast route and the general one (``reverse`` and ``loops``
  turned off by hand) leave the same bounds, guesses and track after every call."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.solvers import kernels
from mitld_lp.solvers.graph import Sense
from tests.test_sweep_two_86 import check_each_sweep, random_block

pytestmark = pytest.mark.skipif(kernels.compiled_kernel() is None,
                                reason="numba is not installed")

FLOOR = kernels.FLOOR


def _no_diagonal(inner: sp.csr_array, groups: np.ndarray) -> sp.csr_array:
    """``inner`` without the entries on its state's diagonal (a choice's self-loop)."""
    coo = inner.tocoo()
    owner = np.repeat(np.arange(groups.size - 1), np.diff(groups))[coo.row]
    keep = coo.col != owner
    return sp.csr_array((coo.data[keep], (coo.row[keep], coo.col[keep])), shape=inner.shape)


def _listed(exits: np.ndarray) -> np.ndarray:
    """The choices whose exit row is not +0.0: a value other than zero or a sign bit."""
    odd = (exits != 0.0) | np.signbit(exits)
    return np.array([c for c in range(exits.shape[0]) if odd[c].any()], dtype=np.int64)


def _case(seed: int, diagonal: bool):
    inner, groups, exits = random_block(seed)
    if not diagonal:
        inner = _no_diagonal(inner, groups)
    exits = np.ascontiguousarray(exits)
    exits[5::9, 1] = 0.25 * exits[5::9, 0]  # some rows whose columns differ
    return inner, groups, exits


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("minimise", [False, True])
@pytest.mark.parametrize("diagonal", [True, False])
@pytest.mark.parametrize("python", [False, True])
def test_the_fast_route_equals_a_python_sweep_to_the_bit(seed, minimise, diagonal, python):
    inner, groups, exits = _case(seed, diagonal)
    n = groups.size - 1
    prep = kernels.Prepared(inner, groups)
    assert prep.reverse and prep.loops == diagonal
    rows = prep.exit_rows(exits)
    assert 0 < rows.size < exits.shape[0]  # listed and not: both kinds swept
    indptr, indices = prep.index
    args = (indptr, indices, inner.data, prep.groups, prep.leave, exits)
    pick = (lambda f: f.py_func) if python else (lambda f: f)
    tol, precision = 1e-3, (1e-3 if seed % 2 else -1.0)
    order = np.full(n, -1, dtype=np.int64)  # not read on the fast route
    for loops in ((True, False) if not diagonal else (True,)):
        check_each_sweep(pick, (inner, groups, exits), args, order, (rows, True, loops),
                         seed, minimise, tol, precision)


@pytest.mark.parametrize("seed", range(4))
def test_exit_rows_and_reverse(seed):
    inner, groups, exits = _case(seed, True)
    n = groups.size - 1
    prep = kernels.Prepared(inner, groups)
    rows = prep.exit_rows(exits)
    np.testing.assert_array_equal(rows, _listed(exits))
    assert np.any(np.signbit(exits[rows]) & (exits[rows] == 0.0))  # -0.0 rows listed
    assert prep.exit_rows(exits) is rows  # once a block: the same exits, the same list
    other = exits.copy()
    other[rows[0]] = 0.0
    np.testing.assert_array_equal(prep.exit_rows(other), _listed(other))
    assert prep.reverse
    prep.order = np.random.default_rng(seed).permutation(n).astype(np.int64)
    assert not prep.reverse
    prep.order = np.arange(n - 1, -1, -1, dtype=np.int64)  # a copy of the range
    assert prep.reverse
    prep.order = np.arange(n - 1, -1, -1, dtype=np.int64)[: n - 1]  # a state left out
    assert not prep.reverse


def _slow_block(seed: int, n: int, diagonal: bool):
    """A block closing slowly (a fifth of the choices reach the target with up to 1e-3,
    every other exit +0.0 or -0.0; each fails with up to 1e-2), so guesses are made,
    tried and proven; with ``diagonal`` a fifth of the choices have a self-loop."""
    rng = np.random.default_rng(seed)
    owner = np.repeat(np.arange(n), rng.integers(1, 3, n))
    m = owner.size
    goal = np.where(rng.random(m) < 0.2, 1e-3 * rng.random(m), 0.0)
    goal[(goal == 0.0) & (rng.random(m) < 0.3)] = -0.0
    second = rng.integers(n, size=m)
    if diagonal:
        second = np.where(rng.random(m) < 0.2, owner, second)
    else:
        second = np.where(second == owner, (owner + 2) % n, second)
    cols = np.column_stack([(owner + 1) % n, second])
    w = rng.random((m, 2))
    w *= ((1.0 - np.abs(goal) - 1e-2 * rng.random(m)) / w.sum(axis=1))[:, None]
    inner = sp.csr_array((w.ravel(), (np.repeat(np.arange(m), 2), cols.ravel())),
                         shape=(m, n))
    inner.sum_duplicates()
    groups = np.searchsorted(owner, np.arange(n + 1)).astype(np.int64)
    return inner, groups, np.column_stack([goal, goal])


@pytest.mark.parametrize("minimise", [False, True])
@pytest.mark.parametrize("diagonal", [True, False])
def test_the_whole_kernel_same_bits_by_both_routes(minimise, diagonal):
    sense = Sense.MIN if minimise else Sense.MAX
    proven = 0.0
    for seed in range(3):
        inner, groups, exits = _slow_block(seed, 80, diagonal)
        n = groups.size - 1
        preps = [kernels.Prepared(inner, groups) for _ in range(2)]
        assert preps[0].reverse and preps[0].loops == diagonal
        preps[1].reverse = False  # the general route: the order and every exit read
        preps[1].loops = True
        locals_ = [np.column_stack([np.zeros(n), np.ones(n)]) for _ in range(2)]
        for _call in range(150):
            got = [kernels.compiled_sweeps(p, exits, x, 1e-300, 1, sense, 1e-9)
                   for p, x in zip(preps, locals_, strict=True)]
            assert got[0] == got[1]
            np.testing.assert_array_equal(locals_[0], locals_[1])
            np.testing.assert_array_equal(preps[0].guess, preps[1].guess)
            np.testing.assert_array_equal(preps[0].track, preps[1].track)
        proven += preps[0].track[3]
    assert proven > 0  # guesses were proven: the verifying sweeps ran both routes
