"""The fused pass's crowded states and bool reach columns
(:func:`~mitld_lp.solvers.analysis_kernels.components_reach`,
:func:`~mitld_lp.solvers.analysis_reach.fused_components_reaching`), checked against
routes written here: the components from SciPy's ``connected_components`` on a state
graph built in the test from sets of successors, their sizes counted with a ``Counter``,
and reach by a fixpoint of the successors' sets.  The kernel is run as Python
(its ``py_func``): no compiled cache is read or written."""

from __future__ import annotations

from collections import Counter
from types import SimpleNamespace

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from mitld_lp.solvers import analysis_gates, analysis_kernels, analysis_reach
from mitld_lp.solvers.graph import components_reaching
from mitld_lp.solvers.quotient_order import crowded

KERNEL = analysis_kernels.components_reach.py_func


def _matrix(rng: np.random.Generator, n: int, spread: int) -> tuple[sp.csr_array, np.ndarray]:
    """A choice matrix over ``n`` states (1-2 choices a state, 1-3 entries a choice, each
    to a state ``-spread .. 2 spread`` away: small cycles and chains), int32 indices."""
    per_state = rng.integers(1, 3, n)
    groups = np.concatenate([[0], np.cumsum(per_state)]).astype(np.int64)
    rows, cols = [], []
    for r in range(int(groups[-1])):
        s = int(np.searchsorted(groups, r, side="right") - 1)
        for t in {(s + int(d)) % n for d in rng.integers(-spread, 2 * spread + 1,
                                                         int(rng.integers(1, 4)))}:
            rows.append(r)
            cols.append(t)
    m = sp.csr_array((np.ones(len(rows)), (rows, cols)), shape=(int(groups[-1]), n))
    m.indices = m.indices.astype(np.int32)
    m.indptr = m.indptr.astype(np.int32)
    return m, groups


def _forward(m: sp.csr_array, groups: np.ndarray) -> sp.csr_array:
    """``m`` without its entries into a state below the choice's own: no cycle but
    self-loops (a row left empty keeps its self-loop)."""
    owner = np.repeat(np.arange(groups.size - 1), np.diff(groups))
    rows, cols = [], []
    for r in range(m.shape[0]):
        ts = [int(t) for t in m.indices[m.indptr[r]:m.indptr[r + 1]] if t >= owner[r]]
        for t in ts or [int(owner[r])]:
            rows.append(r)
            cols.append(t)
    out = sp.csr_array((np.ones(len(rows)), (rows, cols)), shape=m.shape)
    out.indices = out.indices.astype(np.int32)
    out.indptr = out.indptr.astype(np.int32)
    return out


def _succ(m: sp.csr_array, groups: np.ndarray) -> list[set[int]]:
    return [{int(t) for r in range(groups[s], groups[s + 1])
             for t in m.indices[m.indptr[r]:m.indptr[r + 1]]} for s in range(groups.size - 1)]


def _scipy_labels(succ: list[set[int]]) -> np.ndarray:
    n = len(succ)
    rows = [s for s, ts in enumerate(succ) for _ in ts]
    cols = [t for ts in succ for t in ts]
    graph = sp.csr_array((np.ones(len(rows)), (rows, cols)), shape=(n, n))
    return connected_components(graph, directed=True, connection="strong")[1]


def _reaching_fixpoint(succ: list[set[int]], seeds: np.ndarray) -> np.ndarray:
    """The states with a path to a seed (seeds included): a fixpoint of "some successor
    reaches", swept forward until nothing changes (not a search of the reversed graph)."""
    found = seeds.copy()
    changed = True
    while changed:
        changed = False
        for s, ts in enumerate(succ):
            if not found[s] and any(found[t] for t in ts):
                found[s] = changed = True
    return found


@pytest.mark.parametrize("seed", range(8))
def test_kernel_crowd_is_the_states_of_components_of_two_or_more(seed: int) -> None:
    rng = np.random.default_rng(84200 + seed)
    m, groups = _matrix(rng, int(rng.integers(1, 400)), int(rng.integers(1, 6)))
    seeds = rng.random((groups.size - 1, 2)) < 0.05
    _, label, reach, crowd, _, _ = KERNEL(m.indptr, m.indices, groups,
                                          analysis_kernels.seed_columns(seeds))
    succ = _succ(m, groups)
    expected = _scipy_labels(succ)
    sizes = Counter(expected.tolist())
    assert crowd.tolist() == [s for s, c in enumerate(expected) if sizes[c] > 1]
    assert np.array_equal(crowd, crowded(label))  # the route it replaces
    for j in range(2):
        assert np.array_equal(reach[:, j], _reaching_fixpoint(succ, seeds[:, j]))


