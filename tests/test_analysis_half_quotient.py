"""The quotient :func:`~mitld_lp.solvers.analysis.analyse` builds, against a brute force
written with dense boolean matrices: which choices it keeps and their rows (read from
the maybe states' choice ranges and one copy of the kept rows), each row's one-step
probability of the target, the qualitative sets, the end components collapsed, and the
product's components and levels it keeps for the certificate.  Random MDPs of 3-9
states, with cycles and without, maxima and minima, with and without truncated states,
on the NumPy walks and on the compiled ones."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.mdp import MDP
from mitld_lp.solvers import walks
from mitld_lp.solvers.analysis import analyse
from mitld_lp.solvers.graph import Sense

SEEDS = range(24)


@pytest.fixture(params=["numpy", "compiled"])
def route(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> str:
    big = 0 if request.param == "compiled" else 10**12
    if request.param == "compiled":
        pytest.importorskip("numba")
    monkeypatch.setattr(walks, "COMPILED_LOADED_MIN_ENTRIES", big)
    monkeypatch.setattr(walks, "COMPILED_MIN_ENTRIES", big)
    return request.param


def _mdp(seed: int, acyclic: bool, truncated: bool) -> tuple[MDP, np.ndarray, np.ndarray]:
    """3-9 states; the last absorbing (the goal), with ``truncated`` the one before it
    absorbing too (the extra set); every other state 1-3 choices of 1-3 successors with
    random weights, only to higher states when ``acyclic`` (the absorbing states' loops
    are the only cycles), anywhere else.  A dense (choices x states) probability table
    beside it."""
    rng = np.random.default_rng(1000 + seed)
    n = int(rng.integers(3, 10))
    absorbing = 2 if truncated else 1
    table, owner = [], []
    for s in range(n):
        for _ in range(1 if s >= n - absorbing else int(rng.integers(1, 4))):
            row = np.zeros(n)
            if s >= n - absorbing:
                row[s] = 1.0
            else:
                low = s + 1 if acyclic else 0
                k = int(rng.integers(1, min(3, n - low) + 1))
                row[rng.choice(np.arange(low, n), k, replace=False)] = rng.random(k) + 0.05
                row /= row.sum()
            table.append(row)
            owner.append(s)
    dense = np.array(table)
    return as_mdp(dense, owner, truncated), dense, np.array(owner)


def as_mdp(dense: np.ndarray, owner: list[int], truncated: bool) -> MDP:
    """The MDP of a dense (choices x states) table whose choices' states are ``owner``
    (ascending): its last state the goal, with ``truncated`` the one before it the
    truncated set; both in ``target``."""
    n = dense.shape[1]
    groups = np.searchsorted(np.array(owner), np.arange(n + 1))
    goal = np.zeros(n, dtype=bool)
    goal[-1] = True
    extra = np.zeros(n, dtype=bool)
    if truncated:
        extra[-2] = True
    no = np.zeros(n, dtype=bool)
    return MDP(matrix=sp.csr_array(dense), row_groups=groups.astype(np.int64),
               choice_actions=np.zeros(len(owner), dtype=np.int32), action_names=(),
               initial=0, target=goal | extra, sink=no, truncated=extra, states=range(n))


def _closure(adj: np.ndarray) -> np.ndarray:
    """Reflexive transitive closure of a boolean adjacency matrix, by squaring."""
    r = adj | np.eye(adj.shape[0], dtype=bool)
    while True:
        nxt = (r.astype(int) @ r.astype(int)) > 0
        if np.array_equal(nxt, r):
            return r
        r = nxt


def _adjacency(support: np.ndarray, owner: np.ndarray, n: int) -> np.ndarray:
    adj = np.zeros((n, n), dtype=bool)
    for c in range(support.shape[0]):
        adj[owner[c]] |= support[c]
    return adj


def _prob1e(support: np.ndarray, owner: np.ndarray, target: np.ndarray) -> np.ndarray:
    """nu U. mu R. target | {s: a choice of s inside U that meets R}."""
    n = target.size
    u = np.ones(n, dtype=bool)
    while True:
        r = target.copy()
        while True:
            ok = ~(support & ~u).any(axis=1) & (support & r).any(axis=1)
            nxt = r | np.bincount(owner[ok], minlength=n).astype(bool)
            if np.array_equal(nxt, r):
                break
            r = nxt
        if np.array_equal(r, u):
            return u
        u = r


def _prob0e(support: np.ndarray, owner: np.ndarray, target: np.ndarray) -> np.ndarray:
    """nu Y. {s not a target: a choice of s with its support inside Y}."""
    y = ~target
    while True:
        inside = ~(support & ~y).any(axis=1)
        nxt = y & np.bincount(owner[inside], minlength=target.size).astype(bool)
        if np.array_equal(nxt, y):
            return y
        y = nxt


def _mecs(support: np.ndarray, owner: np.ndarray, among: np.ndarray
          ) -> tuple[set[frozenset[int]], np.ndarray]:
    """The maximal end components among ``among`` and their internal choices: choices
    kept while their support stays in their state's mutual-reach class among the states
    left, until nothing changes."""
    n = among.size
    alive = among.copy()
    allowed = alive[owner] & ~(support & ~alive).any(axis=1)
    while True:
        reach = _closure(_adjacency(support & allowed[:, None], owner, n))
        same = reach & reach.T
        stays = allowed & ~(support & ~same[owner]).any(axis=1)
        left = alive & np.bincount(owner[stays], minlength=n).astype(bool)
        stays &= left[owner] & ~(support & ~left).any(axis=1)
        if np.array_equal(stays, allowed) and np.array_equal(left, alive):
            break
        allowed, alive = stays, left
    classes = {frozenset(np.flatnonzero(same[s] & alive).tolist())
               for s in np.flatnonzero(alive)}
    return classes, allowed


def _levels(support: np.ndarray, owner: np.ndarray, n: int
            ) -> tuple[set[frozenset[int]], np.ndarray]:
    """The product's components (mutual reach) and each state's level: 0 for a class
    with no edge out of it, else one more than the highest class it has an edge to."""
    adj = _adjacency(support, owner, n)
    reach = _closure(adj)
    same = reach & reach.T
    level = np.full(n, -1)

    def of(s: int) -> int:
        if level[s] < 0:
            out = adj[same[s]].any(axis=0) & ~same[s]
            level[same[s]] = 1 + max((of(int(t)) for t in np.flatnonzero(out)), default=-1)
        return int(level[s])

    for s in range(n):
        of(s)
    return {frozenset(np.flatnonzero(same[s]).tolist()) for s in range(n)}, level


def _prob1a(support: np.ndarray, owner: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The states with no path, before the target, to a state of :func:`_prob0e`."""
    n = target.size
    z = _prob0e(support, owner, target)  # can reach, avoiding the target, where it may stay
    while True:
        nxt = z | (_adjacency(support, owner, n)[:, z].any(axis=1) & ~target)
        if np.array_equal(nxt, z):
            return ~z
        z = nxt


