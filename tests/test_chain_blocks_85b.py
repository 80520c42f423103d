"""layer-85b: a chain's blocks of the support layers by one compiled call
(:func:`mitld_lp.solvers.certify_blocks.compiled_chain_blocks`).

The compiled blocks are held against :func:`mitld_lp.solvers.graph.blocks_from`'s NumPy
calls array for array, and their pieces against constructions written here (the ids'
ranks by ``np.unique``, the order by ``np.argsort(kind="stable")``, sizes by counting),
on random ids with ties, gaps, levels past a 16-bit key and an empty chain; the
certificate's brackets, with the compiled blocks and without, against the brute
force's optimum in fractions (every deterministic policy solved in rational arithmetic,
``test_cert_small_exact``'s models with end components), both senses: the same bits."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
import scipy.sparse as sp
from test_cert_small_exact import exact_optimum, paid_kernels, small_model

from mitld_lp.solvers import certify as C
from mitld_lp.solvers import certify_blocks as CB
from mitld_lp.solvers import certify_chain as CH
from mitld_lp.solvers import certify_compiled as CC
from mitld_lp.solvers.graph import blocks_from

FIELDS = ("component", "level", "size", "by_level", "level_starts", "self_loop")
COMPILED_BLOCKS = CB.compiled_chain_blocks  # (the spies below replace it)


def _ids(seed: int, n: int, top: int, n_levels: int, level_top: int):
    """``n`` states' component ids below ``top`` (ties: several states a component) and
    a level for every id (``n_levels`` distinct values below ``level_top``, gaps)."""
    rng = np.random.default_rng(85_200 + seed)
    comp = rng.integers(0, top, size=n).astype(np.int32)
    present = rng.choice(level_top, size=n_levels, replace=False)
    level = present[rng.integers(0, n_levels, size=top)].astype(np.int32)
    return comp, level


CASES = [(0, 500, 3000, 7, 20), (1, 2000, 300, 40, 40), (2, 1000, 1000, 1, 1),
         (3, 3000, 5000, 300, 70_000), (4, 50, 60_000, 5, 65_537), (5, 1, 1, 1, 1),
         (6, 4000, 4000, 2, 65_536)]


@pytest.mark.parametrize(("seed", "n", "top", "n_levels", "level_top"), CASES)
def test_compiled_blocks_are_numpys(seed, n, top, n_levels, level_top, monkeypatch) -> None:
    paid_kernels(monkeypatch, True)
    comp, level = _ids(seed, n, top, n_levels, level_top)
    diag = np.random.default_rng(seed).random(n)
    got = CB.compiled_chain_blocks(comp, level, diag)
    assert got is not None
    want = blocks_from(comp, level, diag)
    for name in FIELDS:
        a, b = getattr(got, name), getattr(want, name)
        assert a.dtype == b.dtype and np.array_equal(a, b), name
        assert not a.flags.writeable, name
    # and against constructions of their own: ranks by np.unique, a stable argsort
    ids, dense = np.unique(comp, return_inverse=True)
    levels_present, dense_level = np.unique(level[ids], return_inverse=True)
    assert np.array_equal(got.component, dense)
    assert np.array_equal(got.level, dense_level)
    assert np.array_equal(got.size, np.array([np.sum(comp == c) for c in ids]))
    key = dense_level[dense]
    assert np.array_equal(got.by_level, np.argsort(key, kind="stable"))
    assert np.array_equal(got.level_starts, np.searchsorted(
        key[got.by_level], np.arange(levels_present.size + 1)))


def test_int64_ids_and_writable_levels_give_the_same_blocks(monkeypatch) -> None:
    paid_kernels(monkeypatch, True)
    comp, level = _ids(7, 800, 900, 12, 30)
    diag = np.zeros(800)
    a = CB.compiled_chain_blocks(comp.astype(np.int64), level.astype(np.int64), diag)
    ro = level.copy()
    ro.flags.writeable = False
    b = CB.compiled_chain_blocks(comp, ro, diag)
    for name in FIELDS:
        assert np.array_equal(getattr(a, name), getattr(b, name)), name


def test_the_numpy_calls_run_where_the_kernel_may_not(monkeypatch) -> None:
    comp, level = _ids(8, 100, 200, 4, 10)
    paid_kernels(monkeypatch, False)
    assert CB.compiled_chain_blocks(comp, level, np.zeros(100)) is None  # no load paid
    paid_kernels(monkeypatch, True)
    bad = comp.copy()
    bad[3] = -1
    assert CB.compiled_chain_blocks(bad, level, np.zeros(100)) is None  # a negative id
    assert CB.compiled_chain_blocks(comp, level[:150], np.zeros(100)) is None  # no level
    monkeypatch.setattr(CC, "COMPILED_CHECK_MIN_ROWS", 101)
    assert CB.compiled_chain_blocks(comp, level, np.zeros(100)) is None  # too few


def _optimal(mdp, exact, upper: bool):
    """The brute force's optimum of ``small_model``'s five states, an optimal policy,
    and the certificate's sense with the states it is told are 0 (and, for a minimum,
    1)."""
    v, policy = exact_optimum(mdp, exact, 5, upper)
    known = {"sense": "max" if upper else "min", "zero": np.array([p == 0 for p in v]),
             "one": None if upper else np.array([p == 1 for p in v])}
    return v, policy, known


@pytest.mark.parametrize("seed", range(8))
def test_brackets_hold_the_brute_force_optimum_with_the_compiled_blocks(
        seed, monkeypatch) -> None:
    """Five unknown states with end components; the certificate of the brute force's
    optimal policy holds its exact optimum, compared as fractions with no tolerance,
    with the chain's blocks compiled and by NumPy: the same bits."""
    paid_kernels(monkeypatch, True)
    mdp, exact = small_model(seed, 5)
    for upper in (True, False):
        v, policy, known = _optimal(mdp, exact, upper)
        got = set()
        for compiled in (True, False):
            monkeypatch.setattr(CH, "compiled_chain_blocks",
                                COMPILED_BLOCKS if compiled else (lambda *a: None))
            cert = C.certify(mdp, np.asarray(mdp.target), policy, **known)
            assert Fraction(cert.lower) <= v[0] <= Fraction(cert.upper), (upper, v[0], cert)
            got.add((cert.lower.hex(), cert.upper.hex(), cert.certified,
                     np.asarray(cert.values).tobytes()))
        assert len(got) == 1


