"""The analysis's traced memory on a generated product, against an estimate written here
from its sizes; and the pieces that cut it against values found another way.

The product is deadline-like, the shape of QVBS csma 4-2 at a smaller size: states
numbered so that every choice moves to 1-4 of the 50 states below it, so every
strongly connected component is one state; states 0-2 and a tenth of the others are
absorbing targets.  For a minimum with no sink every state reaches the target almost
surely (Prob1A), so the quotient is empty, as csma's is all but 1,111 choices: the
analysis's peak is its graph work on the product (the attractor of Prob0E, the
components, the reversed state graph and Prob1A's search on it).  It is analysed with
the NumPy walks (csma's, where numba is not loaded).

The estimate (:func:`_bound`): 8 bytes an edge (the state graph reversed, 4 bytes an
index, and one transpose's 4-byte indices at a time) and 48 bytes a state (the
components, a few masks and SciPy's int32 scratch of a search), plus 1 MB.  The base
(integ71) held 16.6 MB on the product below (37 bytes an edge), against 7.5 MB here
(17): the state graph kept alive for the levels, an int64 source array an edge for its
reversal, SciPy's float64 copy of it for the components, and the attractor's int64
scratch, at once.

For a maximum with a second target, where most rows stay (the sensed case's shape),
the quotient's matrix owns arrays of its own size (the base kept the kept rows' whole
copy under it, the entries into removed states cut by a view).
"""

from __future__ import annotations

import gc
import tracemalloc

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.mdp import MDP
from mitld_lp.solvers.analysis import analyse
from mitld_lp.solvers.graph import Sense, attractor, attractors
from mitld_lp.solvers.quotient_order import may_split, mixed
from mitld_lp.solvers.quotient_rows import quotient_rows, take_ranges


def deadline_product(n: int, seed: int, sinks: float = 0.05, stay: float = 0.2) -> MDP:
    """``n`` states; state ``s`` (not absorbing) has 1-3 choices, each to 1-4 states
    among the 50 below it, a fraction ``stay`` of them also staying put; states below
    3, a tenth of the others targets (absorbing), a fraction ``sinks`` sinks
    (absorbing)."""
    rng = np.random.default_rng(seed)
    kind = rng.random(n)
    target = kind < 0.1
    target[:3] = True
    sink = (kind >= 0.1) & (kind < 0.1 + sinks)
    sink[:3] = False
    absorbing = target | sink
    n_ch = np.where(absorbing, 1, rng.integers(1, 4, size=n))
    groups = np.concatenate([[0], np.cumsum(n_ch)]).astype(np.int64)
    owner = np.repeat(np.arange(n), n_ch)
    k = np.where(absorbing[owner], 1, rng.integers(1, 5, size=owner.size))
    ptr = np.concatenate([[0], np.cumsum(k)])
    row = np.repeat(np.arange(owner.size), k)
    src = owner[row]
    cols = np.maximum(src - rng.integers(1, 51, size=row.size), 0)
    cols[absorbing[src]] = src[absorbing[src]]
    stay = (rng.random(owner.size) < stay) & ~absorbing[owner]
    first = ptr[:-1]
    cols[first[stay]] = owner[stay]  # a fifth of the choices also stay put
    m = sp.csr_array((rng.random(row.size) + 0.1, cols.astype(np.int32),
                      ptr.astype(np.int32)), shape=(owner.size, n))
    m.sum_duplicates()
    m = sp.csr_array(m.multiply(1.0 / m.sum(axis=1)[:, None]))
    no = np.zeros(n, dtype=bool)
    return MDP(matrix=m, row_groups=groups, choice_actions=np.zeros(owner.size, dtype=np.int32),
               action_names=(), initial=n - 1, target=target, sink=sink, truncated=no,
               states=range(n))


def _traced_peak(mdp: MDP, goal: np.ndarray, extra: np.ndarray | None, sense: Sense,
                 ) -> tuple[int, tuple]:
    """The traced peak of one analysis above the size before it (bytes), and its
    quotients (kept alive, as the solvers keep them)."""
    analyse(mdp, goal, extra, sense=sense)  # SciPy's and NumPy's first-call allocations
    gc.collect()
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        got = analyse(mdp, goal, extra, sense=sense)
        peak = tracemalloc.get_traced_memory()[1] - before
    finally:
        tracemalloc.stop()
    return peak, got


