"""The repair's walk (``certify_repair._Walk.needed``) with the rounding's factors
gathered once and no reduction over states of one row each: per state, what its
choices need, the same bits as a row-by-row reference written out in plain Python
(each row's sum from 0 in its entries' order, the rounding's factors, the support's
extreme, nature's least row, the best choice), with and without nature's rows, states
of one row and of several, a state without a choice; and whole repairs the same by the
walk as state by state (every level read by its rows alone)."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.solvers import certify as C
from mitld_lp.solvers import certify_repair as R
from mitld_lp.solvers.certify_chain import support_layers
from mitld_lp.solvers.rounding import rounding
from mitld_lp.testing import random_mdp


def _reference(st: R.Rows, rnd, x: np.ndarray, s: int, upper: bool) -> float:
    """State ``s``'s need, row by row: ``max_c min_rows min(above(sum), max support)``
    for an upper bound, ``min_c min_rows max(below(sum), min support)`` for a lower
    one (``-inf`` / ``inf`` without a row); ``above``: ``(sum + slack) * high``,
    ``below``: ``max((sum - slack) * low, 0)``, by the row's count of entries."""
    m = st.matrix
    best = -np.inf if upper else np.inf
    for c in range(int(st.groups[s]), int(st.groups[s + 1])):
        rows = (range(c, c + 1) if st.nature is None else
                range(int(st.nature[c]), int(st.nature[c + 1])))
        choice = np.inf
        for r in rows:
            lo, hi = int(m.indptr[r]), int(m.indptr[r + 1])
            acc = 0.0
            for e in range(lo, hi):
                acc += float(m.data[e]) * float(x[m.indices[e]])
            support = [float(x[m.indices[e]]) for e in range(lo, hi)]
            n = hi - lo
            if upper:
                bound = (acc + float(rnd.slack_of[n])) * float(rnd.high_of[n])
                each = min(bound, max(support))
            else:
                bound = max((acc - float(rnd.slack_of[n])) * float(rnd.low_of[n]), 0.0)
                each = max(bound, min(support))
            choice = min(choice, each)
        best = max(best, choice) if upper else min(best, choice)
    return best


def _rows(seed: int, nature: bool, single: bool, empty: bool) -> tuple[R.Rows, int]:
    """Random rows of 60 states: each state 1 choice (``single``) or 1-3, each choice
    1-3 of nature's rows (``nature``), each row 1-4 positive entries; with ``empty``
    one state without a choice."""
    rng = np.random.default_rng(seed)
    n = 60
    per_state = np.ones(n, dtype=np.int64) if single else rng.integers(1, 4, size=n)
    if empty:
        per_state[17] = 0
    groups = np.concatenate([[0], np.cumsum(per_state)])
    n_choices = int(groups[-1])
    per_choice = rng.integers(1, 4, size=n_choices) if nature else np.ones(n_choices,
                                                                          np.int64)
    nat = np.concatenate([[0], np.cumsum(per_choice)])
    n_rows = int(nat[-1])
    lengths = rng.integers(1, 5, size=n_rows)
    indptr = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int32)
    cols = np.concatenate([np.sort(rng.choice(n, size=k, replace=False))
                           for k in lengths]).astype(np.int32)
    vals = rng.random(cols.size) + 0.05
    for r in range(n_rows):  # rows of probabilities (not needed by the walk; as stored)
        vals[indptr[r]:indptr[r + 1]] /= vals[indptr[r]:indptr[r + 1]].sum()
    m = sp.csr_array((vals, cols, indptr), shape=(n_rows, n))
    return R.Rows(m, groups.astype(np.int64), nat.astype(np.int64) if nature else None), n


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("nature", [False, True])
@pytest.mark.parametrize("single", [False, True])
@pytest.mark.parametrize("empty", [False, True])
@pytest.mark.parametrize("upper", [True, False])
def test_needed_is_the_row_by_row_reference(seed: int, nature: bool, single: bool,
                                            empty: bool, upper: bool) -> None:
    st, n = _rows(seed, nature, single, empty)
    rnd = rounding(st.matrix)
    rng = np.random.default_rng(100 + seed)
    x = rng.random(n)
    # the states in levels of 1 to 7 states (a level order the walk takes as given)
    # (a state without a choice first in a level of more: as last it would end the
    # segmented reductions' starts, which both routes refuse alike)
    order = rng.permutation(n)
    order = np.concatenate([[17], order[order != 17]])
    sizes = [int(rng.integers(2, 8))]
    while sum(sizes) < n:
        sizes.append(int(min(rng.integers(1, 8), n - sum(sizes))))
    levels = np.repeat(np.arange(len(sizes)), sizes)
    walk = R._Walk(st, order, levels)
    assert walk.row_entry is not None  # SciPy's product reads the levels
    assert walk.every is not empty
    at = walk.level_at.tolist()
    for a, z in zip(at[:-1], at[1:], strict=True):
        got = walk.needed(rnd, x, a, z, upper)
        want = [_reference(st, rnd, x, int(s), upper) for s in order[a:z]]
        if empty and 17 in order[a:z].tolist() and z - a > 1:
            # a state without a choice inside a level: the segmented reductions give it
            # its next state's row (as before); no repair reads it (it is never live)
            keep = order[a:z] != 17
            assert np.asarray(got)[keep].tobytes() == np.asarray(want)[keep].tobytes()
        else:
            assert np.asarray(got).tobytes() == np.asarray(want, dtype=float).tobytes()
        # the state-by-state route (every row gathered again) agrees bit for bit
        assert got.tobytes() == R._needed(st, rnd, x, order[a:z], upper).tobytes()


