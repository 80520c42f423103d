"""The information states kept as arrays (:mod:`mitld_lp.sensing.keys`): the compiled
table of keys against a dict numbering written here, its move from a dict mid-build,
the columns against plain lists, and random small builds with the compiled table and
with the dict of the NumPy lines the same product to the bit (unmerged, also the same
as one state at a time: tests/test_sensing_build.py's reference)."""

from __future__ import annotations

import numpy as np
import pytest
from test_sensing_build import assert_same, reference, with_sensors
from test_sensing_kernels import both, build, same

from mitld_lp.sensing import Sensor, rows
from mitld_lp.sensing.keys import Columns, Keys

pytest.importorskip("numba")


def numbered(batches: list[list[tuple[int, ...]]]) -> list[list[int]]:
    """Each key's answer, by hand: its state if stored, else ``-1 - k`` for the k-th key
    new in its batch; a batch's new keys then stored as states 100, 101, ..."""
    stored: dict[tuple[int, ...], int] = {}
    out, next_state = [], 100
    for batch in batches:
        new: dict[tuple[int, ...], int] = {}  # in the order first met
        answer = []
        for key in batch:
            if key in stored:
                answer.append(stored[key])
            else:
                answer.append(-1 - new.setdefault(key, len(new)))
        for key in new:
            stored[key] = next_state
            next_state += 1
        out.append(answer)
    return out


@pytest.mark.parametrize("seed", range(6))
def test_keys_number_as_a_dict_does(seed: int) -> None:
    """Random batches of keys (repeats within and across batches, a full 64-bit hash
    column): the compiled table, the dict, and the dict moved into the compiled table
    half-way answer every batch as the numbering by hand, and give the new keys' first
    rows."""
    rng = np.random.default_rng(seed)
    batches = []
    for _ in range(8):
        m = int(rng.integers(0, 3000))
        cols = [rng.integers(0, 1 + int(rng.integers(1, 30)), m) for _ in range(5)]
        cols.append(rng.integers(-(1 << 63), (1 << 63) - 1, m, dtype=np.int64) % 7
                    * np.int64(0x1234567890ABCDE))
        batches.append(list(zip(*(c.tolist() for c in cols), strict=True)))
    want = numbered(batches)
    for switch in (0, 4, 9):  # compiled throughout, from the fifth batch, never
        keys, next_state = Keys(6), 100
        for k, batch in enumerate(batches):
            cols = tuple(np.array([key[j] for key in batch], np.int64) for j in range(6))
            with rows.running_kernels(k >= switch):
                target, reps = keys.match(cols)
                assert target.tolist() == want[k]
                first: dict[int, int] = {}  # each new key's first row, by hand
                for r, t in enumerate(want[k]):
                    if t < 0:
                        first.setdefault(-1 - t, r)
                assert reps.tolist() == [first[f] for f in range(len(first))]
                keys.settle(next_state + np.arange(len(reps), dtype=np.int64))
                next_state += len(reps)


def test_columns_as_lists() -> None:
    """Rows appended and extended past the first allocation read back as lists do."""
    rng = np.random.default_rng(1)
    cols, lists = Columns(3), [[], [], []]
    for _ in range(40):
        if rng.random() < 0.3:
            row = tuple(int(x) for x in rng.integers(-5, 5, 3))
            cols.append(row)
            for c, v in zip(lists, row, strict=True):
                c.append(v)
        else:
            m = int(rng.integers(0, 200))
            block = tuple(rng.integers(0, 1 << 40, m) for _ in range(3))
            cols.extend(block)
            for c, v in zip(lists, block, strict=True):
                c.extend(v.tolist())
    for j in range(3):
        assert cols.col(j).tolist() == lists[j]
    a, b = 17, len(lists[0]) - 5
    assert [c.tolist() for c in cols.rows(a, b)] == [c[a:b] for c in lists]


@pytest.mark.parametrize("seed", range(4))
def test_random_builds_equal_the_dict_build(seed: int) -> None:
    """Random cameras (detection, false alarms, a delay), a random epsilon: the product
    with the compiled table of keys and with the dict the same to the bit, merged and
    not; unmerged without false alarms, also the same as one state at a time."""
    rng = np.random.default_rng(seed)
    events = ["b1", "b2"][:1 + seed % 2]
    sensors = {}
    for e in events:
        fa = {"false_alarm": round(float(rng.uniform(0.05, 0.2)), 2)} if seed == 3 else {}
        delay = {"delay": 1} if seed == 2 else {}
        sensors[e] = Sensor(round(float(rng.uniform(0.4, 0.9)), 2), **fa, **delay)
    model = with_sensors("bus_grid.toml", sensors, round(float(rng.uniform(0.2, 0.35)), 2))
    for merge in (True, False):
        plain, fast = both(build, model, merge)
        m, w = fast.mdp.matrix, plain.mdp.matrix
        same((m.data, m.indices, m.indptr), (w.data, w.indices, w.indptr))
        same((fast.mdp.row_groups, fast.mdp.choice_actions),
             (plain.mdp.row_groups, plain.mdp.choice_actions))
        assert fast.mdp.states == plain.mdp.states
        if not merge and seed != 3:
            with rows.running_kernels(True):
                assert_same(fast, reference(model, fast))


def stored(seed: int):
    """States with random hypotheses stored, and groups that meet them again: each
    group's state, hypotheses count, rows' groups, codes and weights."""
    from types import SimpleNamespace

    rng = np.random.default_rng(seed)
    n = 50
    count = rng.integers(1, 6, n)
    starts = np.cumsum(count) - count
    cols = Columns(6)
    cols.extend(tuple(np.zeros(n, np.int64) for _ in range(4)) + (starts, count))
    codes = rng.integers(0, 1000, int(count.sum()))
    weights = rng.random(len(codes))
    fb = SimpleNamespace(cols=cols, hyp_code=codes, hyp_weight=weights,
                         states=lambda: [f"state {i}" for i in range(n)])
    target = rng.permutation(n)[:20]  # the groups' states, each group met once
    g_count = count[target]
    hobs = np.repeat(np.arange(20), g_count)
    rows_ = np.concatenate([np.arange(starts[t], starts[t] + count[t]) for t in target])
    return fb, target, g_count, hobs, codes[rows_].copy(), weights[rows_].copy()


@pytest.mark.parametrize("wrong", [None, "code", "weight"])
def test_revisits_checked_hypothesis_by_hypothesis(wrong: str | None) -> None:
    """A state met again with its own hypotheses passes; one hypothesis's code changed
    is a collision, one weight moved past WEIGHT_TOL names the state and the gap: the
    kernel and the NumPy lines alike."""
    from mitld_lp.sensing.frontier import FrontierBuilder
    from mitld_lp.sensing.info import WEIGHT_TOL

    for on in (False, True):
        fb, target, g_count, hobs, hcode, weight = stored(7)
        k = len(hcode) // 2
        if wrong == "code":
            hcode[k] += 1
        elif wrong == "weight":
            weight[k] += 3 * WEIGHT_TOL
        with rows.running_kernels(on):
            if wrong is None:
                FrontierBuilder.verify(fb, target, g_count, hobs, hcode, weight)
                continue
            with pytest.raises(RuntimeError) as err:
                FrontierBuilder.verify(fb, target, g_count, hobs, hcode, weight)
        if wrong == "code":
            assert "hash collision" in str(err.value)
        else:
            assert f"state {target[hobs[k]]}" in str(err.value)
            assert f"{3 * WEIGHT_TOL:.3g}" in str(err.value)
