"""The compiled chain solve in strong-component order (mitld_lp.solvers.topo_chain,
topo_kernels) against a dense solve of the same linear system built here, and the
policy jump's brackets with it against the exact optimum."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse import csgraph

from mitld_lp.solvers import policy_jump as pj
from mitld_lp.solvers import topo_chain

pytest.importorskip("numba")


def _rings_chain(seed: int, k: int = 400) -> sp.csr_array:
    """Rings of 1 to 12 states (each a cycle), each state also moving to a state of
    an earlier ring and keeping some mass back (a transient chain)."""
    rng = np.random.default_rng(seed)
    rows, cols, vals = [], [], []
    first = 0
    while first < k:
        size = min(int(rng.integers(1, 13)), k - first)
        for i in range(first, first + size):
            stay = 0.3 * rng.random()
            if size > 1:  # the next state of the ring
                rows.append(i)
                cols.append(first + (i - first + 1) % size)
                vals.append(0.4)
            if first:
                rows.append(i)
                cols.append(int(rng.integers(0, first)))
                vals.append(0.25)
            if rng.random() < 0.5:  # a self-loop
                rows.append(i)
                cols.append(i)
                vals.append(stay)
            if size > 2 and rng.random() < 0.3:  # a chord inside the ring
                rows.append(i)
                cols.append(first + int(rng.integers(0, size)))
                vals.append(0.05)
        first += size
    return sp.csr_array((vals, (rows, cols)), shape=(k, k))


def _labels(chain: sp.csr_array) -> tuple[int, np.ndarray]:
    return csgraph.connected_components(chain, directed=True, connection="strong")


@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize("shuffle", [False, True])
def test_compiled_solve_matches_a_dense_solve(seed, shuffle):
    chain = _rings_chain(seed)
    if shuffle:  # the states in another order: the components not contiguous
        perm = np.random.default_rng(seed + 100).permutation(chain.shape[0])
        chain = sp.csr_array(chain[perm][:, perm])
    n, label = _labels(chain)
    assert n > 50 and np.bincount(label).max() > 1
    lu = topo_chain.factor(chain, label, n, force=True)
    assert isinstance(lu, topo_chain.CompiledTopoLU)
    b = np.random.default_rng(seed).random((chain.shape[0], 2))
    want = np.linalg.solve(np.eye(chain.shape[0]) - chain.toarray(), b)
    np.testing.assert_allclose(lu.solve(b), want, rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(lu.solve(b[:, 1]), want[:, 1], rtol=1e-12, atol=1e-13)


def test_labels_in_the_other_direction_are_turned_round():
    """Labels numbering the components upstream first: the kernel refuses that order
    and the other one is taken."""
    chain = _rings_chain(7)
    n, label = _labels(chain)
    lu = topo_chain.factor(chain, n - 1 - label, n, force=True)
    b = np.ones((chain.shape[0], 1))
    want = np.linalg.solve(np.eye(chain.shape[0]) - chain.toarray(), b)
    np.testing.assert_allclose(lu.solve(b), want, rtol=1e-12)


def test_hand_solved_chains():
    """x = 1 + Q x by hand: a line of halves (x = 1, 1.5, 1.75, 1.875 from its end), a
    ring of two with a half each way and a quarter out (x = 1 / (1 - 3/4) = 4)."""
    line = sp.csr_array(np.eye(4, k=1) * 0.5)
    n, label = _labels(line)
    x = topo_chain.factor(line, label, n, force=True).solve(np.ones(4))
    assert np.allclose(x, [1.875, 1.75, 1.5, 1.0])
    ring = sp.csr_array(np.array([[0.25, 0.5], [0.5, 0.25]]))
    n, label = _labels(ring)
    x = topo_chain.factor(ring, label, n, force=True).solve(np.ones(2))
    assert np.allclose(x, [4.0, 4.0])


def test_a_closed_ring_is_refused():
    """A ring that keeps all its mass (not transient: I - Q singular) gives no
    factors: a pivot reaches 0 and the caller falls back."""
    ring = sp.csr_array(np.roll(np.eye(3), 1, axis=1))
    n, label = _labels(ring)
    assert topo_chain.factor(ring, label, n, force=True) is None


def test_off_or_unloaded_gives_none(monkeypatch):
    chain = _rings_chain(1)
    n, label = _labels(chain)
    monkeypatch.setattr(topo_chain, "COMPILED", False)
    assert topo_chain.factor(chain, label, n, force=True) is None


@pytest.mark.parametrize("compiled", [False, True])
def test_jump_chain_factor_route(compiled, monkeypatch):
    """chain_factor takes the compiled route where allowed (a load paid, the cache
    warm: forced here), SciPy's TopoLU where not; both solve the chain."""
    monkeypatch.setattr(pj, "DENSE_LU_STATES", 0)
    monkeypatch.setattr(topo_chain, "COMPILED", compiled)
    if compiled:
        run = topo_chain.kernels(force=True)
        monkeypatch.setattr(topo_chain, "kernels", lambda force=False: run)
    chain = _rings_chain(3)
    lu = pj.chain_factor(chain)
    assert isinstance(lu, topo_chain.CompiledTopoLU if compiled else pj.TopoLU)
    b = np.arange(chain.shape[0], dtype=float)[:, None]
    want = np.linalg.solve(np.eye(chain.shape[0]) - chain.toarray(), b)
    np.testing.assert_allclose(lu.solve(b), want, rtol=1e-12)