def _inputs(mdp) -> tuple[R.Rows, object, np.ndarray]:
    """What a repair reads of ``mdp``: its rows, their rounding, each state's level."""
    comp, level = support_layers(mdp)
    st = R.Rows(sp.csr_array(mdp.matrix), np.asarray(mdp.row_groups, dtype=np.int64))
    return st, rounding(st.matrix), np.asarray(level)[np.asarray(comp)]


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("upper", [True, False])
def test_a_repair_by_the_walk_is_the_repair_state_by_state(seed: int, upper: bool,
                                                          monkeypatch) -> None:
    """The same bounds, moves and verdict when every level is read by the rows of the
    states it takes up (``SPARSE_LEVEL`` 1) as by the walk's slices; and after it the
    whole Bellman check passes where the repair closed."""
    mdp = random_mdp(400, seed=seed, locality=4, self_loop_fraction=0.0, max_choices=3)
    st, rnd, level_of = _inputs(mdp)
    free = np.asarray(mdp.target, dtype=bool)
    rng = np.random.default_rng(seed)
    x0 = np.where(free, 1.0, rng.random(mdp.n_states) * (0.5 if upper else 1.0))
    failing = C._fails(st, rnd, x0, free, upper)
    assert failing.any()
    runs = []
    for sparse in (None, 1):
        if sparse is not None:
            monkeypatch.setattr(R, "SPARSE_LEVEL", sparse)
        x = x0.copy()
        repair = R.Repair(st, rnd, free, level_of, None, upper)
        runs.append((repair.run(x, failing), x, repair.moved))
    (ok_a, a, moved_a), (ok_b, b, moved_b) = runs
    assert ok_a == ok_b and a.tobytes() == b.tobytes() and moved_a == moved_b > 0
    if ok_a:
        assert not C._fails(st, rnd, a, free, upper).any()


def _layered(seed: int, depth: int = 25, width: int = 6):
    """A deadline-like MDP without a cycle: ``depth`` layers of ``width`` states, each
    with 1-3 choices (a third of the states with a copy of their first: an exact tie),
    each choice to the goal, the dead end and two states 1-2 layers ahead (past the
    last layer: the dead end), by multiples of 1/8 (exact floats, summing to 1
    exactly); the goal and the dead end absorbing."""
    from conftest import build_mdp

    rng = np.random.default_rng(seed)
    n = depth * width
    goal, dead = n, n + 1
    layer_of = np.arange(n) // width
    counts = rng.integers(1, 4, size=n)
    states: list[list[tuple[str, dict[int, float]]]] = [[] for _ in range(n)]
    for s_, c in zip(np.repeat(np.arange(n), counts).tolist(),
                     rng.multinomial(8, [0.15, 0.15, 0.35, 0.35], size=int(counts.sum())),
                     strict=True):
        ahead = (layer_of[s_] + rng.integers(1, 3, size=2)) * width + rng.choice(
            width, 2, replace=False)
        row: dict[int, float] = {}
        for t, k in zip([goal, dead, *np.where(ahead < n, ahead, dead).tolist()],
                        c.tolist(), strict=True):
            if k:
                row[t] = row.get(t, 0.0) + k / 8
        states[s_].append((f"a{len(states[s_])}", row))
    for s_ in np.flatnonzero(rng.random(n) < 0.3).tolist():
        states[s_].append((f"a{len(states[s_])}", dict(states[s_][0][1])))
    states += [[], []]
    return build_mdp(states, target=[goal], sink=[dead]), goal, dead


def _exact_optimum(mdp, goal: int, upper: bool) -> list[Fraction]:
    """Pmax (``upper``) or Pmin of reaching the goal, in fractions, backwards over the
    layers (every choice moves ahead: no cycle but the absorbing states')."""
    m = sp.csr_array(mdp.matrix)
    groups = np.asarray(mdp.row_groups)
    value = [Fraction(0)] * mdp.n_states
    value[goal] = Fraction(1)
    for s in range(mdp.n_states - 3, -1, -1):
        each = []
        for c in range(int(groups[s]), int(groups[s + 1])):
            lo, hi = int(m.indptr[c]), int(m.indptr[c + 1])
            each.append(sum((Fraction(float(m.data[e])) * value[int(m.indices[e])]
                             for e in range(lo, hi)), Fraction(0)))
        value[s] = max(each) if upper else min(each)
    return value