def _bound(mdp: MDP) -> int:
    """The estimate of the module docs, from the product's sizes."""
    return 8 * mdp.matrix.nnz + 48 * mdp.n_states + (1 << 20)


@pytest.fixture
def numpy_walks(monkeypatch: pytest.MonkeyPatch) -> None:
    """The NumPy walks whatever numba's state (csma's analysis in the route)."""
    from mitld_lp.solvers import analysis_gates, walks

    monkeypatch.setattr(walks, "COMPILED_LOADED_MIN_ENTRIES", 1 << 40)
    # the attractor's and the quotient levels' own gates (a warm cache), off too
    monkeypatch.setattr(analysis_gates, "WARM_MIN_ENTRIES", 1 << 40)
    monkeypatch.setattr(analysis_gates, "PAID_MIN_ENTRIES", 1 << 40)
    monkeypatch.setattr(analysis_gates, "LEVELS_MIN_ENTRIES", 1 << 40)


@pytest.mark.usefixtures("numpy_walks")
def test_traced_peak_within_the_estimate() -> None:
    mdp = deadline_product(100_000, seed=45, sinks=0.0, stay=0.0)
    goal = np.asarray(mdp.target, dtype=bool)
    peak, (q, _) = _traced_peak(mdp, goal, None, Sense.MIN)
    # the graph alone decides: Prob1A everywhere (no sink, no choice that stays put)
    assert q.matrix.shape[0] == 0 and bool(np.all(q.qualitative.one))
    assert peak <= _bound(mdp), (peak, _bound(mdp))


@pytest.mark.usefixtures("numpy_walks")
def test_quotient_matrix_owns_its_arrays() -> None:
    """A maximum where most rows stay and some of their entries go: the matrix's arrays
    hold its entries only, and equal the kept rows read whole (SciPy's ``m[kept]``,
    the columns mapped by ``state_map``, the removed ones dropped)."""
    mdp = deadline_product(20_000, seed=46, stay=0.0)
    goal = np.asarray(mdp.target, dtype=bool)
    extra = np.asarray(mdp.sink, dtype=bool) & (np.arange(mdp.n_states) % 7 == 0)
    q, _ = analyse(mdp, goal, extra, sense=Sense.MAX)
    rows = sp.csr_array(sp.csr_array(mdp.matrix)[np.asarray(q.choice_origin)])
    cols = np.asarray(q.state_map)[rows.indices]
    keep = cols >= 0
    assert 0.5 * rows.nnz < q.matrix.nnz == int(keep.sum()) < rows.nnz
    assert np.array_equal(q.matrix.data, rows.data[keep])
    assert np.array_equal(q.matrix.indices, cols[keep])
    for a in (q.matrix.data, q.matrix.indices):
        assert a.base is None or a.base.nbytes == a.nbytes, (a.size, a.base.size)


def test_quotient_rows_against_the_whole_rows() -> None:
    """:func:`quotient_rows` against the rows copied whole by SciPy (``m[kept]``), the
    columns mapped and the removed ones dropped by a Python loop, and the one-step sums
    added in each row's stored order by Python floats (the same additions, so the same
    bits)."""
    rng = np.random.default_rng(3)
    n, choices = 400, 1100
    m = sp.random_array((choices, n), density=0.03, format="csr", rng=rng, dtype=np.float64)
    m.data += 0.01
    kept = np.sort(rng.choice(choices, 700, replace=False)).astype(np.int32)
    state_map = np.full(n, -1, dtype=np.int32)
    live = rng.random(n) < 0.6
    n_red = int(live.sum())
    state_map[live] = rng.permutation(n_red)
    goal = ~live & (rng.random(n) < 0.3)
    extra = ~live & ~goal & (rng.random(n) < 0.3)
    lose = ~live & ~goal & ~extra
    got = quotient_rows(m, kept, state_map, n_red, [[goal, extra], lose], np.int32,
                        positive=(1,))
    rows = sp.csr_array(m[kept])
    want_data, want_cols, want_ptr = [], [], [0]
    sums = np.zeros((kept.size, 2))
    for r in range(kept.size):
        lo, hi = rows.indptr[r], rows.indptr[r + 1]
        for c, v in zip(rows.indices[lo:hi], rows.data[lo:hi], strict=True):
            if state_map[c] >= 0:
                want_data.append(v)
                want_cols.append(state_map[c])
            sums[r, 0] += v * float(goal[c])
            sums[r, 1] += v * float(extra[c])
        want_ptr.append(len(want_data))
    leaks = np.array([any(lose[c] for c in rows.indices[rows.indptr[r]:rows.indptr[r + 1]])
                      for r in range(kept.size)])
    assert got.data.tobytes() == np.array(want_data).tobytes()
    assert np.array_equal(got.indices, want_cols) and got.indices.dtype == np.int32
    assert np.array_equal(got.indptr, want_ptr)
    assert got.sums[0].tobytes() == sums.tobytes()
    assert np.array_equal(got.sums[1], leaks)
    assert got.data.base is None or got.data.base.size == got.data.size  # no larger buffer


