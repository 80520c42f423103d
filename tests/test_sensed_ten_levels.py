"""The sensed build's last passes folded or left out (sensed-ten), against answers found
another way:

* the clock a new state keeps, the largest need of its hypotheses' times
  (:func:`mitld_lp.sensing.group_kernels.level_hypotheses` reads the need table as it
  makes the hypotheses; the pairs the table has not made yet looked up after it), against
  the need table's dict read in Python loops after the build;
* the controller's moves kept level by level (:class:`mitld_lp.sensing.moves.Moves`: no
  concatenation, no sort while building), against a dict of every choice's rows made in
  plain Python;
* the key table stored a column a key (:func:`mitld_lp.sensing.kernels.key_match`),
  against the numbering of a Python dict."""

from __future__ import annotations

import numpy as np
import pytest
from test_sensed_build import build, random_case
from test_sensed_pass import enumerate_match
from test_sensing_build import assert_same, reference

from mitld_lp.sensing import compiled, rows
from mitld_lp.sensing.keys import Keys
from mitld_lp.sensing.moves import Moves

pytest.importorskip("numba")


@pytest.mark.parametrize("seed", [3, 4, 5, 6, 7])
def test_needs_folded_as_the_table_gives_them(monkeypatch, seed: int) -> None:
    """Every level by the kernels: each observation's largest need is the largest of
    the need table's values (its dict, read after the build) over the observation's
    hypotheses, -1 without any; some levels find every need in the dense table (the
    fold used), and the product is the NumPy lines' to the bit."""
    from mitld_lp.sensing import group_kernels as gk

    seen: list[tuple] = []
    found_all: list[bool] = []
    grouped = compiled.grouped_hypotheses
    level_hypotheses = gk.level_hypotheses

    def spy(fb, found, obs, n_obs, tid, q, mass, s_seq, rep):
        out = grouped(fb, found, obs, n_obs, tid, q, mass, s_seq, rep)
        seen.append((fb, tid.copy(), rep.copy(), out[0].copy(), out[1].copy(),
                     out[9].copy(), n_obs))
        return out

    def kernel(*args):
        out = level_hypotheses(*args)
        found_all.append(len(out[10]) == 0)
        return out

    monkeypatch.setattr(compiled, "grouped_hypotheses", spy)
    monkeypatch.setattr(gk, "level_hypotheses", kernel)
    model = random_case(seed)
    with rows.running_kernels(True):
        fast = build(model, merge=True)
    assert seen and found_all and any(found_all)
    for fb, tid, rep, hfirst, hobs, most, n_obs in seen:
        table = fb.need_table.table
        want = [-1] * n_obs
        for h, o in zip(hfirst.tolist(), hobs.tolist(), strict=True):
            want[o] = max(want[o], table[(int(tid[h]), int(rep[o]))])
        assert most.tolist() == want
    monkeypatch.undo()
    with rows.running_kernels(False):
        plain = build(model, merge=True)
    assert fast.mdp.states == plain.mdp.states
    assert (fast.mdp.matrix != plain.mdp.matrix).nnz == 0


@pytest.mark.parametrize("seed", [3, 6])
def test_levels_kept_apart_equal_one_state_at_a_time(seed: int) -> None:
    """The moves kept level by level, the needs folded, the keys a column each: the
    product and its moves those of the build one state at a time."""
    model = random_case(seed, alarms=False)
    with rows.running_kernels(True):
        belief = build(model, merge=False)
    assert_same(belief, reference(model, belief))


