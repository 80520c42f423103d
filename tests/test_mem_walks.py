"""The single-state walks' memory (issue 45, <= 50 bytes a transition): the NumPy walks
of level_batches gather their per-entry and per-choice arrays a group of runs at a time
(bounds upward, flow upstream first), and rows.off_diagonal_entries writes each batch's
kept entries into outputs made once.  Each against a computation written here: the
grouped walks with a tiny forced group size against the whole walk in one group and a
state-by-state loop, to the bit; the entries against a row-by-row Python read."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.solvers import level_batches, rows
from mitld_lp.solvers.analysis import analyse
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.topological import SingleLevels

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_deadline_walks import _deadline_mdp, _plain_order, _plain_rows  # noqa: E402

# ------------------------------------------------------------------------- the groups


@pytest.mark.parametrize("limit", [1, 5, 40])
def test_groups_cut_the_runs_in_order_within_the_limit(monkeypatch, limit: int) -> None:
    mdp = _deadline_mdp(3)
    q, _ = analyse(mdp, mdp.target)
    sl = SingleLevels(q, q.order, compiled=False)
    monkeypatch.setattr(level_batches, "GROUP_ENTRIES", limit)
    groups = level_batches._groups(sl.runs)
    assert [r for g in groups for r in g] == sl.runs  # every run once, in order
    assert len(groups) > 3
    for g in groups:
        entries, choices = g[-1][5] - g[0][4], g[-1][3] - g[0][2]
        assert len(g) == 1 or (entries <= limit and choices <= limit)
    for g, h in zip(groups, groups[1:], strict=False):  # each as long as it could be
        assert h[-1][5] - g[0][4] > limit or h[0][3] - g[0][2] > limit


def _walks(monkeypatch, csr: bool):
    """The batched walks with SciPy's compiled products (``csr``) or the ``bincount``
    ones (SciPy's taken away)."""
    if not csr:
        monkeypatch.setattr(level_batches, "sparsetools", None)


def _bounds(q, sl, rewards):
    got = np.zeros((q.n_states, rewards.shape[1]))
    sl.solve(0, q.order.n_levels, rewards, got)
    return got


@pytest.mark.parametrize("csr", [True, False])
@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize("seed", [0, 4])
def test_grouped_bounds_walk_equals_the_whole_walk(
        monkeypatch, seed: int, sense: Sense, csr: bool) -> None:
    _walks(monkeypatch, csr)
    mdp = _deadline_mdp(seed, depth=30)
    q, _ = analyse(mdp, mdp.target, sense=sense)
    sl = SingleLevels(q, q.order, compiled=False)
    assert sl.positive and len(sl.runs) > 20
    rewards = np.column_stack([q.to_target, 0.25 * q.to_target])
    monkeypatch.setattr(level_batches, "GROUP_ENTRIES", 1 << 40)  # one group
    assert len(level_batches._groups(sl.runs)) == 1
    whole = _bounds(q, sl, rewards)
    for limit in (1, 7, 30):
        monkeypatch.setattr(level_batches, "GROUP_ENTRIES", limit)
        assert len(level_batches._groups(sl.runs)) > 3
        assert _bounds(q, sl, rewards).tobytes() == whole.tobytes()
    # the whole walk against the plain loop: tests/test_deadline_walks.py
    assert 0.0 < whole[:, 0].max() < 1.0 + 1e-15  # not all 0: the walk computes something


def _flow(q, sl, self_loop, weights, x0):
    x = x0.copy()
    sl.flow(0, q.order.n_levels, self_loop, weights, x)
    return x


@pytest.mark.parametrize("csr", [True, False])
@pytest.mark.parametrize("seed", [0, 5])
def test_grouped_flow_walk_equals_the_whole_walk(
        monkeypatch, seed: int, csr: bool) -> None:
    _walks(monkeypatch, csr)
    mdp = _deadline_mdp(seed, depth=30)
    q, _ = analyse(mdp, mdp.target)
    sl = SingleLevels(q, q.order, compiled=False)
    rng = np.random.default_rng(seed)
    weights = rng.random(q.matrix.shape[0])  # a randomised policy: a state's sum 1
    groups = q.row_groups
    weights /= np.repeat(np.add.reduceat(weights, groups[:-1]), np.diff(groups))
    self_loop = np.asarray(q.order.self_loop)
    x0 = rng.random(q.n_states)
    monkeypatch.setattr(level_batches, "GROUP_ENTRIES", 1 << 40)
    whole = _flow(q, sl, self_loop, weights, x0)
    for limit in (1, 7, 30):
        monkeypatch.setattr(level_batches, "GROUP_ENTRIES", limit)
        assert len(level_batches._groups(sl.runs)) > 3
        assert _flow(q, sl, self_loop, weights, x0).tobytes() == whole.tobytes()
    # the whole walk against the plain loop: tests/test_deadline_walks.py
    assert not np.array_equal(whole, x0)  # the flow moved something


def test_a_part_of_the_levels_is_walked_in_groups_too(monkeypatch) -> None:
    # a walk over some of the levels (the solve's call for a stretch between
    # components): grouped and whole agree, and the levels outside are not touched
    mdp = _deadline_mdp(6, depth=30)
    q, _ = analyse(mdp, mdp.target)
    sl = SingleLevels(q, q.order, compiled=False)
    rewards = np.column_stack([q.to_target, q.to_target])
    first, stop = 5, q.order.n_levels - 4
    start = np.random.default_rng(6).random((q.n_states, 2))
    out = []
    for limit in (1 << 40, 3):
        monkeypatch.setattr(level_batches, "GROUP_ENTRIES", limit)
        b = start.copy()
        sl.solve(first, stop, rewards, b)
        out.append(b)
    assert out[0].tobytes() == out[1].tobytes()
    at = sl.level_state
    inside = sl.states[int(at[first]):int(at[stop])]
    outside = np.setdiff1d(np.arange(q.n_states), inside)
    assert np.array_equal(out[1][outside], start[outside])
    assert not np.array_equal(out[1][inside], start[inside])


# -------------------------------------------------------------- the set-up's entries


def _plain_off_diagonal(matrix: sp.csr_array, rows_: np.ndarray, row_state: np.ndarray):
    local, cols, vals = [], [], []
    for i, r in enumerate(rows_.tolist()):
        for e in range(int(matrix.indptr[r]), int(matrix.indptr[r + 1])):
            if int(matrix.indices[e]) != int(row_state[i]):
                local.append(i)
                cols.append(int(matrix.indices[e]))
                vals.append(float(matrix.data[e]))
    return local, cols, vals


@pytest.mark.parametrize("batch", [1, 3, 1 << 16])
@pytest.mark.parametrize("index", [np.int32, np.int64])
def test_off_diagonal_entries_equal_a_plain_read(monkeypatch, batch: int, index) -> None:
    monkeypatch.setattr(rows, "BATCH", batch)
    rng = np.random.default_rng(batch)
    m, n = 60, 25
    dense = rng.random((m, n)) * (rng.random((m, n)) < 0.3)
    dense[rng.random(m) < 0.2] = 0.0  # some empty rows
    matrix = sp.csr_array(dense)
    matrix.indices = matrix.indices.astype(index)
    matrix.indptr = matrix.indptr.astype(index)
    picked = rng.choice(m, 40, replace=False)  # any order
    row_state = rng.integers(0, n, size=picked.size)
    # make about half of the rows' "self-loop" column one they store
    for i, r in enumerate(picked.tolist()):
        lo, hi = matrix.indptr[r], matrix.indptr[r + 1]
        if hi > lo and i % 2 == 0:
            row_state[i] = matrix.indices[lo + (hi - lo) // 2]
    local, cols, vals = rows.off_diagonal_entries(matrix, picked, row_state)
    want = _plain_off_diagonal(matrix, picked, row_state)
    assert (local.tolist(), cols.tolist(), vals.tolist()) == want
    assert len(want[0]) < matrix.indptr[picked + 1].sum() - matrix.indptr[picked].sum()
    assert local.dtype == np.int32 and cols.dtype == index and vals.dtype == np.float64
    for a in (local, cols, vals):  # plain arrays of their own, the kept entries only
        assert a.flags.c_contiguous and a.flags.owndata and a.base is None


def test_off_diagonal_entries_of_no_rows() -> None:
    matrix = sp.csr_array(np.eye(3))
    local, cols, vals = rows.off_diagonal_entries(matrix, np.zeros(0, dtype=np.int64),
                                                  np.zeros(0, dtype=np.int64))
    assert local.size == cols.size == vals.size == 0
    local, cols, vals = rows.off_diagonal_entries(matrix, np.arange(3), np.arange(3))
    assert local.size == cols.size == vals.size == 0  # every entry a self-loop


def test_single_levels_keeps_no_owner_and_its_level_offsets_are_right() -> None:
    mdp = _deadline_mdp(2, depth=20, ties=True)
    q, _ = analyse(mdp, mdp.target)
    sl = SingleLevels(q, q.order, compiled=False)
    assert not hasattr(sl, "owner")
    # per choice, its state's position counted from its level's first state
    want = []
    for level in _plain_order(sl):
        for i in level:
            want += [i - level[0]] * int(sl.state_choice[i + 1] - sl.state_choice[i])
    assert sl.owner_at.tolist() == want and sl.owner_at.dtype == np.int32
    # the NumPy walks' indices in 4 bytes, one array of entry pointers
    for name in ("states", "choices", "state_choice", "choice_entry", "local", "cols"):
        assert getattr(sl, name).dtype == np.int32, name
    assert sl.choice_entry is sl.ptr
    lo = np.asarray(q.row_groups)[sl.states.astype(np.int64)]  # each state's choices in order
    assert np.array_equal(sl.choices[sl.state_choice[:-1]], lo)
    assert np.array_equal(np.diff(sl.state_choice),
                          np.asarray(q.row_groups)[sl.states.astype(np.int64) + 1] - lo)


def _values(q, sl, skip):
    out = np.zeros(q.n_states)
    reduced = np.full(q.n_states, -1, dtype=np.int64)
    weights = np.zeros(q.matrix.shape[0])
    sl.values(0, q.order.n_levels, q.to_target, skip, out, reduced, weights)
    return out, reduced, weights


@pytest.mark.parametrize("csr", [True, False])
@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize("skipping", [False, True])
def test_grouped_values_walk_equals_the_whole_walk_and_the_plain_loop(
        monkeypatch, sense: Sense, skipping: bool, csr: bool) -> None:
    # the LP's values walk: each level's values and the choice among near-ties (the
    # larger preference, then the first), the deferred picks made per group
    _walks(monkeypatch, csr)
    mdp = _deadline_mdp(7, depth=30, ties=True)
    q, _ = analyse(mdp, mdp.target, sense=sense)
    sl = SingleLevels(q, q.order, compiled=False)
    skip = np.zeros(q.n_states, dtype=bool)
    if skipping:
        skip[np.random.default_rng(7).choice(q.n_states, q.n_states // 5, replace=False)] = True
    monkeypatch.setattr(level_batches, "GROUP_ENTRIES", 1 << 40)
    whole = _values(q, sl, skip)
    picked = level_batches._picked
    calls = []
    monkeypatch.setattr(level_batches, "_picked",
                        lambda *a: calls.append(1) or picked(*a))  # deferred picks made
    for limit in (1, 7, 30):
        monkeypatch.setattr(level_batches, "GROUP_ENTRIES", limit)
        calls.clear()
        got = _values(q, sl, skip)
        assert len(calls) > 1  # the deferred picks of several groups
        assert all(g.tobytes() == w.tobytes() for g, w in zip(got, whole, strict=True))
    out = np.zeros(q.n_states)  # the plain loop, state by state
    reduced = np.full(q.n_states, -1, dtype=np.int64)
    maximum = sense is Sense.MAX
    for level in _plain_order(sl):
        for i in level:
            s, choices = _plain_rows(q, sl, i)
            if skip[s]:
                continue
            scores = []
            for c, stay, entries in choices:
                acc = 0.0
                for col, v in entries:
                    acc += v * out[col]
                scores.append(min(max((q.to_target[c] + acc) / (1.0 - stay), 0.0), 1.0))
            top = max(scores) if maximum else min(scores)
            tied = [j for j, x in enumerate(scores)
                    if (x - top if maximum else top - x) >= -level_batches.TIE * abs(top)]
            pref = [q.to_target[choices[j][0]] * (1 if maximum else -1) for j in tied]
            j = tied[pref.index(max(pref))]  # the largest preference, then the first
            out[s], reduced[s] = scores[j], choices[j][0]
    assert whole[0].tobytes() == out.tobytes()
    assert whole[1].tolist() == reduced.tolist()
    assert np.flatnonzero(whole[2]).tolist() == sorted(reduced[reduced >= 0].tolist())
