"""chain-84b: a policy's chain whose solved states all lie in one component of the
product's layers is solved as that block directly (:func:`mitld_lp.solvers.
certify_chain.one_component`), without the layers' blocks and the single states' set-up.

The direct route is held against the level loop it short-cuts, to the bit; the chain's
sets and values against a construction written here (reachability by a closure of the
dense chain, the values by a dense linear solve); the certificate's brackets against
HiGHS's LP optimum on ring-shaped MDPs with end components, both senses."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
import scipy.sparse as sp
from test_cert_fast_exact import model_of_rows
from test_cert_small_exact import exact_optimum, paid_kernels
from test_cert_verdicts_84 import lp_optimum

from mitld_lp.solvers import certify as C
from mitld_lp.solvers import certify_chain as CH
from mitld_lp.solvers.rounding import rounding

ONE_COMPONENT = CH.one_component  # (the spies below replace it)


def ring_model(seed: int, n: int, exact: bool = False):
    """(With ``exact``: also the model in fractions, as ``model_of_rows`` gives it.)
    ``n`` unknown states, the target ``n`` and the sink ``n + 1``.  Each unknown
    state has a choice to the next state of a ring (and, mostly, the target and the
    sink), so that they form one component of the support graph, and 0-2 more: a
    self-loop or a split between two unknown states (end components), or a few states
    with the target and the sink."""
    rng = np.random.default_rng(84_000 + seed)
    target, sink = n, n + 1
    rows = []
    for s in range(n):
        ring = {(s + 1) % n: float(rng.uniform(0.2, 1.0))}
        if rng.random() < 0.8:
            ring[target] = float(rng.uniform(0.0, 0.3))
            ring[sink] = float(rng.uniform(0.0, 0.3))
        total = sum(ring.values())
        choices = [{t: p / total for t, p in ring.items() if p > 0}]
        for _ in range(int(rng.integers(0, 3))):
            kind = rng.random()
            if kind < 0.2:  # a self-loop: an end component of one state
                choices.append({s: 1.0})
                continue
            # a split between two unknown states (end components), else a few
            # states with the target and the sink
            pick = rng.choice(n, size=2 if kind < 0.4 else int(rng.integers(0, 3)),
                              replace=False).tolist()
            succ = sorted(set(pick) | (set() if kind < 0.4 else {target, sink}))
            w = rng.uniform(0.05, 1.0, size=len(succ))
            choices.append(dict(zip(succ, (w / w.sum()).tolist(), strict=True)))
        rows.append(choices)
    rows += [[], []]
    both = model_of_rows(rows, target, sink)
    return both if exact else both[0]


def _chain(mdp, policy, monkeypatch, direct: bool, guess=None):
    """The chain with the direct route on or off (``guess``: the values' estimate,
    read where positive on the block), and whether it ran."""
    ran = []

    def spy(comp):
        got = ONE_COMPONENT(comp) if direct else False
        ran.append(got)
        return got

    monkeypatch.setattr(CH, "one_component", spy)
    target = np.asarray(mdp.target, dtype=bool)
    rnd = rounding(sp.csr_array(mdp.matrix), C.ETA)
    ch = CH.chain(mdp, target, policy, rnd, CH.support_layers(mdp), guess=guess)
    return ch, any(ran)


def _bits(ch) -> tuple[bytes, ...]:
    return tuple(np.ascontiguousarray(a).tobytes()
                 for a in (ch.v, ch.w, ch.solved, ch.sure, ch.never))


@pytest.mark.parametrize("compiled", [True, False])
def test_the_direct_block_is_the_level_loop_to_the_bit(compiled, monkeypatch) -> None:
    paid_kernels(monkeypatch, compiled)
    fired = 0
    for seed in range(12):
        mdp = ring_model(seed, 24)
        for upper in (True, False):
            v, _, policy = lp_optimum(mdp, upper)
            # with the LP's values as the guess (positive on the block: one joint
            # solve of v and W) and without (W solved after v)
            for guess in (None, np.maximum(v, 0.0) * 0.999):
                new, used = _chain(mdp, policy, monkeypatch, True, guess)
                old, off = _chain(mdp, policy, monkeypatch, False, guess)
                assert not off
                assert _bits(new) == _bits(old)
                fired += used
    assert fired >= 24  # the direct route ran on at least half the chains


def _closure(q: np.ndarray, seeds: np.ndarray) -> np.ndarray:
    """The states with a path to a ``seeds`` state along ``q``'s positive entries:
    boolean matrix products until nothing is added."""
    reach = seeds.copy()
    while True:
        more = reach | (q[:, reach] > 0).any(axis=1)
        if np.array_equal(more, reach):
            return reach
        reach = more


@pytest.mark.parametrize("seed", range(8))
@pytest.mark.parametrize("upper", [True, False])
def test_the_direct_block_solves_the_chain(seed, upper, monkeypatch) -> None:
    mdp = ring_model(seed, 20)
    policy = lp_optimum(mdp, upper)[2]
    ch, used = _chain(mdp, policy, monkeypatch, True)
    m = sp.csr_array(mdp.matrix).toarray()
    n = mdp.n_states
    target = np.asarray(mdp.target, dtype=bool)
    q = np.zeros((n, n))  # the policy's chain, the target and absorbing states without
    for s in range(n):
        if policy[s] >= 0 and not target[s]:
            q[s] = m[policy[s]]
    never = ~_closure(q, target)
    sure = ~_closure(q, never)
    assert np.array_equal(ch.never, never) and np.array_equal(ch.sure, sure)
    solved = ~never & ~sure & (policy >= 0) & ~target
    assert np.array_equal(ch.solved, solved)
    idx = np.flatnonzero(solved)
    if idx.size == 0:
        return
    a = np.eye(idx.size) - q[np.ix_(idx, idx)]
    b = q[np.ix_(idx, np.flatnonzero(sure))].sum(axis=1)
    v = np.linalg.solve(a, b)
    assert np.allclose(ch.v, v, rtol=1e-12, atol=1e-15)
    assert used == (idx.size >= 2)  # one component of the ring's layers holds them
    # the slack W covers twice the residual and the rounding on the solved states
    assert np.all(ch.w >= 0) and np.all(ch.w[ch.v > 0] > 0)


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("upper", [True, False])
def test_brackets_hold_the_lp_optimum_on_rings(seed, upper, monkeypatch) -> None:
    """The certificate of the LP's policy, the chain by the direct block and by the
    level loop: the same bits and verdict, holding HiGHS's optimum (to its 1e-9).  (A
    side whose repair does not close is not certified and falls back to the trivial
    bound, which holds the optimum too.)"""
    paid_kernels(monkeypatch, True)
    mdp = ring_model(seed, 30)
    v, zero, policy = lp_optimum(mdp, upper)
    brackets = set()
    for direct in (True, False):
        monkeypatch.setattr(CH, "one_component", ONE_COMPONENT if direct else
                            (lambda comp: False))
        cert = C.certify(mdp, np.asarray(mdp.target), policy,
                         sense="max" if upper else "min", zero=zero)
        assert cert.lower - 1e-9 <= v[0] <= cert.upper + 1e-9, (cert, v[0])
        assert 0.0 <= cert.lower <= cert.upper <= 1.0
        brackets.add((cert.lower.hex(), cert.upper.hex(), cert.certified))
    assert len(brackets) == 1


@pytest.mark.parametrize("seed", range(8))
def test_brackets_hold_the_exact_optimum_in_fractions(seed, monkeypatch) -> None:
    """On rings of five states, the brute force's optimum in exact fractions (every
    deterministic policy solved in rational arithmetic, ``test_cert_small_exact``) lies
    inside the certificate of its optimal policy, compared as fractions with no
    tolerance, with the chain by the direct block and by the level loop: the same
    bits."""
    paid_kernels(monkeypatch, True)
    mdp, exact = ring_model(seed, 5, exact=True)
    target = np.asarray(mdp.target)
    fired = []

    def spy(comp):
        got = ONE_COMPONENT(comp)
        fired.append(got)
        return got

    for upper in (True, False):
        v, policy = exact_optimum(mdp, exact, 5, upper)
        zero = np.array([p == 0 for p in v])
        one = None if upper else np.array([p == 1 for p in v])
        got = set()
        for direct in (True, False):
            monkeypatch.setattr(CH, "one_component", spy if direct else (lambda comp: False))
            cert = C.certify(mdp, target, policy, sense="max" if upper else "min",
                             zero=zero, one=one)
            assert Fraction(cert.lower) <= v[0] <= Fraction(cert.upper), (upper, v[0], cert)
            got.add((cert.lower.hex(), cert.upper.hex(), cert.certified))
        assert len(got) == 1
    assert any(fired)  # the direct block ran on this ring
