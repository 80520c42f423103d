"""The policy jump's lean memory (:mod:`mitld_lp.solvers.policy_jump`): no long double
copy of a block held, products widened a batch at a time, the tie search by
state-sized arrays, one side's exit rewards at a time.

Independent routes: SciPy's whole-matrix product in long double (``astype``, which
sorts and merges each row as it widens) for :func:`~mitld_lp.solvers.policy_jump.
ld_product`'s bits; a plain loop over each state's choices for the tie search; each
policy's chain solved exactly in Fractions (Gaussian elimination written here) and the
optimum by brute force over every deterministic policy, and by SciPy's ``linprog`` on
the block's dual LP, for the jump's bracket; tracemalloc for what the jump holds.
"""

from __future__ import annotations

import itertools
import tracemalloc
from fractions import Fraction

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.optimize import linprog

from mitld_lp.solvers import policy_jump as pj
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.topological import Block, Factors


def _bits(a: np.ndarray) -> bytes:
    """The bits of an array's values (a long double's 80 bits on x86, without the
    padding bytes of its 16, which hold whatever was there)."""
    a = np.ascontiguousarray(a)
    if a.dtype == np.longdouble and np.finfo(np.longdouble).nmant == 63:
        return a.view(np.uint8).reshape(-1, a.dtype.itemsize)[:, :10].tobytes()
    return a.tobytes()


def _messy(seed: int, m: int = 57, n: int = 23) -> sp.csr_array:
    """A CSR matrix with rows in no column order and repeated columns (not canonical)."""
    rng = np.random.default_rng(seed)
    per = rng.integers(0, 6, size=m)
    indptr = np.concatenate([[0], np.cumsum(per)]).astype(np.int32)
    indices = rng.integers(0, n, size=int(indptr[-1])).astype(np.int32)
    data = rng.random(int(indptr[-1])) * rng.choice([1e-9, 1.0, 3e5], size=int(indptr[-1]))
    a = sp.csr_array((data, indices, indptr), shape=(m, n))
    assert not a.has_canonical_format
    return a


@pytest.mark.parametrize("batch", [1, 4, 11, 1 << 13])
@pytest.mark.parametrize("seed", range(4))
def test_ld_product_same_bits_as_the_widened_matrix(monkeypatch, seed, batch):
    a = _messy(seed)
    before = (a.data.copy(), a.indices.copy(), a.indptr.copy())
    rng = np.random.default_rng(100 + seed)
    x = (rng.random(a.shape[1]) * 1e3).astype(np.longdouble) / 7
    want = a.astype(np.longdouble) @ x
    monkeypatch.setattr(pj, "LD_BATCH", batch)
    got = pj.ld_product(a, x)
    assert got.dtype == np.longdouble and _bits(got) == _bits(want)
    rows = rng.choice(a.shape[0], size=19, replace=False)
    assert _bits(pj.ld_product(a, x, rows)) == _bits(want[rows])
    # float64 values are widened as SciPy widens them
    x64 = rng.random(a.shape[1])
    assert _bits(pj.ld_product(a, x64)) == _bits(a.astype(np.longdouble) @ x64)
    # the matrix is left as it came (its rows' order is what float64 sums read)
    for arr, old in zip((a.data, a.indices, a.indptr), before, strict=True):
        assert np.array_equal(arr, old)
    # and the sums are right: each row's exact sum (Fractions) within its rounding
    for i in range(a.shape[0]):
        lo, hi = a.indptr[i], a.indptr[i + 1]
        exact = sum((Fraction(float(a.data[k])) * Fraction(float(x64[a.indices[k]]))
                     for k in range(lo, hi)), Fraction(0))
        terms = sum(abs(float(a.data[k]) * float(x64[a.indices[k]])) for k in range(lo, hi))
        assert abs(Fraction(float(pj.ld_product(a, x64)[i])) - exact) <= \
            Fraction(1e-15) * Fraction(terms)


def test_ld_product_empty_rows():
    a = sp.csr_array((np.zeros(0), np.zeros(0, np.int32), np.zeros(4, np.int32)),
                     shape=(3, 5))
    assert np.array_equal(pj.ld_product(a, np.ones(5)), np.zeros(3))
    assert pj.ld_product(sp.csr_array((0, 5)), np.ones(5)).shape == (0,)


