"""A block answered by the greedy policy of sound bounds, certified by the LP's dual
(mitld_lp.solvers.greedy_block): on MDPs full of exact ties (every state has a twin
it is bisimilar to, every choice a copy that moves to the twins) the values are
scipy linprog's (maximum and minimum); a greedy policy that loses is refused; a
hand block in Fractions."""

from __future__ import annotations

import re
from fractions import Fraction

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.optimize import linprog

from mitld_lp.mdp import MDP
from mitld_lp.solvers import greedy_block, lp_blocks
from mitld_lp.solvers.chain_levels import chain_solve
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.greedy_block import certified_greedy
from mitld_lp.solvers.iteration import interval_iteration
from mitld_lp.solvers.lp import solve_lp
from mitld_lp.solvers.quotient import reduce
from mitld_lp.solvers.topological import Block
from mitld_lp.testing import random_mdp


@pytest.fixture(autouse=True)
def _every_block_size(monkeypatch: pytest.MonkeyPatch) -> None:
    """The greedy policy tried on these small blocks too (the package tries it from
    lp_blocks.GREEDY_MIN_CHOICES choices on)."""
    monkeypatch.setattr(lp_blocks, "GREEDY_MIN_CHOICES", 0)


def _twinned(base: MDP) -> MDP:
    """``base`` doubled: state ``s`` and its twin ``n + s`` (a target's twin a target,
    a sink's a sink) have the same choices, each twice: once to the original
    successors, once to their twins.  Twins are bisimilar, so every value is attained
    by two exactly tied choices (and more where the base has ties)."""
    n = base.n_states
    absorbing = base.target | base.sink
    m = base.matrix
    rows: list[tuple[np.ndarray, np.ndarray]] = []
    counts = []
    for copy in (0, 1):
        for s in range(n):
            if absorbing[s]:
                rows.append((np.array([s + copy * n]), np.array([1.0])))
                counts.append(1)
                continue
            for c in range(base.row_groups[s], base.row_groups[s + 1]):
                at = slice(m.indptr[c], m.indptr[c + 1])
                cols, vals = m.indices[at], m.data[at]
                rows += [(cols, vals), (cols + n, vals)]
            counts.append(2 * int(base.row_groups[s + 1] - base.row_groups[s]))
    row = np.repeat(np.arange(len(rows)), [r[0].size for r in rows])
    matrix = sp.csr_array((np.concatenate([r[1] for r in rows]),
                           (row, np.concatenate([r[0] for r in rows]))),
                          shape=(len(rows), 2 * n))
    groups = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    return MDP(matrix=matrix, row_groups=groups,
               choice_actions=np.zeros(len(rows), dtype=np.int32), action_names=("a",),
               initial=0, target=np.concatenate([base.target, base.target]),
               sink=np.concatenate([base.sink, base.sink]),
               truncated=np.zeros(2 * n, dtype=bool), states=tuple(range(2 * n)))


def linprog_max(mdp: MDP) -> np.ndarray:
    """Pmax by scipy's LP: the least ``v >= 0`` with ``v(s) >= P(c) v`` for every
    choice of a non-target state and ``v = 1`` on the target."""
    n, p = mdp.n_states, mdp.matrix.toarray()
    owner = np.repeat(np.arange(n), np.diff(mdp.row_groups))
    free = ~mdp.target[owner]
    a_ub = p[free].copy()
    a_ub[np.arange(a_ub.shape[0]), owner[free]] -= 1.0  # P(c) v - v(s) <= 0
    bounds = [(1.0, 1.0) if t else (0.0, 1.0) for t in mdp.target]
    res = linprog(np.ones(n), A_ub=a_ub, b_ub=np.zeros(a_ub.shape[0]), bounds=bounds,
                  method="highs", options={"primal_feasibility_tolerance": 1e-10,
                                           "dual_feasibility_tolerance": 1e-10})
    assert res.status == 0
    return res.x


