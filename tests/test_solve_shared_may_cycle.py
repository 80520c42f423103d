""":func:`~mitld_lp.solvers.analysis.may_cycle`, the candidates of an end component
that the analysis's search and the certificate's ``_escapes`` read, made without a
minimum and a maximum over every entry: on random MDPs (some choices a loop on their
own state alone, some with the loop's entry first and others after it, some stored
twice in a row as a non-canonical matrix may hold them) it equals the definition
computed apart: the states of a strongly connected component of more than one state
(a transitive closure of the support graph, by squaring) and those with a choice all
of whose entries lie in their own column (a loop over the rows).  The reduction it
replaced (a minimum and a maximum per row) gives the same states, and the end
components found from it are those of the plain search."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.mdp import MDP
from mitld_lp.solvers.analysis import end_components, may_cycle
from mitld_lp.solvers.graph import maximal_end_components, state_levels


def _mdp(seed: int, canonical: bool) -> MDP:
    rng = np.random.default_rng(900 + seed)
    n = int(rng.integers(2, 12))
    counts = rng.integers(1, 4, size=n)
    groups = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    data: list[float] = []
    cols: list[int] = []
    ptr = [0]
    for s in range(n):
        for _ in range(int(counts[s])):
            kind = rng.random()
            if kind < 0.2:  # stays put
                row = [s, s] if (not canonical and rng.random() < 0.5) else [s]
            elif kind < 0.35:  # its own column first, then elsewhere
                row = [s, int(rng.integers(0, n))]
            else:
                k = int(rng.integers(1, 4))
                row = [int(t) for t in rng.choice(n, min(k, n), replace=False)]
                if canonical:
                    row.sort()
            cols += row
            data += [1.0 / len(row)] * len(row)
            ptr.append(len(cols))
    matrix = sp.csr_array((np.array(data), np.array(cols, dtype=np.int32),
                           np.array(ptr, dtype=np.int32)), shape=(int(groups[-1]), n))
    no = np.zeros(n, dtype=bool)
    return MDP(matrix=matrix, row_groups=groups,
               choice_actions=np.zeros(int(groups[-1]), dtype=np.int32), action_names=(),
               initial=0, target=no, sink=no, truncated=no, states=range(n))


def _defined(mdp: MDP) -> np.ndarray:
    n = mdp.n_states
    m = mdp.matrix
    adj = np.zeros((n, n), dtype=bool)
    stays = np.zeros(n, dtype=bool)
    groups = np.asarray(mdp.row_groups)
    for s in range(n):
        for c in range(groups[s], groups[s + 1]):
            row = m.indices[m.indptr[c]:m.indptr[c + 1]]
            adj[s, row] = True
            stays[s] |= bool(row.size) and bool(np.all(row == s))
    closure = adj.copy()
    while True:
        nxt = closure | ((closure.astype(int) @ closure.astype(int)) > 0)
        if np.array_equal(nxt, closure):
            break
        closure = nxt
    cyclic = np.array([any(closure[s, t] and closure[t, s] for t in range(n) if t != s)
                       for s in range(n)])
    return cyclic | stays


def _reduced(mdp: MDP, comp: np.ndarray) -> np.ndarray:
    """The per-row minimum and maximum it replaced (every row has entries here)."""
    size = np.bincount(comp)
    m = mdp.matrix
    lo = np.minimum.reduceat(m.indices, m.indptr[:-1])
    hi = np.maximum.reduceat(m.indices, m.indptr[:-1])
    pure = (lo == hi) & (lo == mdp.choice_state())
    return (size[comp] > 1) | np.logical_or.reduceat(pure, mdp.row_groups[:-1])


@pytest.mark.parametrize("canonical", [True, False])
def test_may_cycle_is_its_definition(canonical: bool) -> None:
    seen = 0
    for seed in range(60):
        mdp = _mdp(seed, canonical)
        comp = state_levels(sp.csr_array(mdp.matrix), np.asarray(mdp.row_groups)).component
        got = may_cycle(mdp, comp)
        assert np.array_equal(got, _defined(mdp)), seed
        assert np.array_equal(got, _reduced(mdp, comp)), seed
        seen += int(got.sum())
        if canonical:  # the search from these candidates: the plain search's components
            maybe = np.ones(mdp.n_states, dtype=bool)
            a = end_components(mdp, comp, maybe)
            b = maximal_end_components(mdp, maybe)
            assert a.n_mecs == b.n_mecs, seed
            inside_a, inside_b = np.asarray(a.mec_of) >= 0, np.asarray(b.mec_of) >= 0
            assert np.array_equal(inside_a, inside_b), seed
            assert np.array_equal(np.asarray(a.internal), np.asarray(b.internal)), seed
    assert seen > 50
