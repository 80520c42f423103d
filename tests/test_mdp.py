"""Graph analyses of mitld_lp.mdp checked against hand results and a naive reference."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import HAND, build_mdp

from mitld_lp.mdp import ABSORB, MDP
from mitld_lp.solvers.quotient import maximal_end_components, prob0_max, prob1_max, reduce
from mitld_lp.testing import random_mdp

# HAND (tests/conftest.py): 0 loops or goes; {1, 4} a MEC; 2 sink, 3 target; 5 -> sink
# only (prob 0, not absorbing); 6 reaches the target with probability 1 by looping.


def mask(n: int, idx: list[int]) -> np.ndarray:
    out = np.zeros(n, dtype=bool)
    out[idx] = True
    return out


def test_build_mdp_layout() -> None:
    assert HAND.n_states == 7
    assert HAND.n_choices == 11
    assert HAND.row_groups.tolist() == [0, 2, 4, 5, 6, 8, 9, 11]
    assert HAND.choice_actions[4] == ABSORB and HAND.action_name(4) == "absorb"
    assert HAND.action_name(3) == "b"
    np.testing.assert_allclose(HAND.matrix.sum(axis=1), 1.0)


def test_build_mdp_rejects_bad_input() -> None:
    with pytest.raises(ValueError, match="not a distribution"):
        build_mdp([[("a", {0: 0.5})]])
    with pytest.raises(ValueError, match="no choices"):
        build_mdp([[]])
    with pytest.raises(ValueError, match="no state 3"):
        build_mdp([[("a", {3: 1.0})]])


def test_prob0_prob1_by_hand() -> None:
    assert np.flatnonzero(prob0_max(HAND, HAND.target)).tolist() == [2, 5]
    # 0 cannot avoid the sink (go) or stays forever; 1,4 reach 3 or fall in 2 or 0.
    assert np.flatnonzero(prob1_max(HAND, HAND.target)).tolist() == [3, 6]


def test_prob_masks_are_checked() -> None:
    with pytest.raises(ValueError, match="bool mask"):
        prob0_max(HAND, np.array([3]))


def test_mecs_by_hand() -> None:
    ecs = maximal_end_components(HAND, ~HAND.target & ~HAND.sink)
    groups = {frozenset(ecs.states_of(k).tolist()) for k in range(ecs.n_mecs)}
    # {5} has no choice that stays; {6} keeps nothing (f leaves to the target).
    assert groups == {frozenset({0}), frozenset({1, 4})}
    assert np.flatnonzero(ecs.internal).tolist() == [0, 3, 6]
    k = int(ecs.mec_of[1])
    assert ecs.choices_of(k, HAND).tolist() == [3, 6]


def test_mecs_of_whole_mdp_include_absorbing() -> None:
    ecs = maximal_end_components(HAND, np.ones(7, dtype=bool))
    groups = {frozenset(ecs.states_of(k).tolist()) for k in range(ecs.n_mecs)}
    # 6 -> 3 cannot come back, so 6 is in none.
    assert groups == {frozenset({0}), frozenset({1, 4}), frozenset({2}), frozenset({3})}


def test_reduce_by_hand() -> None:
    q = reduce(HAND, HAND.target)
    assert q.prob0.tolist() == mask(7, [2, 5]).tolist()
    assert q.n_states == 3  # state 6, MEC {0}, MEC {1, 4}
    assert q.n_plain == 1 and q.state_map[6] == 0
    assert q.state_map[1] == q.state_map[4] != q.state_map[0]
    # Kept choices: go (1), a (2), d (7), f (9), g (10); stay, b, c are internal.
    assert sorted(q.choice_origin.tolist()) == [1, 2, 7, 9, 10]
    row = {int(c): r for r, c in enumerate(q.choice_origin)}
    dense = q.matrix.toarray()
    m0, m14 = q.state_map[0], q.state_map[1]
    assert dense[row[1], m14] == pytest.approx(0.5)
    assert dense[row[2], m0] == pytest.approx(0.7)
    assert q.to_target[row[2]] == pytest.approx(0.3)
    assert dense[row[9], q.state_map[6]] == pytest.approx(0.5)
    assert dense[row[10]].sum() == 0 and q.to_target[row[10]] == 0  # all mass to prob-0
    assert q.initial == m0
    lifted = q.lift(np.array([0.25, 0.5, 0.75]))
    assert lifted[[2, 3, 5]].tolist() == [0.0, 1.0, 0.0]
    assert lifted[1] == lifted[4]


# ------------------------------------------------------------------------------------
# A naive reference: Python sets and dicts, one state at a time.
# ------------------------------------------------------------------------------------


def succ_lists(mdp: MDP) -> list[list[set[int]]]:
    dense = mdp.matrix.toarray()
    return [
        [set(np.flatnonzero(dense[c] > 0).tolist()) for c in mdp.choices(s)]
        for s in range(mdp.n_states)
    ]


def naive_prob0(mdp: MDP, target: np.ndarray) -> set[int]:
    succ = succ_lists(mdp)
    good = set(np.flatnonzero(target).tolist())
    changed = True
    while changed:
        changed = False
        for s in range(mdp.n_states):
            if s not in good and any(post & good for post in succ[s]):
                good.add(s)
                changed = True
    return set(range(mdp.n_states)) - good


def naive_prob1(mdp: MDP, target: np.ndarray) -> set[int]:
    succ = succ_lists(mdp)
    t = set(np.flatnonzero(target).tolist())
    r = set(range(mdp.n_states))
    while True:
        y = set(t)
        changed = True
        while changed:
            changed = False
            for s in range(mdp.n_states):
                if s not in y and any(post <= r and post & y for post in succ[s]):
                    y.add(s)
                    changed = True
        if y == r:
            return r
        r = y


def naive_mecs(mdp: MDP, states: set[int]) -> set[frozenset[int]]:
    """Refinement with SCCs from a transitive closure (Warshall), per state in Python."""
    succ = succ_lists(mdp)
    allowed = {s: [i for i, post in enumerate(succ[s]) if post <= states] for s in states}
    live = set(states)
    while True:
        while True:  # drop states without choices and choices leaving, to a fixpoint
            smaller = {s for s in live if allowed[s]}
            for s in smaller:
                allowed[s] = [i for i in allowed[s] if succ[s][i] <= smaller]
            if smaller == live and all(allowed[s] for s in live):
                break
            live = smaller
        edges = {s: set().union(*(succ[s][i] for i in allowed[s])) for s in live}
        reach: dict[int, set[int]] = {}
        for s in live:  # depth-first search from each state
            seen, todo = {s}, [s]
            while todo:
                for t in edges[todo.pop()]:
                    if t not in seen:
                        seen.add(t)
                        todo.append(t)
            reach[s] = seen
        scc = {s: frozenset(t for t in reach[s] if s in reach.get(t, set())) for s in live}
        changed = False
        for s in live:
            keep = [i for i in allowed[s] if succ[s][i] <= scc[s]]
            if keep != allowed[s]:
                allowed[s] = keep
                changed = True
        if not changed and all(allowed[s] for s in live):
            return {scc[s] for s in live}


@pytest.mark.parametrize("seed", range(12))
def test_graph_analyses_match_naive_reference(seed: int) -> None:
    n = 10 + 3 * seed
    mdp = random_mdp(n, seed=seed, target_fraction=0.1, sink_fraction=0.1,
                     self_loop_fraction=0.25, max_successors=3,
                     locality=None if seed % 2 else 3)
    target = mdp.target
    assert set(np.flatnonzero(prob0_max(mdp, target)).tolist()) == naive_prob0(mdp, target)
    assert set(np.flatnonzero(prob1_max(mdp, target)).tolist()) == naive_prob1(mdp, target)
    maybe = ~target & ~prob0_max(mdp, target)
    ecs = maximal_end_components(mdp, maybe)
    got = {frozenset(ecs.states_of(k).tolist()) for k in range(ecs.n_mecs)}
    assert got == naive_mecs(mdp, set(np.flatnonzero(maybe).tolist()))
    # Internal choices: exactly those of MEC states whose support stays in the MEC.
    dense = mdp.matrix.toarray()
    owner = mdp.choice_state()
    for c in range(mdp.n_choices):
        k = ecs.mec_of[owner[c]]
        stays = k >= 0 and set(np.flatnonzero(dense[c] > 0)) <= set(ecs.states_of(k))
        assert bool(ecs.internal[c]) == bool(stays)


@pytest.mark.parametrize("seed", range(8))
def test_quotient_has_no_end_components(seed: int) -> None:
    mdp = random_mdp(60, seed=seed, self_loop_fraction=0.3, locality=4)
    q = reduce(mdp, mdp.target)
    n = q.n_states
    # Close the quotient with one absorbing 'gone' state taking the missing mass.
    rows = sp.csr_array(q.matrix).toarray()
    gone = 1.0 - rows.sum(axis=1)
    assert np.all(gone >= q.to_target - 1e-12)
    closed = np.hstack([rows, gone[:, None]])
    closed = np.vstack([closed, np.eye(1, n + 1, n)])
    groups = np.concatenate([q.row_groups, [q.row_groups[-1] + 1]])
    quotient_mdp = MDP(
        matrix=sp.csr_array(closed), row_groups=groups,
        choice_actions=np.zeros(closed.shape[0], dtype=np.int32), action_names=("x",),
        initial=0, target=np.eye(1, n + 1, n, dtype=bool)[0],
        sink=np.zeros(n + 1, dtype=bool), truncated=np.zeros(n + 1, dtype=bool),
        states=tuple(range(n + 1)),
    )
    inner = np.ones(n + 1, dtype=bool)
    inner[n] = False
    assert maximal_end_components(quotient_mdp, inner).n_mecs == 0


def test_unique_is_numpys_unique():
    from mitld_lp.util.arrays import unique

    rng = np.random.default_rng(3)
    for size in (0, 1, 7, 1000):
        a = rng.integers(-5, 20, size=size)
        np.testing.assert_array_equal(unique(a), np.unique(a))