def _linprog_min(mdp: MDP) -> np.ndarray:
    """Pmin by scipy's LP: 0 on the states where some policy avoids the target for ever
    (the greatest set of non-target states each with a choice that stays in it), 1 on
    the target, and elsewhere the greatest ``v`` with ``v(s) <= P(c) v`` for every
    choice (the one fixpoint there)."""
    n, p = mdp.n_states, mdp.matrix.toarray()
    owner = np.repeat(np.arange(n), np.diff(mdp.row_groups))
    avoid = ~mdp.target
    while True:
        stays = (p[:, ~avoid] == 0).all(axis=1)  # a choice that never leaves ``avoid``
        more = avoid & (np.bincount(owner, weights=stays, minlength=n) > 0)
        if np.array_equal(more, avoid):
            break
        avoid = more
    free = ~mdp.target[owner] & ~avoid[owner]
    a_ub = -p[free]
    a_ub[np.arange(a_ub.shape[0]), owner[free]] += 1.0  # v(s) - P(c) v <= 0
    bounds = [(1.0, 1.0) if t else (0.0, 0.0) if z else (0.0, 1.0)
              for t, z in zip(mdp.target, avoid, strict=True)]
    res = linprog(-np.ones(n), A_ub=a_ub, b_ub=np.zeros(a_ub.shape[0]), bounds=bounds,
                  method="highs", options={"primal_feasibility_tolerance": 1e-10,
                                           "dual_feasibility_tolerance": 1e-10})
    assert res.status == 0
    return res.x


def tied_mdp(seed: int, n: int = 30) -> MDP:
    return _twinned(random_mdp(n, seed=seed, target_fraction=0.1, sink_fraction=0.1,
                               self_loop_fraction=0.0, max_choices=3, max_successors=3))


@pytest.mark.parametrize("seed", range(6))
def test_tied_blocks_get_linprogs_values(seed: int) -> None:
    mdp = tied_mdp(seed)
    want = linprog_max(mdp)
    it = interval_iteration(mdp, mdp.target, gap="max", progress=False)
    got = solve_lp(mdp, mdp.target, everywhere=True, bounds=(it.lower, it.upper))
    solved = solve_lp(mdp, mdp.target, everywhere=True, bounds=(it.lower, it.upper),
                      greedy=False)
    assert got.status.value == "optimal" and got.values is not None
    np.testing.assert_allclose(got.values, want, atol=1e-8)
    assert solved.values is not None
    np.testing.assert_allclose(got.values, solved.values, atol=1e-9)
    if "block LP" in solved.message and "0 block LPs" not in solved.message:
        assert "by the bounds' greedy policy, certified" in got.message
    # the policy attains the values: its own chain from the same start
    assert got.policy is not None
    chosen = np.asarray(got.policy)
    chain = mdp.matrix[chosen].toarray()
    chain[mdp.target | mdp.sink] = 0.0
    reach = chain[:, mdp.target].sum(axis=1)
    inner = np.where(mdp.target | mdp.sink, 0.0, 1.0)[:, None] * chain
    inner[:, mdp.target] = 0.0
    live = np.flatnonzero(want > 0)
    v = np.zeros(mdp.n_states)
    v[mdp.target] = 1.0
    v[live] = np.linalg.solve(np.eye(live.size) - inner[np.ix_(live, live)],
                              reach[live] + 0.0)
    np.testing.assert_allclose(v[~mdp.target], want[~mdp.target], atol=1e-8)


def test_a_block_was_certified_at_all() -> None:
    """The seeds above include blocks the certificate answers (else the test would
    only have checked the LP again)."""
    mdp = tied_mdp(0)
    it = interval_iteration(mdp, mdp.target, gap="max", progress=False)
    got = solve_lp(mdp, mdp.target, everywhere=True, bounds=(it.lower, it.upper))
    assert "by the bounds' greedy policy, certified" in got.message
    assert got.message.startswith("0 block LPs") or "clarabel" not in got.message


@pytest.mark.parametrize("seed", range(6))
def test_minimum_with_ties_gets_linprogs_values(seed: int) -> None:
    mdp = tied_mdp(seed)
    want = _linprog_min(mdp)
    it = interval_iteration(mdp, mdp.target, sense=Sense.MIN, gap="max", progress=False)
    got = solve_lp(mdp, mdp.target, sense=Sense.MIN, everywhere=True,
                   bounds=(it.lower, it.upper))
    assert got.values is not None and got.status.value == "optimal"
    np.testing.assert_allclose(got.values, want, atol=1e-9)