def test_moves_by_level_as_plain_python() -> None:
    """Random levels of runs of rows: each choice's table is its rows, level by level
    and run by run in their order, made into a dict by hand; a choice without rows
    has an empty table; iteration and length follow the states' actions."""
    rng = np.random.default_rng(11)
    worlds = [("w", k) for k in range(5)]
    u_sets = [frozenset(), frozenset({"u"})]
    s_sets = [frozenset(), frozenset({"a"}), frozenset({"b"}), frozenset({"a", "b"})]
    records = ["target", "sink", "truncated"]
    acts = {0: ("l", "r"), 1: ("s",), 2: ("l", "r", "s"), 3: ("x", "y"), 4: ("z",)}
    state_world = np.array([0, 1, 2, -1, 3, 4, 2, 0, 1, 3, 4, 2], np.int64)
    per_state = [len(acts[w]) if w >= 0 else 1 for w in state_world.tolist()]
    row_groups = np.concatenate([[0], np.cumsum(per_state)]).astype(np.int64)
    n_choices = int(row_groups[-1])
    cuts = [0, 0, 7, 7, 16, n_choices]  # the levels' first choices (two empty levels)
    levels, every = [], []
    for a, b in zip(cuts[:-1], cuts[1:], strict=True):
        runs = []
        for _ in range(int(rng.integers(0, 3))):
            m = int(rng.integers(0, 12)) if b > a else 0
            run = (rng.integers(a, max(b, a + 1), m), rng.integers(0, 5, m),
                   rng.integers(0, 2, m), rng.integers(0, 4, m), rng.integers(-3, 12, m))
            # a run's choices are kept as rows of their level (from its first, ``a``)
            runs.append((np.asarray(run[0] - a, np.int64),
                         *(np.asarray(x, np.int64) for x in run[1:])))
            every.append(run)
        levels.append((a, tuple(runs)))
    moves = Moves(row_groups, state_world, acts, worlds, u_sets, s_sets, records, levels)
    want: dict[int, dict] = {c: {} for c in range(n_choices)}
    for run in every:  # levels and runs in order: each choice's rows in theirs
        for c, w, o, n, j in zip(*(x.tolist() for x in run), strict=True):
            want[c][(worlds[w], u_sets[o], s_sets[n])] = j if j >= 0 else records[-1 - j]
    keys = []
    for i, w in enumerate(state_world.tolist()):
        for k, action in enumerate(acts[w] if w >= 0 else ()):
            keys.append((i, action))
            assert moves[(i, action)] == want[int(row_groups[i]) + k]
            assert list(moves[(i, action)]) == list(want[int(row_groups[i]) + k])
    assert list(moves) == keys and len(moves) == len(keys)
    assert (3, "l") not in moves and moves.get((99, "l")) is None
    none = Moves(row_groups, state_world, acts, worlds, u_sets, s_sets, records, [])
    assert none[(0, "l")] == {} and len(none) == len(keys)  # no level: no rows


def test_keys_by_columns_as_a_dict() -> None:
    """Chunks of random keys (repeats within and across chunks) matched by the
    compiled table, stored a column a key: each row's state, or -1 - k for the k-th key
    new in its chunk, and each new key's first row, as test_sensed_pass's enumeration
    one row at a time gives them; the table grown and rehashed on the way."""
    rng = np.random.default_rng(5)
    keys, table = Keys(3), {}
    with rows.running_kernels(True):
        for size in (1, 40, 700, 3000, 5):
            cols = tuple(rng.integers(-3, 9, size) for _ in range(3))
            want = enumerate_match(table, cols)
            got = keys.match(cols)
            assert (got[0].tolist(), got[1].tolist()) == want[:2]
            states = len(table) + np.arange(len(want[2]), dtype=np.int64)
            keys.settle(states)
            table.update(zip(want[2], states.tolist(), strict=True))
    assert len(table) == keys.n


@pytest.mark.parametrize("seed", [0, 1])
def test_lex_order_as_sorted_tuples(seed: int) -> None:
    """The columns' order (one packed word, or several where their widths pass 62 bits)
    is Python's sort of the rows' tuples, ties in row order; no rows, no order."""
    from mitld_lp.sensing.rows import lex_order

    rng = np.random.default_rng(seed)
    n = 2000
    runs = np.sort(rng.integers(0, 60, n))  # a level's choices: sorted runs
    narrow = (runs, rng.integers(0, 2, n), rng.integers(-5, 400, n))
    wide = (rng.integers(0, 3, n), rng.integers(-2**61, 2**61, n),
            rng.integers(0, 2**40, n) * (rng.random(n) < 0.5))
    for cols in (narrow, wide):
        keys = list(zip(*(c.tolist() for c in cols), strict=True))
        assert lex_order(*cols).tolist() == sorted(range(n), key=lambda i: (keys[i], i))
    assert len(lex_order(np.zeros(0, np.int64), np.zeros(0, np.int64))) == 0
