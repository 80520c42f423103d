"""The certificate reuses the LP's walk of a chain equal to its own
(:func:`mitld_lp.solvers.chain_levels.walk_of`): only on the same chain, with the bits
of a new walk, freed by the certificate."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from mitld_lp.solvers import chain_levels as cl


def _chain(n: int, seed: int, shuffled: bool) -> sp.csr_array:
    """A transient chain of ``n`` states: cycles of four (1/2 on to the next of the
    four), and from every group but the first 3/10 to a random state of a lower
    group; each row's entries stored in a random order when ``shuffled``."""
    rng = np.random.default_rng(seed)
    i = np.arange(n)
    nxt = (i // 4) * 4 + (i + 1) % 4
    down = np.where(i >= 4, rng.integers(0, np.maximum(i // 4 * 4, 1)), -1)
    rows = [[(nxt[k], 0.5)] + ([(down[k], 0.3)] if down[k] >= 0 else []) for k in range(n)]
    if shuffled:
        rows = [r[::-1] if rng.random() < 0.5 else r for r in rows]
    indptr = np.concatenate([[0], np.cumsum([len(r) for r in rows])])
    cols = np.array([c for r in rows for c, _ in r], dtype=np.int32)
    vals = np.array([v for r in rows for _, v in r])
    return sp.csr_array((vals, cols, indptr.astype(np.int32)), shape=(n, n))


def test_walk_of_reuses_only_the_same_chain_with_a_new_walks_bits() -> None:
    n = cl.WALK_MIN_STATES  # walked over its own components
    b = np.random.default_rng(1).random(n)
    cl.forget()
    first = cl.ChainLevels(_chain(n, 7, shuffled=True))
    x_first = first.solve(b)
    cl.offer(first)
    # another walk of the same chain, its rows stored in another order: reused
    again = _chain(n, 7, shuffled=True)
    got = cl.walk_of(again)
    assert got is first
    assert cl._OFFERED == []  # taken out of the offers
    fresh = cl.ChainLevels(_chain(n, 7, shuffled=False))
    assert np.array_equal(got.solve(b), fresh.solve(b))  # the bits of a new walk
    assert np.array_equal(got.solve(b), x_first)
    # the independent route: x = b + Q x iterated (every row sums to 4/5 at most, so
    # 200 rounds leave 0.8^200 of the answer)
    q = _chain(n, 7, shuffled=False)
    x = b.copy()
    for _ in range(200):
        x = b + q @ x
    assert np.allclose(x_first, x, rtol=1e-12, atol=1e-12)
    # a chain that differs in one value is not the offered one
    cl.offer(first)
    other = _chain(n, 7, shuffled=False)
    other.data[5] = 0.25
    assert cl.walk_of(other) is not first
    assert cl._OFFERED == [first]
    cl.forget()
    assert cl._OFFERED == []


def test_a_small_chain_is_matched_as_it_comes_and_offers_are_capped() -> None:
    cl.forget()
    small = _chain(64, 3, shuffled=True)  # one LU: kept as it comes
    walks = [cl.ChainLevels(_chain(64, s, shuffled=True)) for s in range(cl.OFFER_MAX + 1)]
    for w in walks:
        cl.offer(w)
    assert len(cl._OFFERED) == cl.OFFER_MAX and walks[0] not in cl._OFFERED
    assert cl.walk_of(small) is walks[3]
    b = np.linspace(0.0, 1.0, 64)
    exact = np.linalg.solve(np.eye(64) - small.toarray(), b)
    assert np.allclose(walks[3].solve(b), exact, rtol=1e-13, atol=1e-13)
    cl.forget()


def test_certify_frees_the_offers() -> None:
    from mitld_lp.mdp import MDP
    from mitld_lp.solvers.certify import certify

    cl.offer(cl.ChainLevels(_chain(64, 1, shuffled=False)))
    # s0 -a-> s1 (1/2) or s2 (1/2); s1 the target, s2 a sink: Pmax = 1/2
    target, sink = np.array([False, True, False]), np.array([False, False, True])
    mdp = MDP(matrix=sp.csr_array(np.array([[0.0, 0.5, 0.5], [0, 1, 0], [0, 0, 1]])),
              row_groups=np.array([0, 1, 2, 3], dtype=np.int64),
              choice_actions=np.zeros(3, dtype=np.int32), action_names=("a",),
              initial=0, target=target, sink=sink, truncated=np.zeros(3, dtype=bool),
              states=[0, 1, 2])
    cert = certify(mdp, target, np.array([0, -1, -1]), zero=sink)
    assert cl._OFFERED == []
    assert cert.certified and cert.lower <= 0.5 <= cert.upper


def test_a_walk_of_few_factorised_levels_is_not_kept(monkeypatch) -> None:
    """Holding a large walk for a certificate whose chain is another graph costs memory
    and saves little where it factorised few levels: such a walk is not kept."""
    monkeypatch.setattr(cl, "WALK_MIN_STATES", 2)
    cl.forget()
    n = 64
    i = np.arange(n)
    # one cycle of 8 states, the rest single states leading into it: one cyclic level
    nxt = np.where(i < 8, (i + 1) % 8, i - 1)
    walk = cl.ChainLevels(sp.csr_array((np.full(n, 0.5), nxt, np.arange(n + 1)),
                                       shape=(n, n)))
    x = walk.solve(np.ones(n))
    assert len(walk._cyclic) == 1 < cl.OFFER_MIN_LEVELS
    cl.offer(walk)
    assert cl._OFFERED == []
    # the cycle's states: x = 1 + x/2 around it, so 2; the states above it 1 + x/2
    assert np.allclose(x[:8], 2.0)
    assert np.allclose(x[8], 1.0 + 0.5 * 2.0)