def _first_best_loop(scores: np.ndarray, width: int, sense: Sense) -> np.ndarray:
    """Each state's first choice of best score by a plain loop; a state whose best
    is NaN or infinite (its difference to itself NaN: no choice ties it) gets int64's
    maximum, as ``segmented_argmax``'s route does."""
    out = []
    for s in range(scores.size // width):
        row = [float(v) for v in scores[s * width:(s + 1) * width]]
        best = max(row) if sense is Sense.MAX else min(row)
        if any(np.isnan(v) for v in row) or np.isinf(best):
            out.append(np.iinfo(np.int64).max)
            continue
        out.append(s * width + row.index(best))
    return np.asarray(out, dtype=np.int64)


@pytest.mark.parametrize("dtype", [np.float64, np.longdouble])
@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize("width", [1, 2, 3, 4, 7])
def test_argbest_against_a_loop(width, sense, dtype):
    rng = np.random.default_rng(width)
    n = 300
    scores = rng.choice([0.0, -0.0, 1.0, 0.5, 0.25, -np.inf, np.nan], size=n * width,
                        p=[.2, .2, .15, .15, .15, .1, .05]).astype(dtype)
    scores[: 20 * width] = rng.random(20 * width)  # distinct values too
    scores.reshape(-1, width)[:, 0][np.all(np.isinf(scores.reshape(-1, width)),
                                           axis=1)] = 0.5  # no state all -inf
    groups = np.arange(0, n * width + 1, width)
    with np.errstate(invalid="ignore"):  # inf - inf, NaN: no tie, as in the loop
        got = pj._argbest(scores, groups, width, sense)
    np.testing.assert_array_equal(got, _first_best_loop(scores, width, sense))


def _block(seed: int, n: int, width: int | None, fan: int = 3) -> Block:
    """``n`` states, ``width`` choices each (or one to three: ``None``); a choice
    moves to one to ``fan`` states of the block and leaves with probability at least
    1/8; probabilities are multiples of 1/64 (exact floats)."""
    rng = np.random.default_rng(seed)
    rows, cols, vals, reward, starts = [], [], [], [], []
    m = 0
    for _s in range(n):
        starts.append(m)
        for _c in range(width or int(rng.integers(1, 4))):
            succ = rng.choice(n, size=int(rng.integers(1, min(n, fan) + 1)), replace=False)
            stay = int(rng.integers(8, 57))
            weights = rng.integers(1, 8, size=succ.size).astype(float)
            parts = np.floor(weights / weights.sum() * stay)
            parts[0] += stay - parts.sum()
            for t, p in zip(succ, parts, strict=True):
                if p > 0:
                    rows.append(m)
                    cols.append(int(t))
                    vals.append(p / 64.0)
            reward.append((64 - stay) / 64.0 * int(rng.integers(0, 5)) / 4.0)
            m += 1
    inner = sp.csr_array((vals, (rows, cols)), shape=(m, n))
    inner.sum_duplicates()
    return Block(np.arange(n), np.arange(m), inner, sp.csr_array((m, n)),
                 np.asarray(starts, np.int64), np.asarray(reward))


def _exact(block: Block, chosen) -> list[Fraction]:
    n = len(chosen)
    q = block.inner.toarray()
    a = [[Fraction(int(i == j)) - Fraction(float(q[c, j])) for j in range(n)]
         + [Fraction(float(block.to_target[c]))] for i, c in enumerate(chosen)]
    for col in range(n):
        piv = next(r for r in range(col, n) if a[r][col] != 0)
        a[col], a[piv] = a[piv], a[col]
        for r in range(n):
            if r != col and a[r][col] != 0:
                f = a[r][col] / a[col][col]
                a[r] = [x - f * y for x, y in zip(a[r], a[col], strict=True)]
    return [a[i][n] / a[i][i] for i in range(n)]


def _brute(block: Block, sense: Sense) -> list[Fraction]:
    g = block.groups
    best = None
    for pol in itertools.product(*[range(g[s], g[s + 1]) for s in range(block.states.size)]):
        v = _exact(block, pol)
        pick = max if sense is Sense.MAX else min
        best = v if best is None else [pick(x, y) for x, y in zip(best, v, strict=True)]
    return best


def _linprog(block: Block, sense: Sense) -> np.ndarray:
    """The block's optimum by its dual LP: a maximum is the least ``v`` with ``v(s) >=
    r(c) + Q(c) v`` over every choice, a minimum the greatest with ``<=``."""
    n = block.states.size
    owner = np.repeat(np.arange(n), np.diff(block.groups))
    a = block.inner.toarray()
    a[np.arange(owner.size), owner] -= 1.0  # Q v - v(s)
    r = block.to_target
    if sense is Sense.MAX:  # Q v - v <= -r, min sum v
        res = linprog(np.ones(n), A_ub=a, b_ub=-r, bounds=(0, None), method="highs")
    else:  # v - Q v <= r, max sum v
        res = linprog(-np.ones(n), A_ub=-a, b_ub=r, bounds=(0, None), method="highs")
    assert res.status == 0
    return res.x


CASES = [(seed, width) for seed in range(6) for width in (None, 2, 3)]


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize(("seed", "width"), CASES)
def test_jump_bracket_holds_the_optimum(seed, width, sense):
    """Both bounds proven, within the tolerance, and the exact optimum (brute force over
    the policies in Fractions) inside; SciPy's LP agrees with the brute force."""
    block = _block(seed, 5, width)
    best = _brute(block, sense)
    assert np.allclose(_linprog(block, sense), [float(b) for b in best], atol=1e-8)
    lo, hi = np.zeros(5), np.ones(5)
    tol = 1e-6
    assert pj.jump(block, lo, hi, tol, None, sense)
    for low, up, opt in zip(lo, hi, best, strict=True):
        assert Fraction(float(low)) <= opt <= Fraction(float(up))
        assert up - low <= tol


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize(("seed", "width"), CASES[:9])
def test_improve_ahead_reaches_the_optimum(seed, width, sense):
    """The policy iteration's fixpoint is optimal (its exact values are the brute
    force's optimum) and its values are its chain's exact values to float64."""
    block = _block(seed, 5, width)
    start = pj.start_policy(block, block.to_target, np.zeros(5), sense)
    chosen, v, t = pj.improve_ahead(block, block.to_target, start, factors=Factors(),
                                    sense=sense)
    exact = _exact(block, chosen)
    best = _brute(block, sense)
    for got, want, opt in zip(v, exact, best, strict=True):
        assert abs(Fraction(float(got)) - want) <= Fraction(1, 10**15)
        assert abs(want - opt) <= Fraction(1, 10**14)


def test_less_owner_is_the_repeated_subtraction():
    rng = np.random.default_rng(3)
    for width, counts in ((3, np.full(40, 3)), (0, rng.integers(1, 5, size=40))):
        scores = rng.random(int(counts.sum())).astype(np.longdouble)
        values = rng.random(40).astype(np.longdouble)
        for sense in (Sense.MAX, Sense.MIN):
            want = sense.gain(scores, np.repeat(values, counts))
            got = scores.copy()
            pj._less_owner(got, values, counts, width, sense)
            assert _bits(got) == _bits(want)


def _jump_peak(block: Block) -> int:
    n = block.states.size
    pj.jump(block, np.zeros(n), np.ones(n), 1e-6, None, Sense.MAX)  # imports, caches
    lo, hi = np.zeros(n), np.ones(n)
    tracemalloc.start()
    try:
        entry = tracemalloc.get_traced_memory()[0]
        assert pj.jump(block, lo, hi, 1e-6, None, Sense.MAX)
        return tracemalloc.get_traced_memory()[1] - entry
    finally:
        tracemalloc.stop()


def test_jump_holds_no_long_double_copy_of_the_block():
    """Two blocks of 2,000 states of four choices, one with about four times the
    other's entries: the jump's traced peak grows by less than 24 bytes an added
    entry.  A long double copy of the block's rows alone is 20 bytes an entry (16 for
    a value, 4 for its column), and the jump held one through all its rounds beside
    the float64 rows (36 bytes an added entry measured so); now only the policy's own
    rows (a quarter of the entries) and a batch of widened rows are copied (12)."""
    sparse, dense = _block(5, 2000, 4, fan=2), _block(5, 2000, 4, fan=12)
    assert sparse.choices.size == dense.choices.size
    added = dense.inner.nnz - sparse.inner.nnz
    assert added > 2 * sparse.inner.nnz
    growth = _jump_peak(dense) - _jump_peak(sparse)
    assert growth < 24 * added, (growth / added)


@pytest.mark.parametrize("refuse", [False, True])
@pytest.mark.parametrize("seed", range(5))
def test_greedy_blocks_with_narrow_choices_get_linprogs_values(seed, refuse, monkeypatch):
    """``solve_decomposed`` hands the greedy check its block with int32 choices and the
    LP (where the greedy policy settles nothing: ``refuse``) int64 ones again; either
    way the values are SciPy linprog's optimum of the MDP (tests/test_greedy_block's
    LP, written there independently) and the policy's own chain attains them."""
    from mitld_lp.solvers import lp_blocks
    from mitld_lp.solvers.iteration import interval_iteration
    from mitld_lp.solvers.lp import solve_lp
    from tests.test_greedy_block import linprog_max, tied_mdp

    monkeypatch.setattr(lp_blocks, "GREEDY_MIN_CHOICES", 0)
    seen: dict[str, list] = {"greedy": [], "lp": []}
    real_greedy, real_lp = lp_blocks.certified_greedy, lp_blocks.block_lp

    def greedy(block, *a, **k):
        seen["greedy"].append(block.choices.dtype)
        return None if refuse else real_greedy(block, *a, **k)

    def block_lp(block, *a, **k):
        seen["lp"].append(block.choices.dtype)
        return real_lp(block, *a, **k)

    monkeypatch.setattr(lp_blocks, "certified_greedy", greedy)
    monkeypatch.setattr(lp_blocks, "block_lp", block_lp)
    mdp = tied_mdp(seed)
    want = linprog_max(mdp)
    it = interval_iteration(mdp, mdp.target, gap="max", progress=False)
    got = solve_lp(mdp, mdp.target, everywhere=True, bounds=(it.lower, it.upper))
    assert got.values is not None and got.policy is not None
    np.testing.assert_allclose(got.values, want, atol=1e-8)
    assert seen["greedy"] and all(d == np.int32 for d in seen["greedy"])
    assert all(d == np.int64 for d in seen["lp"])
    if refuse:
        assert len(seen["lp"]) >= len(seen["greedy"])
    # the policy's own chain from the values: v = P_pi v off the target and sinks
    chosen = np.asarray(got.policy)
    chain = mdp.matrix[chosen].toarray()
    free = ~(mdp.target | mdp.sink)
    v = np.where(mdp.target, 1.0, 0.0)
    a = np.eye(mdp.n_states)[free][:, free] - chain[free][:, free]
    v[free] = np.linalg.solve(a, chain[free][:, mdp.target].sum(axis=1))
    np.testing.assert_allclose(v, want, atol=1e-8)


@pytest.mark.parametrize("seed", range(4))
def test_component_order_factorisation_solves_the_chain(seed, monkeypatch):
    """chain_factor in strong-component order (its labels' stable order) on a chain of
    many small cycles: its solve of ``(I - Q) x = b`` against NumPy's dense solve."""
    rng = np.random.default_rng(seed)
    k = 600
    rows, cols, vals = [], [], []
    for i in range(k):
        if i % 3:  # cycles of three, each state also moving down the line
            rows.append(i)
            cols.append(i - 1)
            vals.append(0.25)
        else:
            rows.append(i)
            cols.append(i + 2 if i + 2 < k else i)
            vals.append(0.25)
        if i >= 3:
            rows.append(i)
            cols.append(int(rng.integers(0, i - i % 3)))
            vals.append(0.5)
    chain = sp.csr_array((vals, (rows, cols)), shape=(k, k))
    monkeypatch.setattr(pj, "DENSE_LU_STATES", 0)
    monkeypatch.setattr(pj.topo_chain, "COMPILED", False)  # SciPy's route (topo_chain's own tests)
    lu = pj.chain_factor(chain)
    assert isinstance(lu, pj.TopoLU)
    b = rng.random((k, 2))
    want = np.linalg.solve(np.eye(k) - chain.toarray(), b)
    np.testing.assert_allclose(lu.solve(b), want, rtol=1e-12, atol=1e-12)