def test_fraction_check_of_a_small_solve():
    """A 3-state chain solved in fractions by hand-written elimination: the ring
    0 -> 1 -> 0 with 1/2 each, state 1 also 1/4 to state 2, state 2 a self-loop of
    1/2: x2 = 1 / (1/2) = 2, x1 = 1 + x0/2 + x2/4, x0 = 1 + x1/2."""
    q = np.array([[0.0, 0.5, 0.0], [0.5, 0.0, 0.25], [0.0, 0.0, 0.5]])
    x2 = Fraction(2)
    # x1 = 1 + (1 + x1/2)/2 + x2/4  ->  x1 (1 - 1/4) = 1 + 1/2 + 1/2
    x1 = Fraction(2) / Fraction(3, 4)
    x0 = 1 + x1 / 2
    chain = sp.csr_array(q)
    n, label = _labels(chain)
    got = topo_chain.factor(chain, label, n, force=True).solve(np.ones(3))
    assert np.allclose(got, [float(x0), float(x1), float(x2)], rtol=1e-15)


def test_compile_kernels_fills_a_cold_cache(tmp_path):
    """``mitld-lp warm``'s step: on an empty cache directory both kernels are compiled
    (True) and found by the gate's look-up after; a second call has nothing to do."""
    import subprocess
    import sys

    code = ("from mitld_lp.solvers import topo_chain as t; from mitld_lp.util import "
            "kernel_loader as k; m = 'mitld_lp.solvers.topo_kernels'; "
            "before = [k.module_cached(m, n) for n in t.KERNELS]; "
            "print(before, t.compile_kernels(), t.compile_kernels(), "
            "[k.module_cached(m, n) for n in t.KERNELS])")
    env = dict(__import__("os").environ, NUMBA_CACHE_DIR=str(tmp_path))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env=env, check=True, cwd=__import__("pathlib").Path(
                             __file__).resolve().parents[1]).stdout
    assert out.split() == ["[False,", "False]", "True", "False", "[True,", "True]"]


def _big_ring(k: int = 600, seed: int = 0) -> sp.csr_array:
    """One strong component of ``k`` states: a ring (half a state's mass to the next)
    with random chords (a tenth each, two a state) that fill its factors, and a tenth
    lost a step."""
    rng = np.random.default_rng(seed)
    rows, cols, vals = [], [], []
    for i in range(k):
        rows += [i, i, i]
        cols += [(i + 1) % k, int(rng.integers(0, k)), int(rng.integers(0, k))]
        vals += [0.5, 0.1, 0.1]
    chain = sp.csr_array((vals, (rows, cols)), shape=(k, k))
    chain.sum_duplicates()
    return chain


@pytest.mark.parametrize("room", [4, 0])
def test_a_large_component_and_a_short_first_room(room, monkeypatch):
    """A component of 600 states (past SciPy's route's 256) solved compiled; with no
    room per entry the first factorisation runs out of room and is made again with
    all of it: the same answer as a dense solve either way."""
    monkeypatch.setattr(topo_chain, "ROOM_PER_ENTRY", room)
    chain = _big_ring()
    n, label = _labels(chain)
    assert n == 1
    lu = topo_chain.factor(chain, label, n, force=True)
    b = np.random.default_rng(1).random((600, 2))
    want = np.linalg.solve(np.eye(600) - chain.toarray(), b)
    np.testing.assert_allclose(lu.solve(b), want, rtol=1e-12)


def test_too_much_fill_for_the_cap_gives_none(monkeypatch):
    monkeypatch.setattr(topo_chain, "ROOM_PER_ENTRY", 0)
    monkeypatch.setattr(topo_chain, "MAX_ROOM", 1000)
    chain = _big_ring()
    n, label = _labels(chain)
    assert topo_chain.factor(chain, label, n, force=True) is None


def test_chain_factor_takes_large_components_compiled(monkeypatch):
    """policy_jump.chain_factor: a 600-state component goes to the compiled route
    where it is allowed, and to the whole chain's SuperLU where it is not."""
    chain = _big_ring()
    run = topo_chain.kernels(force=True)
    monkeypatch.setattr(topo_chain, "kernels", lambda force=False: run)
    assert isinstance(pj.chain_factor(chain), topo_chain.CompiledTopoLU)
    monkeypatch.setattr(topo_chain, "MAX_COMPONENT", 512)
    assert not isinstance(pj.chain_factor(chain), (topo_chain.CompiledTopoLU, pj.TopoLU))
