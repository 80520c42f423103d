"""cert-86b: the certificate reuses the LP stage's walk of the greedy chain where its own
chain is that chain, or that chain with single states upstream of it
(:func:`mitld_lp.solvers.chain_levels.walk_of`, :class:`~mitld_lp.solvers.chain_levels.
Extended`): the solves equal a new walk's to the bit on random chains, a chain that is
not such an extension is refused, and the certificate's bracket holds SciPy
``linprog``'s optimum with the reuse on and off."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from test_greedy_block import _linprog_min, linprog_max, tied_mdp

from mitld_lp.solvers import certify_chain, chain_levels, greedy_block, lp_blocks
from mitld_lp.solvers import chain_levels as cl
from mitld_lp.solvers.certify import certify
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.iteration import interval_iteration
from mitld_lp.solvers.lp import solve_lp


def _inner_chain(n: int, rng: np.random.Generator) -> list[list[tuple[int, float]]]:
    """Rows of a transient chain on ``n`` states: cycles of 3 to 6 states (each state
    0.4 to the next of its cycle), and from most states a few entries to lower states,
    some with a self-loop."""
    rows: list[list[tuple[int, float]]] = []
    start = 0
    while start < n:
        size = int(rng.integers(1, 7)) if start else 4
        size = min(size, n - start)
        for k in range(size):
            s = start + k
            entries: dict[int, float] = {}
            if size > 1:
                entries[start + (k + 1) % size] = 0.4
            if rng.random() < 0.2:
                entries[s] = entries.get(s, 0.0) + 0.1
            for t in rng.integers(0, max(start, 1), size=int(rng.integers(0, 3))):
                if start:
                    entries[int(t)] = entries.get(int(t), 0.0) + float(rng.uniform(0.01, 0.15))
            rows.append(sorted(entries.items()))
        start += size
    return rows


def _csr(rows: list[list[tuple[int, float]]], n: int) -> sp.csr_array:
    indptr = np.concatenate([[0], np.cumsum([len(r) for r in rows])]).astype(np.int32)
    cols = np.array([c for r in rows for c, _ in r], dtype=np.int32)
    vals = np.array([v for r in rows for _, v in r], dtype=np.float64)
    return sp.csr_array((vals, cols, indptr), shape=(n, n))


def _extended(seed: int, n: int, extra: int, cyclic_extra: bool = False,
              ) -> tuple[sp.csr_array, np.ndarray, sp.csr_array, np.ndarray]:
    """The greedy chain ``g`` (its states ``g_states``, a sorted sample of product
    states) and a certificate chain ``c`` on those and ``extra`` more states (``c_states``,
    all sorted), ``c``'s rows at ``g``'s states ``g``'s own entry for entry, its other
    states single (``cyclic_extra``: two of them in one cycle) with entries into any
    state of ``g`` and into the other extra states below them (their self-loops too)."""
    rng = np.random.default_rng(seed)
    g_rows = _inner_chain(n, rng)
    product = np.sort(rng.choice(10 * (n + extra), size=n + extra, replace=False))
    is_extra = np.zeros(n + extra, dtype=bool)
    is_extra[rng.choice(n + extra, size=extra, replace=False)] = True
    inside = np.flatnonzero(~is_extra)
    upper = rng.permutation(np.flatnonzero(is_extra))  # their order: downstream first
    rows: list[list[tuple[int, float]]] = [[] for _ in range(n + extra)]
    for j, r in enumerate(g_rows):
        rows[inside[j]] = [(int(inside[t]), v) for t, v in r]
    for k, s in enumerate(upper.tolist()):
        entries: dict[int, float] = {}
        for t in rng.integers(0, n, size=int(rng.integers(1, 4))):
            entries[int(inside[t])] = entries.get(int(inside[t]), 0.0) + 0.2
        if k and rng.random() < 0.6:
            entries[int(upper[rng.integers(0, k)])] = 0.25
        if rng.random() < 0.3:
            entries[s] = 0.1
        rows[s] = sorted(entries.items())
    if cyclic_extra and extra >= 2:
        a, b = int(upper[-1]), int(upper[-2])  # the last two in one cycle
        rows[a] = sorted({**dict(rows[a]), b: 0.25}.items())
        rows[b] = sorted({**dict(rows[b]), a: 0.05}.items())
    return (_csr(g_rows, n), product[inside], _csr(rows, n + extra), product)


@pytest.fixture
def _small_walks(monkeypatch: pytest.MonkeyPatch) -> None:
    """Chains walked over their components however small (the package: 32,768 states)."""
    monkeypatch.setattr(chain_levels, "WALK_MIN_STATES", 8)
    cl.forget()
    yield
    cl.forget()


def _rhs(n: int, k: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.random(n) if k == 1 else rng.random((n, k))


@pytest.mark.usefixtures("_small_walks")
@pytest.mark.parametrize("compiled", [False, True])
@pytest.mark.parametrize("seed", range(6))
def test_a_superset_chain_reuses_the_walk_with_a_new_walks_bits(seed: int, compiled: bool,
                                                                monkeypatch) -> None:
    if compiled:
        pytest.importorskip("numba")
        from mitld_lp.solvers import topological

        kern = topological.level_kernels(1, 1, compiled=True)
        monkeypatch.setattr(chain_levels, "level_kernels", lambda *a: kern)
    else:
        monkeypatch.setattr(chain_levels, "level_kernels", lambda *a: None)
    g, g_states, c, c_states = _extended(seed, 60, 25)
    walk = cl.ChainLevels(g)
    walk.solve(_rhs(60, 2, seed))  # factorised by the LP stage's solve
    cl.offer(walk, g_states)
    got = cl.walk_of(c, c_states)
    assert isinstance(got, cl.Extended) and got.walk is walk
    assert cl._OFFERED == []
    fresh = cl.ChainLevels(c)
    for k in (1, 2):
        b = _rhs(85, k, 100 + seed)
        x = got.solve(b)
        assert np.array_equal(x, fresh.solve(b))  # the bits of a new walk
        # the independent route: a dense solve of (I - Q) x = b
        want = np.linalg.solve(np.eye(85) - c.toarray(), b)
        np.testing.assert_allclose(x, want, rtol=1e-12, atol=1e-12)


@pytest.mark.usefixtures("_small_walks")
@pytest.mark.parametrize("seed", range(4))
def test_the_same_chain_is_reused_whatever_its_levels(seed: int) -> None:
    g, g_states, _, _ = _extended(seed, 70, 0)
    walk = cl.ChainLevels(g)
    walk.solve(_rhs(70, 2, seed))
    assert walk.blocks is not None and len(walk._cyclic) < cl.OFFER_MIN_LEVELS
    cl.offer(walk, g_states)  # told its states: kept whatever its factorised levels
    assert cl._OFFERED == [walk]
    cl.keep_within(np.concatenate([g_states, [10**9]]))
    assert cl._OFFERED == [walk]
    got = cl.walk_of(g.copy(), g_states)
    assert got is walk
    b = _rhs(70, 1, seed)
    assert np.array_equal(got.solve(b), cl.ChainLevels(g).solve(b))
    np.testing.assert_allclose(got.solve(b), np.linalg.solve(np.eye(70) - g.toarray(), b),
                               rtol=1e-12, atol=1e-12)


@pytest.mark.usefixtures("_small_walks")
def test_a_chain_that_is_not_an_extension_is_refused() -> None:
    g, g_states, c, c_states = _extended(3, 50, 12, cyclic_extra=True)
    walk = cl.ChainLevels(g)
    cl.offer(walk, g_states)
    got = cl.walk_of(c, c_states)  # two extra states in a cycle: a new walk
    assert isinstance(got, cl.ChainLevels) and got is not walk
    assert cl._OFFERED == [walk]
    # one entry of the walk's rows changed in the larger chain: refused
    g, g_states, c, c_states = _extended(4, 50, 12)
    cl.forget()
    walk = cl.ChainLevels(g)
    cl.offer(walk, g_states)
    changed = c.copy()
    at = int(np.searchsorted(c_states, g_states[10]))
    changed.data[changed.indptr[at]] *= 0.5
    got = cl.walk_of(changed, c_states)
    assert isinstance(got, cl.ChainLevels) and got is not walk
    # the same chain under other states' names is not the walk's extension
    moved = c_states.copy()
    moved[np.searchsorted(c_states, g_states[0])] += 1  # still increasing: 10x spread
    assert not isinstance(cl.walk_of(c, moved), cl.Extended)
    # and the certificate's solved states without one of the walk's: dropped at once
    cl.keep_within(np.setdiff1d(c_states, g_states[:1]))
    assert cl._OFFERED == []


def _zero_max(mdp) -> np.ndarray:
    """The states from which no choice path reaches the target (a backward search)."""
    n, p = mdp.n_states, mdp.matrix.toarray()
    owner = np.repeat(np.arange(n), np.diff(mdp.row_groups))
    reach = np.asarray(mdp.target, dtype=bool).copy()
    while True:
        more = reach.copy()
        for c in np.flatnonzero((p[:, reach] > 0).any(axis=1)):
            more[owner[c]] = True
        if np.array_equal(more, reach):
            return ~reach
        reach = more


def _avoid_min(mdp) -> np.ndarray:
    """The states from which some policy avoids the target for ever."""
    n, p = mdp.n_states, mdp.matrix.toarray()
    owner = np.repeat(np.arange(n), np.diff(mdp.row_groups))
    avoid = ~np.asarray(mdp.target, dtype=bool)
    while True:
        stays = (p[:, ~avoid] == 0).all(axis=1)
        more = avoid & (np.bincount(owner, weights=stays, minlength=n) > 0)
        if np.array_equal(more, avoid):
            return avoid
        avoid = more


def _certified(seed: int, sense: str, reuse: bool, monkeypatch) -> tuple[object, float, int]:
    """The certificate of the LP's policy on ``tied_mdp(seed)`` (the LP's greedy chains
    walked however small), with the LP's offered walks left to it (``reuse``) or dropped
    first; with SciPy ``linprog``'s optimum at the initial state and how many walks the
    certificate took from the offers."""
    monkeypatch.setattr(lp_blocks, "GREEDY_MIN_CHOICES", 0)
    monkeypatch.setattr(chain_levels, "WALK_MIN_STATES", 8)
    monkeypatch.setattr(greedy_block, "KERNEL_MIN_CHOICES", 0)
    taken: list[object] = []
    walk_of = cl.walk_of

    def recorded(chain, states=None):
        got = walk_of(chain, states)
        taken.append(got)
        return got

    monkeypatch.setattr(certify_chain, "walk_of", recorded)
    mdp = tied_mdp(seed, n=40)
    s = Sense.MAX if sense == "max" else Sense.MIN
    want = linprog_max(mdp) if sense == "max" else _linprog_min(mdp)
    cl.forget()
    it = interval_iteration(mdp, mdp.target, sense=s, gap="max", progress=False)
    lp = solve_lp(mdp, mdp.target, sense=s, everywhere=True, bounds=(it.lower, it.upper))
    assert lp.status.value == "optimal" and lp.policy is not None
    offered = list(cl._OFFERED)
    if not reuse:
        cl.forget()
    zero = _zero_max(mdp) if sense == "max" else _avoid_min(mdp)
    cert = certify(mdp, mdp.target, lp.policy, sense=sense, zero=zero)
    assert cl._OFFERED == []  # freed by the certificate
    reused = [w for w in taken if any(w is o or getattr(w, "walk", None) is o
                                      for o in offered)]
    return cert, float(want[mdp.initial]), len(reused)


@pytest.mark.parametrize("reuse", [True, False])
@pytest.mark.parametrize("sense", ["max", "min"])
@pytest.mark.parametrize("seed", range(4))
def test_the_certificate_holds_linprogs_optimum_with_and_without_reuse(
        seed: int, sense: str, reuse: bool, monkeypatch) -> None:
    cert, want, reused = _certified(seed, sense, reuse, monkeypatch)
    assert cert.certified
    assert cert.lower <= want + 1e-12 and want - 1e-12 <= cert.upper
    assert cert.upper - cert.lower <= 1e-8
    if not reuse:
        assert reused == 0


def test_the_reuse_runs_and_keeps_the_brackets_bits(monkeypatch) -> None:
    """On the minima above the certificate takes the LP's walks (it ran, not only was
    allowed), and its bracket has the bits of the certificate without them."""
    took = 0
    for seed in range(4):
        with_reuse, _, n = _certified(seed, "min", True, monkeypatch)
        without, _, _ = _certified(seed, "min", False, monkeypatch)
        took += n
        assert (with_reuse.lower, with_reuse.upper) == (without.lower, without.upper)
        assert np.array_equal(with_reuse.values, without.values)
    assert took > 0
