"""The LP's policy flow swept by one compiled product (``level_sweeps.flow``, issue 45)
on random acyclic MDPs with thin levels: the same bits as the level walk and as a
state-by-state loop written here; it declines (the walk runs) where the walk is not
linear; the flow it gives is the occupancy of a dense linear solve; and the LP stage
that uses it gives the value of a brute-force backward induction written here, for a
maximum and a minimum."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import build_mdp

from mitld_lp.solvers import level_batches, level_sweeps
from mitld_lp.solvers.analysis import analyse
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.lp import solve_lp
from mitld_lp.solvers.topological import SingleLevels


def _acyclic(seed: int, n: int = 120, loops: bool = False):
    """``n`` states, each with 1-3 choices moving only to higher-numbered states, the
    goal or the dead end (acyclic but for self-loops, with ``loops`` on a third of the
    choices); returns the MDP and its rows ``[(choice's {successor: p})]`` per state."""
    rng = np.random.default_rng(seed)
    goal, dead = n, n + 1
    states = []
    for s in range(n):
        mine = []
        for a in range(int(rng.integers(1, 4))):
            ahead = [int(t) for t in rng.integers(s + 1, s + 12, size=3) if t < n]
            nxt = [goal, dead, *ahead]
            w = rng.integers(0, 9, size=len(nxt)).astype(float)
            w[0] = w[0] if rng.random() < 0.3 else 0.0
            w[1] += 1.0
            if loops and rng.random() < 0.33:
                nxt.append(s)
                w = np.append(w, float(rng.integers(1, 5)))
            p = w / w.sum()
            row: dict[int, float] = {}
            for t, q in zip(nxt, p, strict=True):
                if q > 0:
                    row[t] = row.get(t, 0.0) + float(q)
            row[dead] += 1.0 - sum(row.values())
            mine.append((f"a{a}", row))
        states.append(mine)
    rows = [[r for _, r in mine] for mine in states]
    states += [[], []]
    return build_mdp(states, target=[goal], sink=[dead]), rows


def _backward(rows, n: int, maximum: bool) -> np.ndarray:
    """Brute-force backward induction (highest state first): ``v(goal) = 1``,
    ``v(dead) = 0``, ``v(s) = opt_c (sum_{t != s} p(t) v(t)) / (1 - p(s))``."""
    v = np.zeros(n + 2)
    v[n] = 1.0
    for s in range(n - 1, -1, -1):
        scores = []
        for row in rows[s]:
            stay = row.get(s, 0.0)
            scores.append(sum(p * v[t] for t, p in row.items() if t != s) / (1.0 - stay))
        v[s] = max(scores) if maximum else min(scores)
    return v


def _deterministic(q, sl: SingleLevels, rng) -> np.ndarray:
    """Weight 1 on one choice of each single state, drawn among those that keep no
    self-loop (none if every choice keeps one)."""
    weights = np.zeros(q.matrix.shape[0])
    loop = np.asarray(q.order.self_loop)
    for s in sl.states.tolist():
        free = [c for c in range(int(q.row_groups[s]), int(q.row_groups[s + 1]))
                if loop[c] == 0.0]
        if free:
            weights[free[int(rng.integers(len(free)))]] = 1.0
    return weights


def _plain_flow(q, sl: SingleLevels, self_loop, weights, x0) -> np.ndarray:
    """The flow walk state by state: the levels upstream first, a level's states
    divided by what they keep, then each sent along its choices' entries in order."""
    x = x0.copy()
    m = q.matrix
    at = sl.level_state
    for k in range(at.size - 2, -1, -1):
        level = [int(s) for s in sl.states[int(at[k]):int(at[k + 1])]]
        for s in level:
            kept = 0.0
            for c in range(int(q.row_groups[s]), int(q.row_groups[s + 1])):
                kept += weights[c] * self_loop[c]
            x[s] /= 1.0 - kept
        for s in level:
            for c in range(int(q.row_groups[s]), int(q.row_groups[s + 1])):
                for e in range(int(m.indptr[c]), int(m.indptr[c + 1])):
                    if m.indices[e] != s:
                        x[m.indices[e]] += m.data[e] * (weights[c] * x[s])
    return x


def _groups(sl: SingleLevels, entries: int | None = None):
    """All of ``sl``'s runs in the walk's groups (of ``entries`` entries if given)."""
    runs = sl._runs(0, sl.level_state.size - 1)
    if entries is None:
        return level_batches._groups(runs)
    out, at = [], 0
    for r in runs:
        if not out or r[5] - at > entries:
            out.append([])
            at = r[4]
        out[-1].append(r)
    return out


def _walked(sl: SingleLevels, self_loop, weights, x0) -> np.ndarray:
    """The level walk the sweep replaces, group by group (upstream first)."""
    x = x0.copy()
    runs = sl._runs(0, sl.level_state.size - 1)
    for group in reversed(level_batches._groups(runs)):
        level_batches._flow(sl, group, self_loop, weights, x)
    return x


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize("loops", [False, True])
def test_swept_flow_is_the_walk_and_the_plain_loop_to_the_bit(seed, sense, loops) -> None:
    mdp, _ = _acyclic(seed, loops=loops)
    q, _ = analyse(mdp, mdp.target, sense=sense)
    sl = SingleLevels(q, q.order, compiled=False)
    assert len(sl.runs) > 20 and sl.ptr is not None
    rng = np.random.default_rng(seed)
    weights = _deterministic(q, sl, rng)
    self_loop = np.asarray(q.order.self_loop)
    x0 = rng.random(q.n_states)
    x0[rng.random(q.n_states) < 0.3] = 0.0
    got = x0.copy()
    assert level_sweeps.flow(sl, _groups(sl), self_loop, weights, got)
    assert got.tobytes() == _walked(sl, self_loop, weights, x0).tobytes()
    assert got.tobytes() == _plain_flow(q, sl, self_loop, weights, x0).tobytes()
    small = x0.copy()  # a sweep a group of some 40 entries: the same bits
    assert len(_groups(sl, 40)) > 5
    assert level_sweeps.flow(sl, _groups(sl, 40), self_loop, weights, small)
    assert small.tobytes() == got.tobytes()
    via = x0.copy()  # the walk's entry point takes the sweep
    sl.flow(0, q.order.n_levels, self_loop, weights, via)
    assert via.tobytes() == got.tobytes()


@pytest.mark.parametrize("seed", [0, 1])
def test_sweep_declines_where_the_walk_is_not_linear(seed) -> None:
    mdp, _ = _acyclic(seed, loops=True)
    q, _ = analyse(mdp, mdp.target)
    sl = SingleLevels(q, q.order, compiled=False)
    self_loop = np.asarray(q.order.self_loop)
    runs = _groups(sl)
    rng = np.random.default_rng(seed)
    x0 = rng.random(q.n_states)
    # a randomised policy: weights strictly between 0 and 1
    groups = q.row_groups
    mixed = rng.random(q.matrix.shape[0]) + 0.1
    mixed /= np.repeat(np.add.reduceat(mixed, groups[:-1]), np.diff(groups))
    many = np.diff(groups)[sl.states] > 1
    assert many.any()
    x = x0.copy()
    assert not level_sweeps.flow(sl, runs, self_loop, mixed, x)
    assert x.tobytes() == x0.tobytes()
    # a deterministic policy choosing a self-loop somewhere
    weights = _deterministic(q, sl, rng)
    looped = np.flatnonzero(self_loop > 0)
    looped = looped[np.isin(looped, sl.choices)]
    assert looped.size
    c = int(looped[0])
    s = int(np.searchsorted(q.row_groups, c, side="right") - 1)
    weights[q.row_groups[s]:q.row_groups[s + 1]] = 0.0
    weights[c] = 1.0
    assert not level_sweeps.flow(sl, runs, self_loop, weights, x)
    assert x.tobytes() == x0.tobytes()
    # both still walked, as the plain loop does
    for w in (mixed, weights):
        walked = x0.copy()
        sl.flow(0, q.order.n_levels, self_loop, w, walked)
        assert walked.tobytes() == _plain_flow(q, sl, self_loop, w, x0).tobytes()


@pytest.mark.parametrize("seed", [4, 5])
def test_swept_flow_is_the_occupancy_of_a_dense_solve(seed) -> None:
    mdp, _ = _acyclic(seed)
    q, _ = analyse(mdp, mdp.target)
    sl = SingleLevels(q, q.order, compiled=False)
    rng = np.random.default_rng(seed)
    weights = _deterministic(q, sl, rng)
    self_loop = np.asarray(q.order.self_loop)
    x0 = rng.random(q.n_states)
    got = x0.copy()
    assert level_sweeps.flow(sl, _groups(sl), self_loop, weights, got)
    # x = x0 + P_w' x over the quotient's states, P_w the policy's chain, solved dense
    dense = q.matrix.toarray()[:, :q.n_states]
    owner = np.repeat(np.arange(q.n_states), np.diff(q.row_groups))
    chain = np.zeros((q.n_states, q.n_states))
    np.add.at(chain, owner, weights[:, None] * dense)
    want = np.linalg.solve(np.eye(q.n_states) - chain.T, x0)
    assert np.allclose(got, want, rtol=1e-12, atol=1e-13)


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize("loops", [False, True])
def test_lp_stage_gives_the_backward_induction_value(seed, sense, loops, monkeypatch) -> None:
    mdp, rows = _acyclic(seed, loops=loops)
    swept = []
    sweep = level_sweeps.flow

    def counted(*args):
        done = sweep(*args)
        swept.append(done)
        return done

    monkeypatch.setattr(level_sweeps, "flow", counted)
    r = solve_lp(mdp, mdp.target, sense=sense)
    want = _backward(rows, len(rows), sense is Sense.MAX)
    assert abs(r.value - want[mdp.initial]) <= 1e-12
    assert abs(r.primal_objective - want[mdp.initial]) <= 1e-12
    if not loops:  # a deterministic policy without self-loops: the flow was swept
        assert swept and all(swept)


def test_in_place_probe_refuses_a_product_that_reads_its_input_first(monkeypatch):
    """The sweep relies on SciPy's loop order: the probe says yes on this SciPy, and a
    product that reads a copy of its input (as a SciPy might) makes the flow decline."""
    from mitld_lp.solvers import level_sweeps

    monkeypatch.setattr(level_sweeps, "_IN_PLACE", None)
    assert level_sweeps._in_place() is True

    real = level_sweeps.sparsetools

    class _Copying:
        @staticmethod
        def csc_matvec(n_row, n_col, ptr, rows, vals, x, y):
            real.csc_matvec(n_row, n_col, ptr, rows, vals, x.copy(), y)

    monkeypatch.setattr(level_sweeps, "sparsetools", _Copying)
    monkeypatch.setattr(level_sweeps, "_IN_PLACE", None)
    assert level_sweeps._in_place() is False
