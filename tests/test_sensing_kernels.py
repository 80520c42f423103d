"""The compiled kernels of the sensed build (:mod:`mitld_lp.sensing.kernels`, run by
:mod:`mitld_lp.sensing.rows` once loaded) against the NumPy lines they replace and
against values found here another way: on random small rows the same arrays to the bit,
groups numbered as sorting the distinct rows by hand numbers them, sums as math.fsum;
and whole builds with the kernels and without them the same product to the bit, and
the same as one state at a time (tests/test_sensing_build.py's reference)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_sensing_build import CASES, assert_same, reference, with_sensors

from mitld_lp.automata.translate import to_dta
from mitld_lp.sensing import Sensor, rows
from mitld_lp.sensing.belief import belief_product

pytest.importorskip("numba")


def both(f, *args):
    """``f(*args)`` with the NumPy lines and with the kernels (fresh copies of the
    arguments each time: some are written)."""
    out = []
    for on in (False, True):
        with rows.running_kernels(on) as running:
            assert running == on
            out.append(f(*(a.copy() if isinstance(a, np.ndarray) else a for a in args)))
    return out


def same(x, y) -> None:
    if isinstance(x, tuple | list):
        assert len(x) == len(y)
        for a, b in zip(x, y, strict=True):
            same(a, b)
    else:
        assert x.dtype == y.dtype and np.array_equal(x, y)


def by_hand(cols: tuple[np.ndarray, ...]) -> list[int]:
    """Each row's group: its place among the distinct rows sorted."""
    keyed = list(zip(*(c.tolist() for c in cols), strict=True))
    place = {k: i for i, k in enumerate(sorted(set(keyed)))}
    return [place[k] for k in keyed]


@pytest.mark.parametrize("seed", range(8))
def test_groups_as_sorting_by_hand(seed: int) -> None:
    """Dense words, packed words, a hash column of its own (a full 64-bit range),
    negative values: the groups numbered in the rows' lexicographic order, one row of
    each group carrying its values, the same arrays either way."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 400))
    cols = [rng.integers(-3, 1 + int(rng.integers(1, 40)), n) for _ in range(seed % 4 + 1)]
    if seed % 2:
        cols.append(rng.integers(-(1 << 63), (1 << 63) - 1, n, dtype=np.int64)
                    % np.int64(1 + seed) if seed % 4 == 1 else
                    rng.integers(-(1 << 63), (1 << 63) - 1, n, dtype=np.int64))
        cols.append(rng.integers(0, 1 << 40, n))
    cols = tuple(cols)
    plain, fast = both(rows.groups, *cols)
    same(plain, fast)
    ids, first = fast
    assert ids.tolist() == by_hand(cols)
    for c in cols:
        assert np.array_equal(c[first][ids], c)  # each group's row carries its values


def scattered(op: str, out: np.ndarray, idx: np.ndarray, vals: np.ndarray) -> np.ndarray:
    rows.scatter(op, out, idx, vals)
    return out


def test_sums_spread_scatter_and_lookup() -> None:
    rng = np.random.default_rng(11)
    for trial in range(20):
        counts = rng.integers(1, 9, 200)
        ids = np.repeat(np.arange(200), counts)
        v = rng.random(len(ids)) * 10.0 ** rng.integers(-18, 1, len(ids))
        if trial % 2:
            v = 0.5 ** rng.integers(0, 60, len(ids)) * rng.choice([0.3, 1 / 3], len(ids))
        plain, fast = both(rows.fsum_by, ids, v, 200)
        same(plain, fast)
        starts = np.cumsum(counts) - counts
        assert fast.tolist() == [math.fsum(v[a:a + k].tolist())
                                 for a, k in zip(starts, counts, strict=True)]
        c = rng.integers(0, 5, 50)
        plain, fast = both(rows.spread, c)
        same(plain, fast)
        assert fast[0].tolist() == [p for p, k in enumerate(c.tolist()) for _ in range(k)]
        idx, vals = rng.integers(0, 30, 500), rng.integers(-99, 99, 500)
        for op, start, pick in (("max", -1000, max), ("min", 1000, min)):
            outs = both(scattered, op, np.full(30, start), idx, vals)
            same(*outs)
            assert outs[1].tolist() == [pick([start] + vals[idx == k].tolist())
                                        for k in range(30)]
        h = rng.integers(0, 1 << 63, 500, dtype=np.int64).astype(np.uint64) * np.uint64(3)
        outs = both(scattered, "add", np.zeros(30, np.uint64), idx, h)
        same(*outs)
        assert outs[1].tolist() == [sum(h[idx == k].tolist()) % (1 << 64) for k in range(30)]

    def look(a, b):
        table = rows.Lookup(lambda x, y: (5 * x + y) % 7 - 1)
        return [table(a[:k], b[:k]) for k in (10, 200, 400)]

    a, b = rng.integers(0, 60, 400), rng.integers(0, 9, 400)
    plain, fast = both(look, a, b)
    same(plain, fast)
    assert fast[-1].tolist() == ((5 * a + b) % 7 - 1).tolist()


def build(model, merge: bool):
    return belief_product(model.game, to_dta(model.spec), model.distributions,
                          dict(model.sensors), model.epsilon, max_states=10**6,
                          late_reports=False, merge=merge)


FA = {"false alarms": lambda: with_sensors("bus_grid.toml", {"b2": Sensor(0.8,
                                                                   false_alarm=0.1)}, 0.2)}


@pytest.mark.parametrize("case", ["two cameras", "a delay", "a safety part", "one camera",
                                  "false alarms"])
def test_compiled_build_is_the_numpy_build(case: str) -> None:
    """The product with the kernels and without them: the same matrix, choices and
    states to the bit (merged: the times shifted), and, unmerged, the same as one state
    at a time."""
    model = {**CASES, **FA}[case]()
    for merge in (True, False):
        plain, fast = both(build, model, merge)
        for x in ("matrix", "row_groups", "choice_actions"):
            got, want = getattr(fast.mdp, x), getattr(plain.mdp, x)
            if x == "matrix":
                same((got.data, got.indices, got.indptr), (want.data, want.indices,
                                                          want.indptr))
            else:
                same(got, want)
        assert fast.mdp.states == plain.mdp.states
        if not merge and case != "false alarms":
            with rows.running_kernels(True):
                assert_same(fast, reference(model, fast))


@pytest.mark.parametrize("small", [False, True])
def test_kernel_rows_run_or_give_way(monkeypatch, small: bool) -> None:
    """The hypotheses' rows come from the kernel (each level's, a table held dense), or,
    where the automaton's tables are too large to hold dense, from the NumPy lines: the
    same product either way."""
    from mitld_lp.sensing import compiled

    answers: list[bool] = []
    kernel_rows = compiled.hypothesis_rows

    def spy(*args):
        out = kernel_rows(*args)
        answers.append(out is not None)
        return out

    monkeypatch.setattr(compiled, "hypothesis_rows", spy)
    if small:
        monkeypatch.setattr(rows, "DENSE", 1 << 6)
    model = FA["false alarms"]()
    plain, fast = both(build, model, True)
    same((fast.mdp.matrix.data, fast.mdp.matrix.indices), (plain.mdp.matrix.data,
                                                           plain.mdp.matrix.indices))
    assert fast.mdp.states == plain.mdp.states
    assert answers and all(answers) != small  # small: some levels gave way
