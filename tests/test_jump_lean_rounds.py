"""The policy jump's lean rounds (:func:`mitld_lp.solvers.policy_jump.lean_round`) and
its factorisation in strong-component order (:func:`~mitld_lp.solvers.policy_jump.
chain_factor`) on random MDPs with cycles, both senses.

Independent routes: each policy's chain solved exactly in Fractions (Gaussian
elimination written here), the optimum by brute force over every deterministic policy
(a transient MDP has one policy optimal in every state), and the rounds of
:func:`~mitld_lp.solvers.topological.policy_round` (the route the lean one replaces),
which must give the same bits when the factorisation is the same.
"""

from __future__ import annotations

import itertools
from fractions import Fraction

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.solvers import policy_jump as pj
from mitld_lp.solvers import topo_chain
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.topological import Block, Factors


def _random_block(seed: int, n: int = 6) -> Block:
    """``n`` states, one to three choices each; a choice moves to one to three states of
    the block (cycles likely) and leaves with probability at least 1/8 (so every
    policy's chain is transient); probabilities are multiples of 1/64 (exact floats)."""
    rng = np.random.default_rng(seed)
    rows, cols, vals, reward, starts = [], [], [], [], []
    m = 0
    for _s in range(n):
        starts.append(m)
        for _c in range(int(rng.integers(1, 4))):
            succ = rng.choice(n, size=int(rng.integers(1, 4)), replace=False)
            weights = rng.integers(1, 8, size=succ.size).astype(float)
            stay = int(rng.integers(8, 57))  # 64ths kept in the block
            parts = np.floor(weights / weights.sum() * stay)
            parts[0] += stay - parts.sum()
            for t, p in zip(succ, parts, strict=True):
                if p > 0:
                    rows.append(m)
                    cols.append(int(t))
                    vals.append(p / 64.0)
            leave = (64 - stay) / 64.0
            reward.append(leave * int(rng.integers(0, 5)) / 4.0)  # exits worth 0..1
            m += 1
    inner = sp.csr_array((vals, (rows, cols)), shape=(m, n))
    inner.sum_duplicates()
    outer = sp.csr_array((m, n))
    return Block(np.arange(n), np.arange(m), inner, outer, np.asarray(starts, np.int64),
                 np.asarray(reward))


def _exact_values(block: Block, chosen: np.ndarray, reward: np.ndarray) -> list[Fraction]:
    """``v = r + Q v`` of the chain of the ``chosen`` rows, by Fraction elimination."""
    n = chosen.size
    q = block.inner.toarray()
    a = [[Fraction(int(i == j)) - Fraction(float(q[c, j])) for j in range(n)]
         + [Fraction(float(reward[c]))] for i, c in enumerate(chosen)]
    for col in range(n):
        piv = next(r for r in range(col, n) if a[r][col] != 0)
        a[col], a[piv] = a[piv], a[col]
        for r in range(n):
            if r != col and a[r][col] != 0:
                f = a[r][col] / a[col][col]
                a[r] = [x - f * y for x, y in zip(a[r], a[col], strict=True)]
    return [a[i][n] / a[i][i] for i in range(n)]


def _optimum(block: Block, reward: np.ndarray, sense: Sense) -> list[Fraction]:
    groups = block.groups
    per_state = [range(groups[s], groups[s + 1]) for s in range(block.states.size)]
    best: list[Fraction] | None = None
    for pol in itertools.product(*per_state):
        v = _exact_values(block, np.asarray(pol), reward)
        if best is None:
            best = v
        else:
            pick = max if sense is Sense.MAX else min
            best = [pick(x, y) for x, y in zip(best, v, strict=True)]
    assert best is not None
    return best


def _improve(block: Block, sense: Sense):
    reward = block.to_target
    start = pj.start_policy(block, reward, np.zeros(block.states.size), sense)
    return pj.improve_ahead(block, reward, start, factors=Factors(), sense=sense)


SEEDS = range(12)


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize("seed", SEEDS)
def test_lean_round_same_bits_as_policy_round(monkeypatch, seed, sense):
    """With the whole-chain factorisation, the lean rounds give the policy, values and
    exit times of topological.policy_round's rounds to the bit."""
    block = _random_block(seed)
    monkeypatch.setattr(pj, "TOPO_LU", False)
    monkeypatch.setattr(pj, "LEAN_ROUNDS", True)
    lean = _improve(block, sense)
    monkeypatch.setattr(pj, "LEAN_ROUNDS", False)
    plain = _improve(block, sense)
    for x, y in zip(lean, plain, strict=True):
        assert x.dtype == y.dtype and np.array_equal(x, y)


def _compiled_topo(monkeypatch, compiled: bool) -> None:
    """The compiled factorisation in component order (topo_chain) forced on (a cold
    cache compiles), or off (SciPy's TopoLU)."""
    monkeypatch.setattr(topo_chain, "COMPILED", compiled)
    if compiled:
        pytest.importorskip("numba")
        run = topo_chain.kernels(force=True)
        monkeypatch.setattr(topo_chain, "kernels", lambda force=False: run)


