"""The repair's large levels (:meth:`mitld_lp.solvers.certify_repair.Repair.run`): the
readers of the states it moved kept as flags level after level (``KEEP_READS``) and the
compiled rounds' scratch map kept through a run, against the search of every moved
state's readers again at each level, to the bit; the levels' stable order by a 16-bit
radix sort against NumPy's stable argsort on the keys as they come; and certificates
repaired through these routes holding the exact optimum (every deterministic policy
solved in fractions)."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
import scipy.sparse as sp
from test_cert_small_exact import exact_optimum, small_model

from mitld_lp.solvers import certify as C
from mitld_lp.solvers import certify_compiled as CC
from mitld_lp.solvers import certify_repair as R
from mitld_lp.solvers.certify_chain import support_layers
from mitld_lp.solvers.certify_repair_index import stable_order
from mitld_lp.solvers.rounding import rounding
from mitld_lp.testing import random_mdp
from mitld_lp.util import kernel_loader


@pytest.fixture
def hot(monkeypatch):
    """The compiled rounds' gate opened: their load counted as paid, their cache as
    warm (the arrays of a product's kinds: the kernel's one cached signature)."""
    monkeypatch.setattr(kernel_loader, "compiled_paid", lambda: True)
    monkeypatch.setattr(CC, "_ROUNDS_WARM", [True])


@pytest.fixture
def spied(monkeypatch):
    """The calls of the kept readers counted, with the moved states each was given."""
    kept: list[int] = []
    real = R.Repair._reading

    def reading(self, reads, moved):
        kept.append(int(moved.size))
        return real(self, reads, moved)

    monkeypatch.setattr(R.Repair, "_reading", reading)
    return kept


def _product_rows(mdp) -> tuple[C.Rows, object]:
    """``mdp``'s rows as the checks read them and their rounding, the indices in int32
    as a product's are (the kernel's one cached signature)."""
    m = sp.csr_array(mdp.matrix)
    st = C.Rows(sp.csr_array((m.data, m.indices.astype(np.int32),
                              m.indptr.astype(np.int32)), shape=m.shape),
                np.asarray(mdp.row_groups, dtype=np.int64))
    return st, rounding(st.matrix)


def _repair(mdp, x0, free, upper, *, keep: bool, compiled: bool, sparse: int,
            monkeypatch):
    """The repair of ``x0`` by one route: ``(closed, x, moves, scratch)``."""
    st, rnd = _product_rows(mdp)
    comp, level = support_layers(mdp)
    x = x0.copy()
    failing = C._fails(st, rnd, x, free, upper)
    with monkeypatch.context() as mp:
        mp.setattr(R, "KEEP_READS", keep)
        mp.setattr(R, "SPARSE_LEVEL", sparse)
        if not compiled:
            mp.setattr(R, "compiled_rounds", lambda *a: None)
        rep = R.Repair(st, rnd, free, np.asarray(level)[np.asarray(comp)], None, upper)
        ok = rep.run(x, failing)
    return ok, x, rep.moved, rep.at


def _start(mdp, seed: int, upper: bool) -> tuple[np.ndarray, np.ndarray]:
    """A candidate far from any fixed point: random bounds (the repair moves most
    states and, on the cyclic levels, gives up)."""
    free = np.asarray(mdp.target, dtype=bool)
    rng = np.random.default_rng(seed)
    x0 = np.where(free, 1.0, rng.random(mdp.n_states) * (0.5 if upper else 1.0))
    return x0, free


def _near(mdp, seed: int, upper: bool) -> tuple[np.ndarray, np.ndarray]:
    """A candidate the repair closes: the optimum by value iteration in floats (Pmax
    for the upper side, Pmin for the lower), moved by 1e-3 to the passing side, then
    a few states moved far to the failing side."""
    free = np.asarray(mdp.target, dtype=bool)
    m = sp.csr_array(mdp.matrix)
    groups = np.asarray(mdp.row_groups)
    has = np.diff(groups) > 0
    v = free.astype(float)
    for _ in range(3000):
        rows = m @ v
        best = (np.maximum if upper else np.minimum).reduceat(rows, groups[:-1][has])
        v = np.where(free, 1.0, 0.0)
        v[has & ~free] = best[~free[has]]
    x0 = np.clip(v + (1e-3 if upper else -1e-3), 0.0, 1.0)
    x0[free] = 1.0
    rng = np.random.default_rng(seed)
    hit = rng.choice(np.flatnonzero(~free & has), size=12, replace=False)
    x0[hit] = x0[hit] / 2 if upper else (1.0 + x0[hit]) / 2
    return x0, free


@pytest.mark.parametrize("seed", range(12))
@pytest.mark.parametrize("upper", [True, False])
@pytest.mark.parametrize("sparse", [1, 3])
def test_kept_readers_give_the_searched_readers_bounds(seed, upper, sparse, hot, spied,
                                                       monkeypatch) -> None:
    """Many levels with cycles (self-loops, states reading upstream ones), every level
    large (``sparse`` 1) or small and large mixed (3), from a random candidate (seeds
    0-5: the cyclic levels do not settle, the repair gives up part way) or from one
    near the optimum (6-11: some close): the kept flags give the bounds,
    the count of moves and the verdict of the search at each level, bit for bit, with
    the compiled rounds and with NumPy's; the kept route ran with moves to keep; the
    kernel's scratch is -1 everywhere after its levels; a closed repair passes the
    whole Bellman check."""
    mdp = random_mdp(300, seed=seed % 6, locality=6, self_loop_fraction=0.3,
                     max_choices=3)
    x0, free = (_start if seed < 6 else _near)(mdp, seed, upper)
    got = {}
    ran = {}
    for keep in (False, True):
        for compiled in (False, True):
            spied.clear()
            got[keep, compiled] = _repair(mdp, x0, free, upper, keep=keep,
                                          compiled=compiled, sparse=sparse,
                                          monkeypatch=monkeypatch)
            assert keep or not spied  # the flags kept on that route alone
            ran[keep, compiled] = sum(spied)
            scratch = got[keep, compiled][3]
            assert scratch is None or bool(np.all(scratch == -1))
            if compiled and sparse == 1:
                assert scratch is not None  # the kernel ran, with the kept scratch
    want = got[False, False]
    assert want[2] > 0
    # moves kept for a later large level (the compiled rounds keep them where a
    # level settles; a first level still moving gives up before)
    assert ran[True, False] > 0 and (ran[True, True] > 0 or not want[0])
    for key, (ok, x, moves, _) in got.items():
        assert ok == want[0] and moves == want[2], key
        assert x.tobytes() == want[1].tobytes(), key
    if want[0]:
        st = C.Rows(sp.csr_array(mdp.matrix), np.asarray(mdp.row_groups, dtype=np.int64))
        assert not C._fails(st, rounding(st.matrix), want[1], free, upper).any()


@pytest.mark.parametrize("upper", [True, False])
def test_a_level_still_moving_gives_up_alike(upper, hot, monkeypatch) -> None:
    """With one round a level, the first level still moving is refused by every route,
    with the same bounds moved up to there."""
    mdp = random_mdp(300, seed=7, locality=6, self_loop_fraction=0.3, max_choices=3)
    x0, free = _start(mdp, 7, upper)
    monkeypatch.setattr(R, "ROUNDS", 1)
    got = [_repair(mdp, x0, free, upper, keep=keep, compiled=compiled, sparse=1,
                   monkeypatch=monkeypatch)
           for keep in (False, True) for compiled in (False, True)]
    assert not any(g[0] for g in got)
    assert len({(g[1].tobytes(), g[2]) for g in got}) == 1


def test_the_scratch_is_read_as_a_fresh_map_would_be(hot) -> None:
    """The compiled rounds given a scratch that is -1 everywhere and left so, level
    after level, move what they move with a map made a call; a scratch of another
    kind is refused by name."""
    mdp = random_mdp(200, seed=3, locality=5, self_loop_fraction=0.3, max_choices=3)
    st, rnd = _product_rows(mdp)
    readers = R.readers_by_column(st)
    x0, free = _start(mdp, 3, True)
    groups = np.asarray(mdp.row_groups)
    live = np.flatnonzero(~free & (np.diff(groups) > 0))
    halves = np.array_split(live, 2)
    runs = []
    for shared in (False, True):
        x = x0.copy()
        moved = np.zeros(x.size, dtype=bool)
        at = np.full(x.size, -1, dtype=np.int64) if shared else None
        for mine in halves:
            todo = np.ones(mine.size, dtype=bool)
            got = CC.compiled_rounds(st, rnd, x, mine, todo, True, readers, moved, 64,
                                     at, shared)
            assert got is not None
            runs.append(got)
            if shared:
                assert bool(np.all(at == -1))
        runs.append((x.tobytes(), moved.tobytes()))
    assert runs[:3] == runs[3:]
    with pytest.raises(ValueError, match="at must be an int64"):
        CC.compiled_rounds(st, rnd, x0.copy(), halves[0], np.ones(halves[0].size, bool),
                           True, readers, np.zeros(x0.size, bool), 64,
                           np.full(x0.size, -1, dtype=np.int32))


@pytest.mark.parametrize("seed", range(5))
def test_stable_order_is_numpys_stable_argsort(seed) -> None:
    """The radix route (levels within 16 bits) and the fallback (wider or negative
    keys) give the permutation of ``np.argsort(kind="stable")`` on the keys as they
    come, ties in their order."""
    rng = np.random.default_rng(seed)
    for high in (1, 7, 300, 65_535, 65_536, 1 << 40):
        lv = rng.integers(0, high + 1, size=5_000, dtype=np.int64)
        assert np.array_equal(stable_order(lv), np.argsort(lv, kind="stable"))
    lv = rng.integers(-3, 40, size=2_000, dtype=np.int64)
    assert np.array_equal(stable_order(lv), np.argsort(lv, kind="stable"))
    assert stable_order(np.zeros(0, dtype=np.int64)).size == 0


@pytest.mark.parametrize("seed", range(8))
def test_brackets_hold_the_brute_force_optimum_through_the_kept_readers(
        seed, spied, monkeypatch) -> None:
    """Small MDPs with end components and rare values, max and min: with every level
    read as a large one (the compiled paths as this process has them), the
    certificate's bracket holds
    the exact optimum (every deterministic policy solved in fractions), and its bits
    are those with the readers searched at each level."""
    n = 5
    mdp, exact = small_model(seed, n)
    target = np.asarray(mdp.target)
    monkeypatch.setattr(R, "SPARSE_LEVEL", 1)
    for upper in (True, False):
        v, policy = exact_optimum(mdp, exact, n, upper)
        sets = {"zero": np.array([p == 0 for p in v]),
                "one": None if upper else np.array([p == 1 for p in v])}
        bits = set()
        for keep in (True, False):
            monkeypatch.setattr(R, "KEEP_READS", keep)
            cert = C.certify(mdp, target, policy, sense="max" if upper else "min", **sets)
            assert cert.certified, [c.detail for c in cert.checks]
            assert Fraction(cert.lower) <= v[0] <= Fraction(cert.upper)
            bits.add((cert.lower.hex(), cert.upper.hex(), np.asarray(cert.values).tobytes()))
        assert len(bits) == 1