def test_the_compiled_blocks_ran_on_the_brute_force_models(monkeypatch) -> None:
    """The models above reach the compiled blocks (a chain of more than one component
    with solved states) on some seed and sense: the test above is not vacuous."""
    paid_kernels(monkeypatch, True)
    fired = []

    def spy(*a):
        got = COMPILED_BLOCKS(*a)
        fired.append(got is not None)
        return got

    monkeypatch.setattr(CH, "compiled_chain_blocks", spy)
    for seed in range(8):
        mdp, exact = small_model(seed, 5)
        for upper in (True, False):
            _, policy, known = _optimal(mdp, exact, upper)
            C.certify(mdp, np.asarray(mdp.target), policy, **known)
    assert any(fired)


@pytest.mark.parametrize("distinct", [True, False])
def test_the_single_states_order_and_level_starts(distinct) -> None:
    """The single states' set-up (every component one state, or some not) against a
    count written here: the single states in the blocks' order, and per level the
    number of single states at lower levels."""
    rng = np.random.default_rng(85_300 + distinct)
    n = 600
    comp = rng.permutation(2 * n)[:n] if distinct else rng.integers(0, n // 2, size=n)
    level = rng.integers(0, 25, size=2 * n)
    blk = blocks_from(comp, level, np.zeros(n))
    sub = sp.csr_array((n, n))
    got = CH._Singles(sub, blk)
    lv = blk.level[blk.component]
    one = blk.size[blk.component] == 1
    want = [s for s in blk.by_level.tolist() if one[s]]
    assert got.order.tolist() == want and got.order.dtype == np.int64
    assert got.order.flags.writeable
    assert got.at.tolist() == [int(np.sum(one & (lv < k))) for k in range(blk.n_levels + 1)]
    assert (blk.n_components == n) == distinct