def _whole(mdp: MDP):
    q = reduce(mdp, mdp.target)
    block = Block.of(q, np.arange(q.n_states))
    kept = np.flatnonzero(q.state_map >= 0)
    return q, block, kept


@pytest.mark.parametrize("batch", [greedy_block.BATCH, 5])  # 5: the choices in batches
@pytest.mark.parametrize("seed", range(4))
def test_a_losing_greedy_policy_is_refused(seed: int, batch: int, monkeypatch) -> None:
    """With the optimal values as the bound the greedy policy is certified, with its
    values; with a bound that ranks a clearly losing choice first (the optimum raised
    on that choice's own successors) it is refused at that choice's state and every
    state upstream of it; the states downstream keep the optimum."""
    monkeypatch.setattr(greedy_block, "BATCH", batch)
    mdp = tied_mdp(seed)
    want = linprog_max(mdp)
    q, block, kept = _whole(mdp)
    v = np.zeros(q.n_states)
    v[q.state_map[kept]] = want[kept]
    reward = block.to_target
    ok = certified_greedy(block, reward, v, Sense.MAX, 1e-9, 1e-6)
    assert ok is not None
    np.testing.assert_allclose(ok.values, v, atol=1e-9)
    score = reward + block.inner @ v
    owner = np.repeat(np.arange(v.size), np.diff(block.groups))
    loss = v[owner] - score
    # a clearly losing choice whose successors no other choice of its state moves to
    # (each choice's copy moves to the twins): raising them makes it the greedy one
    inner = block.inner
    for c in np.argsort(-loss):
        s, succ = owner[c], inner[[c]].indices
        others = [d for d in range(block.groups[s], block.groups[s + 1]) if d != c]
        if loss[c] > 1e-6 and succ.size and s not in succ and not np.isin(inner[others].indices,
                                                             succ).any():
            break
    else:
        pytest.skip("no losing choice with successors of its own")
    bent = v.copy()
    bent[succ] += 2.0 * loss[c] / inner[[c]].data.sum()  # the choice now scores best
    part = certified_greedy(block, reward, bent, Sense.MAX, 1e-9, 1e-6)
    if part is None:  # every state can reach the one that fails
        return
    assert s in part.left
    # the settled states (those that cannot reach a failing one) have the optimum
    settled = np.setdiff1d(np.arange(v.size), part.left)
    np.testing.assert_allclose(part.values[settled], v[settled], atol=1e-9)
    graph = np.zeros((v.size, v.size), dtype=bool)  # state -> successor, any choice
    coo = sp.coo_array(inner)
    graph[owner[coo.row], coo.col] = True
    reach = graph | np.eye(v.size, dtype=bool)
    for _ in range(int(np.ceil(np.log2(v.size))) + 1):  # paths of every length
        reach = (reach.astype(np.int64) @ reach.astype(np.int64)) > 0
    assert not reach[np.ix_(settled, [s])].any()