def _forced(monkeypatch: pytest.MonkeyPatch) -> None:
    """The fused route taken on a small matrix, the kernel run as Python."""
    monkeypatch.setattr(analysis_reach, "_kernels", lambda: SimpleNamespace(
        components_reach=KERNEL, seed_columns=analysis_kernels.seed_columns))
    monkeypatch.setattr(analysis_reach, "SMALL", 0)
    monkeypatch.setattr(analysis_gates, "PAID_MIN_ENTRIES", 0)
    monkeypatch.setattr(analysis_reach, "component_walks", lambda entries, states: None)


@pytest.mark.parametrize("spread", [0, 3])
@pytest.mark.parametrize("with_extra", [False, True])
def test_fused_record_matches_scipys_route(monkeypatch, spread: int, with_extra: bool) -> None:
    """``spread`` 0: every state a self-loop only, so every component one state (crowd
    empty, in :func:`crowded`'s int64)."""
    rng = np.random.default_rng(8421 + spread)
    m, groups = _matrix(rng, 700, spread) if spread else _matrix(rng, 700, 1)
    if not spread:  # each choice's entries pointing forward only: no cycle but self-loops
        m = _forward(m, groups)
    n = groups.size - 1
    seeds = rng.random((n, 2)) < 0.03
    extra = rng.random(n) < 0.02 if with_extra else None
    found_s, reach_s, _ = components_reaching(m, groups, seeds)
    _forced(monkeypatch)
    got = analysis_reach.fused_components_reaching(m, groups, seeds, extra)
    assert got is not None
    found, reach, reached, crowd = got
    # the same partition (a graph this small is numbered by SciPy's route's Python walk)
    pairs = set(zip(found.component.tolist(), found_s.component.tolist(), strict=True))
    assert len(pairs) == len(set(found.component.tolist())) == len(set(found_s.component.tolist()))
    assert reach.dtype == bool and reach.shape == (n, 2) and reach.flags.c_contiguous
    assert np.array_equal(reach, reach_s)
    want = crowded(found.component)  # the route it replaces
    assert crowd.dtype == want.dtype and np.array_equal(crowd, want)
    succ = _succ(m, groups)
    labels = _scipy_labels(succ)
    sizes = Counter(labels.tolist())
    assert crowd.tolist() == [s for s, c in enumerate(labels) if sizes[c] > 1]
    if not spread:
        assert max(sizes.values()) == 1 and crowd.size == 0
    else:  # the case is not vacuous
        assert crowd.size > 0
    if with_extra:
        assert reached is not None and reached.flags.c_contiguous
        assert np.array_equal(reached, _reaching_fixpoint(succ, extra))
    else:
        assert reached is None


def _mdp(m: sp.csr_array, groups: np.ndarray):
    from mitld_lp.mdp import MDP

    n, c = groups.size - 1, int(groups[-1])
    no = np.zeros(n, dtype=bool)
    return MDP(matrix=m, row_groups=groups, choice_actions=np.zeros(c, dtype=np.int32),
               action_names=(), initial=0, target=no, sink=no, truncated=no, states=range(n))


@pytest.mark.parametrize("spread", [0, 2])
def test_end_components_told_one_each_match_counted(spread: int) -> None:
    """``one_each`` passed (as the analysis passes it from the fused pass's crowd) gives
    the record the count gives, and :func:`singles` says what a ``Counter`` of SciPy's
    labels says."""
    from mitld_lp.solvers.analysis_ends import end_components, ends_and_sure, singles

    rng = np.random.default_rng(8422 + spread)
    m, groups = _matrix(rng, 500, max(spread, 1))
    if not spread:  # forward entries only: every component one state, self-loops kept
        m = _forward(m, groups)
    mdp = _mdp(m, groups)
    labels = _scipy_labels(_succ(m, groups))
    one_each = max(Counter(labels.tolist()).values()) == 1
    assert one_each == (not spread)
    assert singles(labels) == one_each
    maybe = rng.random(groups.size - 1) < 0.9
    zero = ~maybe & (rng.random(groups.size - 1) < 0.5)
    for told, counted in ((end_components(mdp, labels, maybe, one_each),
                           end_components(mdp, labels, maybe)),
                          (ends_and_sure(mdp, labels, maybe, zero, one_each)[0],
                           ends_and_sure(mdp, labels, maybe, zero)[0])):
        assert told.n_mecs == counted.n_mecs
        assert np.array_equal(np.asarray(told.mec_of), np.asarray(counted.mec_of))
        assert np.array_equal(np.asarray(told.internal), np.asarray(counted.internal))
    if not spread:  # each maybe state with a choice that only loops is one, alone
        loops = {s for s in np.flatnonzero(maybe) for r in range(groups[s], groups[s + 1])
                 if set(m.indices[m.indptr[r]:m.indptr[r + 1]].tolist()) == {s}}
        assert len(loops) > 10  # not vacuous
        assert end_components(mdp, labels, maybe, True).n_mecs == len(loops)