def _far_candidate(seed: int, upper: bool, draw: int):
    """A layered model (:func:`_layered`), its check's inputs, the states ``free`` of the
    side and a candidate far from the optimum (random values drawn with seed ``draw``:
    many states fail, their moves run up the layers) with its failing states."""
    mdp, goal, dead = _layered(seed)
    st, rnd, level_of = _inputs(mdp)
    target = np.asarray(mdp.target, dtype=bool)
    zero = np.zeros(mdp.n_states, dtype=bool)
    zero[dead] = True
    free = target.copy() if upper else target | zero
    rng = np.random.default_rng(draw)
    x0 = np.where(target, 1.0, rng.random(mdp.n_states) * (0.3 if upper else 1.0))
    x0[dead] = 0.0
    failing = C._fails(st, rnd, x0, free, upper)
    assert failing.any()
    return mdp, goal, st, rnd, level_of, free, x0, failing


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("upper", [True, False])
def test_the_repair_pass_by_pass_is_the_repair_level_by_level(seed: int, upper: bool,
                                                             monkeypatch) -> None:
    """On levels that read only lower ones: the same bounds (bits), count and verdict
    pass by pass, level by level (``PASSES`` False) and state by state (``SPARSE_LEVEL``
    1); the result passes the whole check, and is a bound of the exact optimum (in
    fractions: above Pmax, below Pmin)."""
    mdp, goal, st, rnd, level_of, free, x0, failing = _far_candidate(seed, upper, seed)
    passes = []
    real = R.Repair._passes

    def counted(self, *args):
        passes.append(1)
        return real(self, *args)

    monkeypatch.setattr(R.Repair, "_passes", counted)
    runs = []
    for route in ("passes", "levels", "states"):
        if route == "levels":
            monkeypatch.setattr(R, "PASSES", False)
        if route == "states":
            monkeypatch.setattr(R, "SPARSE_LEVEL", 1)
        x = x0.copy()
        repair = R.Repair(st, rnd, free, level_of, None, upper)
        runs.append((repair.run(x, failing), x.tobytes(), repair.moved))
        if route == "passes":
            assert passes == [1]  # the route taken on these levels
    assert runs[0] == runs[1] == runs[2]
    ok, _, moved = runs[0]
    assert ok and moved > 0
    _assert_a_checked_bound(mdp, goal, st, rnd, np.frombuffer(runs[0][1]), free, upper)


def _assert_a_checked_bound(mdp, goal, st, rnd, x, free, upper: bool) -> None:
    """``x`` passes the whole check and bounds the exact optimum (fractions: above Pmax,
    below Pmin) on every state not ``free``."""
    assert not C._fails(st, rnd, x, free, upper).any()
    exact = _exact_optimum(mdp, goal, upper)
    live = np.flatnonzero(~free)
    if upper:
        assert all(Fraction(float(x[s])) >= exact[s] for s in live.tolist())
    else:
        assert all(Fraction(float(x[s])) <= exact[s] for s in live.tolist())


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("upper", [True, False])
def test_the_passes_in_one_compiled_call_are_the_numpy_passes(seed: int, upper: bool,
                                                              monkeypatch) -> None:
    """fixed-82: the repair's passes by the rounds' kernel (every live state one level,
    until none moves) give the NumPy passes' bounds (bits), count and verdict; the
    result passes the whole check and bounds the exact optimum (fractions)."""
    from mitld_lp.solvers import certify_compiled as CC
    from mitld_lp.util import kernel_loader

    pytest.importorskip("numba")
    mdp, goal, st, rnd, level_of, free, x0, failing = _far_candidate(seed, upper, 100 + seed)
    calls = []  # each call's answer (None: the NumPy passes ran)
    monkeypatch.setattr(R, "compiled_rounds",
                        lambda *a, _real=R.compiled_rounds: calls.append(_real(*a)) or calls[-1])
    runs = []
    for compiled in (True, False):
        monkeypatch.setattr(kernel_loader, "compiled_paid", lambda c=compiled: c)
        monkeypatch.setattr(CC, "_ROUNDS_WARM", [compiled])
        calls.clear()
        x = x0.copy()
        repair = R.Repair(st, rnd, free, level_of, None, upper)
        runs.append((repair.run(x, failing), x.tobytes(), repair.moved))
        assert [c is not None for c in calls] == [compiled]  # the passes' route
    assert runs[0] == runs[1]
    ok, raw, moved = runs[0]
    assert ok and moved > 0
    _assert_a_checked_bound(mdp, goal, st, rnd, np.frombuffer(raw), free, upper)