@pytest.mark.parametrize("compiled", [False, True])
@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize("seed", SEEDS)
def test_component_order_values_against_fractions(monkeypatch, seed, sense, compiled):
    """The factorisation in strong-component order forced on (every chain, however
    small; SciPy's or the compiled one): the policy iteration's values are the exact
    optimum (brute force over the policies, Fractions) and its policy's own exact
    values, to extended precision."""
    block = _random_block(seed)
    monkeypatch.setattr(pj, "DENSE_LU_STATES", 0)
    monkeypatch.setattr(pj, "TOPO_LU", True)
    _compiled_topo(monkeypatch, compiled)
    made = []
    real = pj.chain_factor

    def spy(chain):
        lu = real(chain)
        made.append(type(lu).__name__)
        return lu

    monkeypatch.setattr(pj, "chain_factor", spy)
    chosen, v, t = _improve(block, sense)
    assert ("CompiledTopoLU" if compiled else "TopoLU") in made
    exact = _exact_values(block, chosen, block.to_target)
    steps = _exact_values(block, chosen, np.ones(block.choices.size))
    best = _optimum(block, block.to_target, sense)
    for got, want, opt in zip(v, exact, best, strict=True):
        assert abs(Fraction(float(got)) - want) <= Fraction(1, 10**15) * (abs(want) + 1)
        assert abs(want - opt) <= Fraction(1, 10**14)
    for got, want in zip(t, steps, strict=True):
        assert abs(Fraction(float(got)) - want) <= Fraction(1, 10**14) * want


@pytest.mark.parametrize("seed", SEEDS)
def test_topo_lu_solves_the_chain(seed):
    """TopoLU's answer (permuted in and out) against the exact solve of the chain."""
    block = _random_block(seed, n=9)
    groups = block.groups
    chosen = groups[:-1] + (seed % 2) * (np.diff(groups) - 1)  # first or last choices
    chain = sp.csr_array(block.inner[chosen])
    lu = pj.TopoLU.__new__(pj.TopoLU)
    import scipy.sparse.linalg as spla
    from scipy.sparse import csgraph

    _, label = csgraph.connected_components(chain, directed=True, connection="strong")
    order = np.argsort(label, kind="stable")[::-1].copy()  # another order: still exact
    at = np.empty_like(order)
    at[order] = np.arange(order.size)
    a = sp.csc_array((sp.eye_array(9) - chain).toarray()[np.ix_(order, order)])
    lu.__init__(spla.splu(a, permc_spec="NATURAL"), order, at)
    rhs = block.to_target[chosen]
    got = lu.solve(np.column_stack([rhs, np.ones(9)]))
    exact = _exact_values(block, chosen, block.to_target)
    for x, want in zip(got[:, 0], exact, strict=True):
        assert abs(Fraction(float(x)) - want) <= Fraction(1, 10**12) * (abs(want) + 1)
    with pytest.raises(ValueError, match="trans"):
        lu.solve(rhs, trans="T")


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize("seed", SEEDS)
def test_jump_brackets_contain_the_optimum(monkeypatch, seed, sense):
    """The whole jump with the component-order factorisation on and off: each bracket
    it proves contains the exact optimum; with it off, the lean rounds and the plain
    ones prove the same bounds to the bit."""
    block = _random_block(seed)
    best = _optimum(block, block.to_target, sense)
    got = {}
    for topo, lean in (("compiled", True), (True, True), (False, True), (False, False)):
        _compiled_topo(monkeypatch, topo == "compiled")
        topo = bool(topo)
        monkeypatch.setattr(pj, "DENSE_LU_STATES", 0 if topo else 256)
        monkeypatch.setattr(pj, "TOPO_LU", topo)
        monkeypatch.setattr(pj, "LEAN_ROUNDS", lean)
        lo, hi = np.zeros(block.states.size), np.ones(block.states.size)
        ok = pj.jump(block, lo, hi, 1e-6, None, sense)
        for low, up, opt in zip(lo, hi, best, strict=True):
            assert Fraction(float(low)) <= opt <= Fraction(float(up))
        got[topo, lean] = (ok, lo, hi)
    (ok1, lo1, hi1), (ok2, lo2, hi2) = got[False, True], got[False, False]
    assert ok1 == ok2 and np.array_equal(lo1, lo2) and np.array_equal(hi1, hi2)


def test_large_component_falls_back_to_the_whole_chain(monkeypatch):
    """A chain with a strong component above TOPO_MAX_COMPONENT is factorised whole
    (topological.chain_lu), one with none is factorised in component order."""
    monkeypatch.setattr(pj, "DENSE_LU_STATES", 0)
    cycle = sp.csr_array(np.roll(np.eye(4), 1, axis=1) * 0.5)  # one component of 4
    line = sp.csr_array(np.eye(4, k=1) * 0.5)  # four components of 1
    monkeypatch.setattr(pj, "TOPO_MAX_COMPONENT", 3)
    monkeypatch.setattr(topo_chain, "COMPILED", False)  # SciPy's route
    assert not isinstance(pj.chain_factor(cycle), pj.TopoLU)
    assert isinstance(pj.chain_factor(line), pj.TopoLU)
    # both solve x = 1 + Q x: the cycle's x = 2, the line's 2 - 2^-(3 - i) ... by hand
    assert np.allclose(pj.chain_factor(cycle).solve(np.ones(4)), 2.0)
    assert np.allclose(pj.chain_factor(line).solve(np.ones(4)), [1.875, 1.75, 1.5, 1.0])


def test_one_way_reads_the_labels():
    """_one_way: the labels order the components (moves between them all one way) or
    not; checked by hand on the line 0 -> 1 -> 2."""
    line = sp.csr_array(np.eye(3, k=1) * 0.5)
    assert pj._one_way(line, np.array([2, 1, 0]))  # downstream lower
    assert pj._one_way(line, np.array([0, 1, 2]))  # downstream higher
    assert not pj._one_way(line, np.array([1, 2, 0]))  # 0 -> 1 up, 1 -> 2 down
