"""The deadline solve stage's set-up cut (issue 45), each piece against a plain loop
written here on random acyclic models: the single levels' choice pointers counted, not
searched (``SingleLevels.choice_entry``); the certificate's chain walk with each state's
right-hand side, rounding term and divisor gathered once for a run
(``certify_chain._Singles``); the rows' entries copied by SciPy's compiled row gather
(``rows.row_entries``, ``off_diagonal_entries``); the level walks' clip by its ufunc
(the bounds and values walks are ``test_deadline_walks``' and ``test_deadline_fuse``');
the component levels' reach searched from the seeds' one component on the reversed graph
itself (``level_search.searched_levels``); and a small PRISM deadline model solved end
to end against Storm's exact engine, with the levels walked and searched: the bracket
holds the exact value, the same bits either way."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.solvers import certify_chain, graph, level_search
from mitld_lp.solvers import rows as rows_mod
from mitld_lp.solvers.analysis import analyse
from mitld_lp.solvers.graph import Sense, graph_blocks
from mitld_lp.solvers.topological import SingleLevels

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_deadline_walks import (  # noqa: E402,I001
    _deadline_mdp,
    _plain_components,
    _plain_levels,
    _random_graph,
    _searches,
    walked_and_searched,
)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
@pytest.mark.parametrize("ties", [False, True])
def test_single_levels_choice_pointers_are_each_choices_kept_entries(seed: int,
                                                                    ties: bool) -> None:
    mdp = _deadline_mdp(seed, ties=ties)
    q, _ = analyse(mdp, mdp.target, sense=Sense.MAX)
    sl = SingleLevels(q, q.order, compiled=False)
    m = q.matrix
    # per single state's choice, its entries but the self-loop, counted row by row
    want = [0]
    for i, s in enumerate(sl.states.tolist()):
        for c in range(int(q.row_groups[s]), int(q.row_groups[s + 1])):
            assert int(sl.choices[sl.state_choice[i] + c - q.row_groups[s]]) == c
            cols = m.indices[m.indptr[c]:m.indptr[c + 1]].tolist()
            want.append(want[-1] + sum(1 for col in cols if col != s))
    assert sl.choice_entry.tolist() == want
    assert sl.ptr is not None and sl.ptr.tolist() == want
    assert int(sl.choice_entry[-1]) == sl.cols.size > 0


def _acyclic_chain(seed: int, n: int = 300) -> sp.csr_array:
    """A transient chain on ``n`` states: each row moves only to higher states (or stays,
    with a self-loop below 1), some mass leaves the chain; its entries in a shuffled
    order within each row (the walk sums them in the row's order)."""
    rng = np.random.default_rng(seed)
    rows, cols, vals = [], [], []
    for s in range(n):
        ahead = [int(t) for t in rng.choice(np.arange(s + 1, min(n, s + 9)),
                                            size=min(3, n - 1 - s), replace=False)] \
            if s < n - 1 else []
        targets = ahead + ([s] if rng.random() < 0.5 else [])
        rng.shuffle(targets)
        w = rng.random(len(targets) + 1) + 0.05
        p = w / w.sum()  # the last share leaves the chain
        for t, v in zip(targets, p[:-1], strict=False):
            rows.append(s)
            cols.append(t)
            vals.append(float(v))
    order = np.lexsort((rng.random(len(rows)), rows))  # grouped by row, shuffled within
    r, c, v = (np.asarray(a)[order] for a in (rows, cols, vals))
    ptr = np.concatenate([[0], np.cumsum(np.bincount(r, minlength=n))])
    return sp.csr_array((v, c, ptr), shape=(n, n))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_chain_walk_is_the_plain_loop_to_the_bit(seed: int) -> None:
    sub = _acyclic_chain(seed)
    n = sub.shape[0]
    rng = np.random.default_rng(seed + 100)
    b = rng.random(n) * 0.3
    kappa = rng.random(n) * 1e-14
    diag = sub.diagonal()
    blk = graph_blocks(sp.csr_array(sub != 0, dtype=np.float64), diag)
    assert blk.n_levels > 30 and bool(np.all(blk.size == 1))
    singles = certify_chain._Singles(sub, blk)
    want_ptr = [0]
    for s in singles.order.tolist():
        want_ptr.append(want_ptr[-1] + int(sub.indptr[s + 1] - sub.indptr[s]))
    assert singles.entry_at.tolist() == want_ptr
    v, w = np.zeros(n), np.zeros(n)
    half = blk.n_levels // 2  # two runs of levels, as the walk is called between blocks
    singles.solve(0, half, b, kappa, diag, v, w)
    singles.solve(half, blk.n_levels, b, kappa, diag, v, w)
    pv, pw = [0.0] * n, [0.0] * n
    for s in range(n - 1, -1, -1):  # every successor is a higher state: done first
        acc_v = acc_w = 0.0
        for e in range(int(sub.indptr[s]), int(sub.indptr[s + 1])):
            col, p = int(sub.indices[e]), float(sub.data[e])
            acc_v += p * pv[col]  # the state's own entry reads 0: not solved yet
            acc_w += p * pw[col]
        stay = float(diag[s])
        pv[s] = (float(b[s]) + acc_v) / (1.0 - stay)
        pw[s] = (2.0 * float(kappa[s]) * pv[s] + acc_w) / (1.0 - stay)
    assert v.tobytes() == np.asarray(pv).tobytes()
    assert w.tobytes() == np.asarray(pw).tobytes()
    # the whole chain through the solve the certificate calls, the same bits
    v2, w2 = certify_chain._solve(sub, b, kappa, None)
    assert v2.tobytes() == v.tobytes() and w2.tobytes() == w.tobytes()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_reach_from_one_component_matches_a_plain_search(seed: int, monkeypatch) -> None:
    monkeypatch.setattr(graph, "SMALL", 0)  # every graph large and thin: searched
    monkeypatch.setattr(graph, "PROBE_LEVELS", 1)
    monkeypatch.setattr(level_search, "LEVEL_CALL_SECONDS", 1.0)
    used = _searches(monkeypatch)
    n = 1200
    g = _random_graph(seed, n)
    succ = [g.indices[g.indptr[v]:g.indptr[v + 1]].tolist() for v in range(n)]
    label = _plain_components(n, succ)
    sizes = np.bincount(label)
    rng = np.random.default_rng(seed + 20)
    seeds = np.zeros((n, 4), dtype=bool)
    seeds[int(rng.integers(n)), 0] = True  # one state
    big = int(np.argmax(sizes))  # every state of a component of several (a cycle)
    assert sizes[big] > 1
    seeds[np.asarray(label) == big, 1] = True
    seeds[rng.choice(n, 5, replace=False), 2] = True  # several components: joined node
    # column 3: none
    found = graph.levels(g, seeds)
    assert used == [True]
    level, reach = _plain_levels(n, succ, label, seeds)
    assert max(level.values()) > 50
    for v in range(n):
        c = int(found.component[v])
        assert found.level[c] == level[label[v]], v
        assert found.reach[c].tolist() == reach[label[v]], v
    assert found.reach[:, 0].any() and found.reach[:, 1].any() and found.reach[:, 2].any()
    assert not found.reach[:, 3].any()


LATE = """mdp
const int D = 48;
module m
  t : [0..D] init 0;
  x : [0..9] init 0;
  [go] t<D & x<9 -> 0.3 : (x'=x+1)&(t'=t+1) + 0.1 : (x'=max(x-1,0))&(t'=t+1) + 0.6 : (t'=t+1);
  [wait] t<D & x<9 -> 0.15 : (x'=x+1)&(t'=t+1) + 0.85 : (t'=t+1);
  [jump] t<D-2 & x<8 -> 0.12 : (x'=x+2)&(t'=t+3) + 0.08 : (x'=0)&(t'=t+3) + 0.8 : (t'=t+3);
  [stop] t=D | x=9 -> true;
endmodule
label "goal" = x=9;
"""


@pytest.mark.parametrize("objective, prop", [("max", "Pmax=? [F \"goal\"]"),
                                             ("min", "Pmin=? [F \"goal\"]")])
def test_prism_deadline_solve_holds_storms_exact_value(tmp_path, monkeypatch,
                                                       objective: str, prop: str) -> None:
    walked_and_searched(tmp_path, monkeypatch, LATE, "x=9", objective, prop)


@pytest.mark.parametrize("index", [np.int32, np.int64])
def test_row_entries_are_each_rows_stored_entries_in_order(index) -> None:
    rng = np.random.default_rng(7)
    n_rows, n_cols = 60, 40
    lengths = rng.integers(0, 5, n_rows)
    ptr = np.concatenate([[0], np.cumsum(lengths)]).astype(index)
    cols = rng.integers(0, n_cols, int(ptr[-1])).astype(index)  # unsorted, repeats
    vals = rng.random(int(ptr[-1]))
    m = sp.csr_array((vals, cols, ptr), shape=(n_rows, n_cols))
    rows = rng.integers(0, n_rows, 90)  # repeats, any order
    want = [(i, int(m.indices[e]), float(m.data[e])) for i, r in enumerate(rows.tolist())
            for e in range(int(ptr[r]), int(ptr[r + 1]))]
    for got in (rows_mod.row_entries(m, rows),
                rows_mod.row_entries(m, rows.astype(np.int32))):
        local, c, v = got
        assert list(zip(local.tolist(), c.tolist(), v.tolist(), strict=True)) == want
        assert c.dtype == m.indices.dtype
    # a row past the last is refused, as NumPy's indexing refuses it
    with pytest.raises(IndexError):
        rows_mod.row_entries(m, np.array([n_rows]))
    # the off-diagonal entries: each row's entry in its state's column left out
    state = rng.integers(0, n_cols, rows.size)
    local, c, v = rows_mod.off_diagonal_entries(m, rows, state)
    kept = [(i, col, val) for i, col, val in want if col != state[i]]
    assert list(zip(local.tolist(), c.tolist(), v.tolist(), strict=True)) == kept