def _check(q, dense: np.ndarray, owner: np.ndarray, target: np.ndarray,
           maybe: np.ndarray, mecs: set[frozenset[int]], internal: np.ndarray,
           sure: np.ndarray) -> None:
    n = target.size
    state_map = np.asarray(q.state_map)
    found = {frozenset(np.flatnonzero(np.asarray(q.mecs.mec_of) == k).tolist())
             for k in range(q.mecs.n_mecs)}
    assert found == mecs
    assert np.array_equal(np.asarray(q.mecs.internal), internal)
    assert np.array_equal(state_map >= 0, maybe)
    # the kept choices: every choice of a maybe state that is not internal to an end
    # component, grouped by reduced state in the quotient's row groups
    origin = np.asarray(q.choice_origin)
    want = np.flatnonzero(maybe[owner] & ~internal)
    assert sorted(origin.tolist()) == want.tolist()
    groups = np.asarray(q.row_groups)
    red_of_row = np.repeat(np.arange(groups.size - 1), np.diff(groups))
    assert np.array_equal(state_map[owner[origin]], red_of_row)
    # each row: the product row's probabilities summed into reduced states, the removed
    # states dropped; its one-step probability of the target beside it
    got = np.asarray(q.matrix.todense())
    n_red = groups.size - 1
    for r, c in enumerate(origin):
        row = np.zeros(n_red)
        for t in range(n):
            if state_map[t] >= 0:
                row[state_map[t]] += dense[c, t]
        np.testing.assert_allclose(got[r], row, rtol=1e-14, atol=0)
        # the removed states of value 1 count as the target
        assert q.to_target[r] == pytest.approx(dense[c, target | sure].sum(), rel=1e-14,
                                               abs=0)
    assert q.matrix.nnz == int((got != 0).sum())  # no stored zero