def test_hand_block_in_fractions() -> None:
    """Two states in a cycle, each with two exactly tied choices and one that loses:
    s0: to s1 w.p. 1/2, else target 1/4 (twice, as two choices), or target 1/5;
    s1: to s0 w.p. 1/3, else target 1/3 (twice), or target 1/2 - 1/100.
    v0 = 1/4 + v1/2, v1 = 1/3 + v0/3  =>  v0 = 1/2, v1 = 1/2."""
    f = Fraction
    rows = [[0, f(1, 2)], [0, f(1, 2)], [0, 0], [f(1, 3), 0], [f(1, 3), 0], [0, 0]]
    reward = [f(1, 4), f(1, 4), f(1, 5), f(1, 3), f(1, 3), f(1, 2) - f(1, 100)]
    v0 = (reward[0] + f(1, 2) * reward[3]) / (1 - f(1, 2) * f(1, 3))
    v1 = reward[3] + f(1, 3) * v0
    inner = sp.csr_array(np.array(rows, dtype=float))
    block = Block(np.arange(2), np.arange(6), inner, inner, np.array([0, 3]),
                  np.array(reward, dtype=float))
    got = certified_greedy(block, block.to_target, np.array([0.499, 0.499]), Sense.MAX,
                           1e-9, 1e-6)
    assert got is not None and got.left.size == 0
    np.testing.assert_allclose(got.values, [float(v0), float(v1)], rtol=1e-15)
    assert got.chosen[0] in (0, 1) and got.chosen[1] in (3, 4)
    assert got.weights.sum() == 2.0 and got.weights[got.chosen].sum() == 2.0
    # bounds 0.4 rank s1's losing choice first (1/3 + 0.4/3 < 49/100): refused
    assert certified_greedy(block, block.to_target, np.array([0.4, 0.4]), Sense.MAX,
                            1e-9, 1e-6) is None
    # a minimum: v0 = min(1/5, 1/4 + v1/2) = 1/5, v1 = min(49/100, 1/3 + v0/3) = 2/5
    low = certified_greedy(block, block.to_target, np.array([0.21, 0.41]), Sense.MIN,
                           1e-9, 1e-6)
    assert low is not None and low.chosen[0] == 2 and low.chosen[1] in (3, 4)
    np.testing.assert_allclose(low.values, [float(f(1, 5)), float(f(1, 3) + f(1, 15))],
                               rtol=1e-15)
    # upper bounds 0.6 rank s1's 49/100 first, which loses to 2/5: refused
    assert certified_greedy(block, block.to_target, np.array([0.6, 0.6]), Sense.MIN,
                            1e-9, 1e-6) is None


def test_chain_solve_matches_a_dense_solve() -> None:
    rng = np.random.default_rng(3)
    n = 40
    q = sp.random_array((n, n), density=0.08, rng=rng, format="csr")
    q = sp.csr_array(q.multiply(0.9 / np.maximum(q.sum(axis=1), 1.0)[:, None]))
    rhs = rng.random((n, 2))
    want = np.linalg.solve(np.eye(n) - q.toarray(), rhs)
    np.testing.assert_allclose(chain_solve(q, rhs), want, rtol=1e-12)


def test_a_level_of_two_components_is_settled_apart() -> None:
    """A block of two components of one level, the greedy policy losing in one of
    them: the other is settled by the certificate, the LP solves the first alone, and
    the values are linprog's."""
    a, b = tied_mdp(0), tied_mdp(1)
    na, nb = a.n_states, b.n_states
    matrix = sp.block_diag([a.matrix, b.matrix], format="csr")
    both = MDP(matrix=sp.csr_array(matrix),
               row_groups=np.concatenate([a.row_groups, a.row_groups[-1] + b.row_groups[1:]]),
               choice_actions=np.zeros(matrix.shape[0], dtype=np.int32),
               action_names=("a",), initial=0,
               target=np.concatenate([a.target, b.target]),
               sink=np.concatenate([a.sink, b.sink]),
               truncated=np.zeros(na + nb, dtype=bool), states=tuple(range(na + nb)))
    want = linprog_max(both)
    # the optimum as the lower bound, except that in the first half a state's worst
    # choice is made greedy by raising its successors' bounds
    lower = want.copy()
    p = a.matrix.toarray()
    score = p @ want[:na]
    owner = np.repeat(np.arange(na), np.diff(a.row_groups))
    loss = want[owner] - score
    loss[a.target[owner] | a.sink[owner]] = 0.0
    live = ~(a.target | a.sink)
    for c in np.argsort(-loss):  # a losing choice to live successors of its own
        succ, mine = np.flatnonzero(p[c] > 0), owner[c]
        others = [d for d in range(a.row_groups[mine], a.row_groups[mine + 1]) if d != c]
        if (loss[c] > 1e-3 and live[succ].all() and mine not in succ
                and not (p[others][:, succ] > 0).any()):
            break
    else:
        pytest.fail("no losing choice with live successors of its own")
    lower[succ] += 2.0 * loss[c] / p[c, succ].sum()
    it = interval_iteration(both, both.target, gap="max", progress=False)
    got = solve_lp(both, both.target, everywhere=True, bounds=(lower, it.upper))
    assert got.values is not None and got.status.value == "optimal"
    np.testing.assert_allclose(got.values, want, atol=1e-8)
    settled = int(re.search(r"(\d+) block states by the bounds' greedy policy",
                            got.message).group(1))
    assert 0 < settled
    assert re.search(r"[1-9]\d* block LP", got.message)