def test_take_ranges_against_slices() -> None:
    rng = np.random.default_rng(5)
    values = rng.integers(0, 1000, size=300_000).astype(np.int32)
    lo = np.sort(rng.integers(0, 299_000, size=5000))
    hi = lo + rng.integers(0, 60, size=5000)
    want = np.concatenate([values[a:b] for a, b in zip(lo, hi, strict=True)])
    got = take_ranges(values, lo, hi)
    assert got.dtype == values.dtype and np.array_equal(got, want)


def test_two_attractors_on_one_transpose() -> None:
    """:func:`attractors` against :func:`attractor` called apart, and both against a
    plain fixed point (a state joins when every choice has a successor inside)."""
    product = deadline_product(3_000, seed=47)
    m, g = sp.csr_array(product.matrix), np.asarray(product.row_groups)
    seeds = [np.asarray(product.target, dtype=bool), np.asarray(product.sink, dtype=bool)]
    both = attractors(m, g, seeds)
    for s, got in zip(seeds, both, strict=True):
        assert np.array_equal(got, attractor(m, g, s))
    inside = seeds[1].copy()  # the fixed point, by whole sweeps (acyclic: few needed)
    while True:
        hit = np.zeros(m.shape[0], dtype=bool)
        owner = np.repeat(np.arange(m.shape[0]), np.diff(m.indptr))
        hit[owner[inside[m.indices]]] = True
        every = np.logical_and.reduceat(hit, g[:-1]) & (np.diff(g) > 0)
        new = inside | every
        if np.array_equal(new, inside):
            break
        inside = new
    assert np.array_equal(both[1], inside)


def test_mixed_and_may_split_against_counts() -> None:
    """The components' tests against a count a component in Python."""
    rng = np.random.default_rng(9)
    for _ in range(50):
        comp = rng.integers(0, 30, size=80)
        maybe = rng.random(80) < rng.random()
        inside = {c: [bool(maybe[i]) for i in range(80) if comp[i] == c] for c in set(comp)}
        assert mixed(comp, maybe) == any(len(set(v)) == 2 for v in inside.values())
        assert may_split(comp, maybe) == any(len(v) > 1 and any(v) for v in inside.values())


@pytest.mark.usefixtures("numpy_walks")
def test_the_state_graph_not_kept() -> None:
    """The levels' closure of the components (``later``) holds no state graph (only the
    product's matrix, which the analysis holds anyway): it rebuilds it, and finds the
    levels of the components SciPy found (every edge between two goes down)."""
    from mitld_lp.solvers import graph

    product = deadline_product(20_000, seed=48)  # past SMALL: SciPy's components
    m, g = sp.csr_array(product.matrix), np.asarray(product.row_groups)
    seeds = np.asarray(product.target, dtype=bool)[:, None]
    found, _, back = graph.components_reaching(m, g, seeds)
    assert back is not None  # the reversed state graph's path
    cells = found.later.__closure__ or ()
    assert all(c.cell_contents is m for c in cells if sp.issparse(c.cell_contents))
    level = found.later()
    comp = found.component
    view = graph.graph_view(m, g)
    src = np.repeat(np.arange(view.shape[0]), np.diff(view.indptr))
    cross = comp[src] != comp[view.indices]
    assert np.all(level[comp[src[cross]]] > level[comp[view.indices[cross]]])
