"""The lean lift of a quotient's policy and its neighbours (branch csma-mem) against
brute force written otherwise, on small random MDPs with end components, absorbing
states, stored zeros, for a minimum and a maximum:

* ``absorbing_states`` (read from the ``ABSORB`` choices) against a loop over every
  state's choices and their action names, an ``ABSORB`` choice beside another choice
  included (not absorbing);
* ``first_staying`` (a slice of states at a time, views of the rows) against a loop
  over each state's choices and their stored entries, a stored zero leading out
  included (no edge);
* ``lift_policy`` (written in place, a slice at a time): every state's choice is its
  own, -1 exactly on the target and the absorbing states, a minimum's prob-0 states
  stay among them, and the lifted policy's value, solved on the product by dense
  linear algebra, equals the quotient policy's value solved on the quotient and
  lifted, at every state (end components, removed states of value 1 and prob-0 states
  included), with the analysis's recorded attractor strategy and with the one searched
  when it is absent;
* ``quotient_order.staying`` (each choice's self-loop, a slice of states at a time)
  against a loop adding each row's entries in its own column, to the bit;
* ``EndComponents.none`` (stride-0 views) against a search that finds no end
  component, and a minimum's analysis holding it: the same answers to the bit.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import build_mdp

from mitld_lp.mdp import ABSORB, absorbing_states
from mitld_lp.solvers import quotient as quotient_mod
from mitld_lp.solvers.analysis import analyse
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.quotient import first_staying, lift_policy, reduce
from mitld_lp.solvers.value_one import ATTRACTOR_STRATEGY


def random_mdp(seed: int, n: int = 36):
    """Random choices among ``n`` states: some stay among a state and its two
    neighbours (end components), some go to a trap of two states that loop (``n``,
    ``n + 1``: a minimum avoids the goal there), some to two states from which every
    policy reaches the goal (``n + 2``, ``n + 3``: a minimum's value 1); the goal
    ``n + 4``, a dead end ``n + 5``."""
    rng = np.random.default_rng(seed)
    trap, sure, goal, dead = n, n + 2, n + 4, n + 5
    states = []
    for s in range(n):
        mine = []
        for a in range(int(rng.integers(1, 4))):
            u = rng.random()
            if u < 0.3:  # cycles among s and its neighbours
                succ = sorted({s, (s + 1) % n, (s + 2) % n})
            elif u < 0.4:  # into the trap, or on to the goal
                succ = sorted({trap, goal} if rng.random() < 0.3 else {trap})
            elif u < 0.5:  # into the states sure to reach it
                succ = sorted({sure, sure + 1})
            else:
                succ = sorted(set(rng.choice(n + 6, size=3).tolist()))
            w = rng.integers(1, 9, size=len(succ)).astype(float)
            p = w / w.sum()
            row = {int(t): float(x) for t, x in zip(succ, p, strict=True)}
            row[succ[-1]] += 1.0 - sum(row.values())
            mine.append((f"a{a}", row))
        states.append(mine)
    states.append([("t", {trap + 1: 1.0})])
    states.append([("t", {trap: 1.0}), ("u", {trap: 0.5, goal: 0.5})])
    states.append([("a", {goal: 1.0}), ("b", {sure + 1: 0.5, goal: 0.5})])
    states.append([("a", {sure: 1.0}), ("b", {sure: 0.25, goal: 0.75})])
    states += [[], []]
    return build_mdp(states, target=[goal], sink=[dead])


def with_zeros(mdp, seed: int):
    """``mdp`` with a stored zero in some rows, in a column the row does not reach (no
    edge: every analysis ignores it)."""
    rng = np.random.default_rng(seed)
    m = sp.csr_array(mdp.matrix)
    rows, cols, vals = [], [], []
    for c in range(m.shape[0]):
        lo, hi = m.indptr[c], m.indptr[c + 1]
        have = set(m.indices[lo:hi].tolist())
        rows += [c] * (hi - lo)
        cols += m.indices[lo:hi].tolist()
        vals += m.data[lo:hi].tolist()
        free = [t for t in range(mdp.n_states) if t not in have]
        if free and rng.random() < 0.4:
            rows.append(c)
            cols.append(int(rng.choice(free)))
            vals.append(0.0)
    coo = sp.coo_array((vals, (rows, cols)), shape=m.shape)
    stored = sp.csr_array((coo.data, (coo.row, coo.col)), shape=m.shape)
    stored.sort_indices()
    assert stored.nnz > m.nnz and np.any(stored.data == 0.0)
    return replace(mdp, matrix=stored)


@pytest.fixture(scope="module")
def mdps():
    out = [random_mdp(seed) for seed in range(6)]
    out += [with_zeros(random_mdp(seed), seed) for seed in range(6, 9)]
    return out


def _choice_list(mdp, s: int) -> list[int]:
    return [int(c) for c in range(int(mdp.row_groups[s]), int(mdp.row_groups[s + 1]))]


def test_absorbing_states_is_the_loop_over_the_choices(mdps) -> None:
    rng = np.random.default_rng(1)
    for mdp in mdps:
        actions = np.asarray(mdp.choice_actions).copy()
        # an ABSORB label on some choice of a state with other choices: not absorbing
        many = [s for s in range(mdp.n_states) if len(_choice_list(mdp, s)) > 1]
        for s in rng.choice(many, size=3, replace=False):
            actions[_choice_list(mdp, int(s))[-1]] = ABSORB
        odd = replace(mdp, choice_actions=actions)
        for model in (mdp, odd):
            want = np.array([len(_choice_list(model, s)) == 1
                             and model.action_name(_choice_list(model, s)[0]) == "absorb"
                             for s in range(model.n_states)])
            got = absorbing_states(model)
            assert got.dtype == np.bool_ and got.shape == (model.n_states,)
            assert np.array_equal(got, want)
        assert absorbing_states(mdp).sum() == 2  # the goal and the dead end


def staying_by_loop(mdp, inside: np.ndarray, s: int) -> int:
    m = sp.csr_array(mdp.matrix)
    for c in _choice_list(mdp, s):
        lo, hi = m.indptr[c], m.indptr[c + 1]
        if all(inside[t] for t, p in zip(m.indices[lo:hi], m.data[lo:hi], strict=True)
               if p > 0):
            return c
    return _choice_list(mdp, s)[0]


def test_first_staying_is_the_loop_over_the_rows(mdps, monkeypatch) -> None:
    rng = np.random.default_rng(2)
    later = none = 0  # picks past the first choice; states where no choice stays
    for mdp in mdps:
        for _ in range(4):
            inside = rng.random(mdp.n_states) < 0.6
            lo = int(rng.integers(0, mdp.n_states // 2))
            hi = int(rng.integers(lo + 1, mdp.n_states + 1))
            want = [staying_by_loop(mdp, inside, s) for s in range(lo, hi)]
            assert np.array_equal(first_staying(mdp, inside, lo, hi), want)
            with monkeypatch.context() as m:  # several slices, one state each at least
                m.setattr(quotient_mod, "SLICE_STATES", 3)
                assert np.array_equal(first_staying(mdp, inside, lo, hi), want)
            every = [staying_by_loop(mdp, inside, s) for s in range(mdp.n_states)]
            assert np.array_equal(first_staying(mdp, inside), every)
            later += int(np.count_nonzero(np.asarray(want) != mdp.row_groups[lo:hi]))
            none += sum(not _stays(mdp, inside, _choice_list(mdp, s)[0])
                        and staying_by_loop(mdp, inside, s) == _choice_list(mdp, s)[0]
                        for s in range(lo, hi))
    assert later > 0 and none > 0  # the test tells the cases apart


def _stays(mdp, inside: np.ndarray, c: int) -> bool:
    m = sp.csr_array(mdp.matrix)
    lo, hi = m.indptr[c], m.indptr[c + 1]
    return all(inside[t] for t, p in zip(m.indices[lo:hi], m.data[lo:hi], strict=True)
               if p > 0)


def _policy_values(mdp, policy: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The probability of reaching ``target`` under a deterministic ``policy`` (-1:
    the state is absorbing or a target), by a dense linear solve over the states with
    a path to the target (the others 0), found by repeated steps of the chain."""
    n = mdp.n_states
    m = sp.csr_array(mdp.matrix).toarray()
    p = np.zeros((n, n))
    for s in range(n):
        if policy[s] >= 0 and not target[s]:
            p[s] = m[policy[s]]
    reach = target.copy()
    while True:
        more = reach | ((p > 0) @ reach.astype(float) > 0)
        if np.array_equal(more, reach):
            break
        reach = more
    solve = reach & ~target
    x = np.where(target, 1.0, 0.0)
    a = np.eye(int(solve.sum())) - p[np.ix_(solve, solve)]
    b = p[np.ix_(solve, target)].sum(axis=1)
    x[solve] = np.linalg.solve(a, b)
    return x


def _quotient_values(q, choice: np.ndarray) -> np.ndarray:
    """The quotient policy ``choice``'s values on the quotient (no end component: the
    chain is transient), dense."""
    rows = q.matrix.toarray()[choice]
    return np.linalg.solve(np.eye(q.n_states) - rows, q.to_target[choice])


def _quotients(mdp):
    for sense in (Sense.MAX, Sense.MIN):
        yield analyse(mdp, mdp.target, sense=sense)[0]
        yield reduce(mdp, mdp.target, sense=sense)


def _check_lift(mdp, q, choice: np.ndarray) -> None:
    policy = lift_policy(mdp, q, choice)
    assert policy.dtype == np.int64 and policy.shape == (mdp.n_states,)
    ends = np.array([len(_choice_list(mdp, s)) == 1
                     and int(mdp.choice_actions[_choice_list(mdp, s)[0]]) == ABSORB
                     for s in range(mdp.n_states)])
    assert np.array_equal(policy < 0, mdp.target | ends)
    for s in np.flatnonzero(policy >= 0):
        assert int(policy[s]) in _choice_list(mdp, int(s))
    if q.sense is Sense.MIN:  # prob-0: a choice that stays among them where one does
        for s in np.flatnonzero(q.prob0 & ~ends):
            assert policy[s] == staying_by_loop(mdp, q.prob0, int(s))
    want = q.lift(_quotient_values(q, choice)) if q.n_states else q.lift(np.zeros(0))
    got = _policy_values(mdp, policy, mdp.target)
    assert np.allclose(got, want, rtol=1e-9, atol=1e-12)
    removed = q.state_map < 0
    assert np.allclose(got[removed], np.where(q.qualitative.one, 1.0, 0.0)[removed],
                       rtol=0.0, atol=1e-12)


def test_lift_policy_achieves_the_quotient_policy_value(mdps) -> None:
    rng = np.random.default_rng(3)
    seen = {"mecs": 0, "prob0_min": 0, "one_max": 0, "one_min": 0}
    for mdp in mdps:
        for q in _quotients(mdp):
            seen["mecs"] += q.mecs.n_mecs
            removed_one = np.asarray(q.qualitative.one) & (q.state_map < 0) & ~q.target
            if q.sense is Sense.MIN:
                seen["prob0_min"] += int(q.prob0.sum())
                seen["one_min"] += int(removed_one.sum())
            else:
                seen["one_max"] += int(removed_one.sum())
            for _ in range(3):
                choice = np.array([rng.integers(q.row_groups[r], q.row_groups[r + 1])
                                   for r in range(q.n_states)], dtype=np.int64)
                _check_lift(mdp, q, choice)
    assert all(v > 0 for v in seen.values()), seen


def test_lift_policy_searches_the_attractor_when_none_is_recorded(mdps) -> None:
    rng = np.random.default_rng(4)
    searched = 0
    for mdp in mdps:
        q = analyse(mdp, mdp.target, sense=Sense.MAX)[0]
        choice = np.array([rng.integers(q.row_groups[r], q.row_groups[r + 1])
                           for r in range(q.n_states)], dtype=np.int64)
        recorded = lift_policy(mdp, q, choice)
        if q.shared.pop(ATTRACTOR_STRATEGY, None) is None:
            continue
        searched += 1
        _check_lift(mdp, q, choice)  # searched now, kept in shared
        again = lift_policy(mdp, q, choice)
        _check_lift(mdp, q, choice)
        assert np.array_equal(again[q.state_map >= 0], recorded[q.state_map >= 0])
    assert searched > 0


def test_lift_policy_in_slices_is_the_whole(mdps, monkeypatch) -> None:
    rng = np.random.default_rng(5)
    for mdp in mdps:
        for q in _quotients(mdp):
            choice = np.array([rng.integers(q.row_groups[r], q.row_groups[r + 1])
                               for r in range(q.n_states)], dtype=np.int64)
            whole = lift_policy(mdp, q, choice)
            with monkeypatch.context() as m:
                m.setattr(quotient_mod, "SLICE_STATES", 5)
                assert np.array_equal(lift_policy(mdp, q, choice), whole)


def test_staying_is_the_loop_over_the_entries(mdps, monkeypatch) -> None:
    """``quotient_order.staying`` (a slice of states at a time) against a loop adding
    each row's entries in its own state's column, in their order (the same sums, to
    the bit), on the quotients (self-loops on collapsed end components) and on the
    products themselves."""
    from mitld_lp.solvers import quotient_order

    def by_loop(matrix, row_groups):
        m = sp.csr_array(matrix)
        out = []
        for s in range(row_groups.size - 1):
            for c in range(int(row_groups[s]), int(row_groups[s + 1])):
                total = 0.0
                for j in range(m.indptr[c], m.indptr[c + 1]):
                    if m.indices[j] == s:
                        total += float(m.data[j])
                out.append(total)
        return np.asarray(out)

    loops = 0
    for mdp in mdps:
        pairs = [(q.matrix, np.asarray(q.row_groups)) for q in _quotients(mdp)]
        pairs.append((mdp.matrix, np.asarray(mdp.row_groups)))
        for matrix, groups in pairs:
            want = by_loop(matrix, groups)
            loops += int(np.count_nonzero(want))
            assert np.array_equal(quotient_order.staying(sp.csr_array(matrix), groups), want)
            with monkeypatch.context() as m:
                m.setattr(quotient_order, "SLICE_STATES", 4)
                assert np.array_equal(
                    quotient_order.staying(sp.csr_array(matrix), groups), want)
    assert loops > 0


def test_no_end_components_record_is_stride_zero_and_answers_alike(mdps, monkeypatch
                                                                   ) -> None:
    """``EndComponents.none``: the values of a search that finds no end component
    (``maximal_end_components`` over no state), nothing allocated a state or a choice;
    and a minimum's analysis holding it in place of its materialised record gives the
    same quotient, LP, iteration and lifted policy to the bit."""
    from mitld_lp.solvers import analysis
    from mitld_lp.solvers.end_components import EndComponents, maximal_end_components
    from mitld_lp.solvers.iteration import interval_iteration
    from mitld_lp.solvers.lp import solve_lp

    for mdp in mdps[:4]:
        none = EndComponents.none(mdp.n_states, mdp.n_choices)
        found = maximal_end_components(mdp, np.zeros(mdp.n_states, dtype=bool))
        assert none.n_mecs == found.n_mecs == 0
        assert np.array_equal(none.mec_of, found.mec_of)
        assert np.array_equal(none.internal, found.internal)
        assert none.mec_of.dtype == np.int32 and none.internal.dtype == np.bool_
        assert none.mec_of.strides == (0,) and none.internal.strides == (0,)
        assert not none.mec_of.flags.writeable and not none.internal.flags.writeable

    def answers(mdp):
        q = analysis.analyse(mdp, mdp.target, sense=Sense.MIN)[0]
        lp = solve_lp(mdp, mdp.target, quotient=q, sense=Sense.MIN, everywhere=True)
        it = interval_iteration(mdp, mdp.target, quotient=q, sense=Sense.MIN)
        choice = np.asarray(q.row_groups[:-1], dtype=np.int64)
        return (q.state_map, q.choice_origin, q.matrix.toarray(), q.to_target,
                lp.values, lp.policy, it.lower, it.upper, lift_policy(mdp, q, choice))

    for mdp in mdps:
        made = answers(mdp)
        with monkeypatch.context() as m:
            m.setattr(analysis, "_no_end_components", EndComponents.none)
            views = answers(mdp)
            held = analysis.analyse(mdp, mdp.target, sense=Sense.MIN)[0].mecs
            assert held.mec_of.strides == (0,)  # the record held is the views
        for a, b in zip(made, views, strict=True):
            assert a.dtype == b.dtype and np.array_equal(a, b)