def _check_lifted(support: np.ndarray, owner: np.ndarray, comp: np.ndarray,
                  comp_level: np.ndarray, state_map: np.ndarray) -> None:
    """The levels the NumPy route keeps: every edge between two components with a level
    goes down, and a component whose states all stay in the quotient has one."""
    n = comp.size
    level = comp_level[comp]
    adj = _adjacency(support, owner, n)
    for u, v in zip(*np.nonzero(adj), strict=True):
        if comp[u] != comp[v] and level[u] >= 0 and level[v] >= 0:
            assert level[u] > level[v], (u, v)
    for k in set(comp.tolist()):
        if bool(np.all(state_map[comp == k] >= 0)):
            assert comp_level[k] >= 0, k


@pytest.mark.parametrize("truncated", [False, True])
@pytest.mark.parametrize("acyclic", [False, True])
@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
def test_quotient_against_dense_brute_force(route: str, sense: Sense, acyclic: bool,
                                            truncated: bool) -> None:
    kinds = set()
    for seed in SEEDS:
        mdp, dense, owner = _mdp(seed, acyclic, truncated)
        n = mdp.n_states
        support = dense > 0
        goal = np.zeros(n, dtype=bool)
        goal[-1] = True
        extra = np.asarray(mdp.truncated)
        low, high = analyse(mdp, goal, extra, sense=sense)
        if not truncated:
            assert low is high
        classes, level = _levels(support, owner, n)
        comp, comp_level = (np.asarray(a) for a in low.layers)
        assert {frozenset(np.flatnonzero(comp == k).tolist()) for k in set(comp.tolist())} \
            == classes
        if route == "compiled":  # the product's levels, found by the walk at no cost
            assert np.array_equal(comp_level[comp], level)
        else:  # the quotient's, lifted: a layering where known (-1: not one of its)
            _check_lifted(support, owner, comp, comp_level, np.asarray(low.state_map))
        wide = goal | extra
        reach = _closure(_adjacency(support, owner, n))
        if sense is Sense.MAX:  # Prob1E of the goal (so of the wider one) removed too
            sure = _prob1e(support, owner, goal) & ~goal
            maybe = reach[:, wide].any(axis=1) & ~wide & ~sure
            mecs, internal = _mecs(support, owner, maybe)
        else:  # Prob1A of the goal (so of the wider target too) is removed as well
            sure = _prob1a(support, owner, goal) & ~goal
            maybe = ~_prob0e(support, owner, wide) & ~wide & ~sure
            mecs, internal = set(), np.zeros(owner.size, dtype=bool)
        kinds.add(bool(mecs))
        for q, target in ((low, goal), (high, wide)):
            _check(q, dense, owner, target, maybe, mecs, internal, sure)
            if sense is Sense.MAX:
                prob0 = ~reach[:, target].any(axis=1) & ~target
                one = _prob1e(support, owner, target)
            else:
                prob0 = _prob0e(support, owner, target)
                one = _prob1a(support, owner, target)
            assert np.array_equal(np.asarray(q.prob0), prob0)
            decided = q.qualitative
            assert np.array_equal(np.asarray(decided.zero), prob0)
            assert np.array_equal(np.asarray(decided.one), one)
            assert np.array_equal(np.asarray(decided.unreachable),
                                  ~reach[:, target].any(axis=1) & ~target)
            zero = np.zeros(q.row_groups.size - 1, dtype=bool)
            zero[np.asarray(q.state_map)[maybe & prob0]] = True
            assert np.array_equal(np.asarray(q.zero), zero)
    if sense is Sense.MAX and not acyclic and truncated:
        # some draws keep end components, some none (without a truncated state to lose
        # to, these draws' end components all have value 1 and leave the quotient)
        assert kinds == {False, True}
