"""The lifted policy in one compiled pass over the states
(:func:`~mitld_lp.solvers.lift_kernels.lift_states`, taken by
:func:`~mitld_lp.solvers.quotient.lift_policy` where no end component is collapsed),
checked against independent routes on random MDPs with end components, absorbing
goal, sink and truncated states, minima and maxima:

* the kernel's policy against the lift's rules written here state by state (a plain
  Python loop over the rows);
* :func:`lift_policy` with the compiled route forced against its NumPy route, to the bit;
* the LP's lifted policy of a minimum, evaluated here as a Markov chain (a linear solve
  of its own), equal to SciPy's LP optimum of Pmin (HiGHS), which the interval
  iteration's bracket holds.

The kernel is run as Python (its ``py_func``): no compiled cache is read or written."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.optimize import linprog

from mitld_lp.mdp import ABSORB, MDP
from mitld_lp.solvers import lift_kernels, quotient
from mitld_lp.solvers.analysis import analyse
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.iteration import interval_iteration
from mitld_lp.solvers.lp import solve_lp


def _mdp(rng: np.random.Generator, n: int, forward: bool = False,
         ) -> tuple[MDP, np.ndarray, np.ndarray]:
    """``n`` states: absorbing goal, sink and truncated states (an ``ABSORB`` self-loop
    each), the others 1-3 choices of 1-3 successors near them (cycles, so end
    components), some a choice that only loops; ``forward``: every successor of a
    higher id, the last state a goal (no end component among the others)."""
    kind = rng.choice(4, n, p=[0.9, 0.04, 0.03, 0.03])  # plain, goal, sink, truncated
    kind[0] = 0
    if forward:
        kind[-1] = 1
    rows, cols, vals, actions, groups = [], [], [], [], [0]
    c = 0
    for s in range(n):
        if kind[s]:
            rows.append(c), cols.append(s), vals.append(1.0), actions.append(ABSORB)
            c += 1
        else:
            for a in range(int(rng.integers(1, 4))):
                k = int(rng.integers(1, 4))
                if forward:
                    ts = sorted({min(s + int(d), n - 1) for d in rng.integers(1, 9, k)})
                elif rng.random() < 0.1:
                    ts = [s]  # a choice that stays put
                else:
                    ts = sorted({int((s + d) % n) for d in rng.integers(-4, 9, k)})
                for t in ts:
                    rows.append(c), cols.append(t), vals.append(1.0 / len(ts))
                actions.append(a)
                c += 1
        groups.append(c)
    matrix = sp.csr_array((vals, (rows, cols)), shape=(c, n))
    matrix.indices = matrix.indices.astype(np.int32)
    matrix.indptr = matrix.indptr.astype(np.int32)
    goal, extra = kind == 1, kind == 3
    mdp = MDP(matrix=matrix, row_groups=np.array(groups, dtype=np.int64),
              choice_actions=np.array(actions, dtype=np.int32), action_names=("a", "b", "c"),
              initial=0, target=goal | extra, sink=kind == 2, truncated=extra, states=range(n))
    return mdp, goal, extra


def _forced(monkeypatch: pytest.MonkeyPatch) -> None:
    """The compiled route taken whatever the size, load and cache (the kernel as Python)."""
    monkeypatch.setattr(quotient, "_lift_states_compiled", lambda *args: True)
    monkeypatch.setattr(lift_kernels, "lift_states_kernel",
                        lift_kernels.lift_states_kernel.py_func)


def _rules(mdp: MDP, q, reduced_choice: np.ndarray) -> np.ndarray:
    """The lift's rules (lift_policy's docs) state by state, -2 on a maximum's removed
    value-1 states (their strategy is checked apart)."""
    m, groups = mdp.matrix, mdp.row_groups
    zero, target = np.asarray(q.prob0), np.asarray(q.target)
    one, state_map = np.asarray(q.qualitative.one), np.asarray(q.state_map)
    out = []
    for s in range(mdp.n_states):
        first, last = int(groups[s]), int(groups[s + 1])
        absorbing = last - first == 1 and mdp.choice_actions[first] == ABSORB
        if state_map[s] >= 0:
            out.append(int(q.choice_origin[reduced_choice[state_map[s]]]))
        elif target[s] or absorbing:
            out.append(-1)
        elif q.sense is Sense.MAX and one[s]:
            out.append(-2)
        elif q.sense is Sense.MIN and zero[s]:
            stay = [c for c in range(first, last)
                    if all(zero[t] for t, p in zip(m.indices[m.indptr[c]:m.indptr[c + 1]],
                                                   m.data[m.indptr[c]:m.indptr[c + 1]],
                                                   strict=True) if p > 0)]
            out.append(stay[0] if stay else first)
        else:
            out.append(first)
    return np.array(out, dtype=np.int64)


CASES = [(seed, sense, truncated, forward) for seed in range(3)
         for sense in (Sense.MIN, Sense.MAX) for truncated in (False, True)
         for forward in (False, True)]


@pytest.mark.parametrize(("seed", "sense", "truncated", "forward"), CASES)
def test_compiled_lift_is_the_rules_and_the_numpy_route(monkeypatch, seed: int, sense: Sense,
                                                         truncated: bool, forward: bool) -> None:
    rng = np.random.default_rng(8500 + seed)
    mdp, goal, extra = _mdp(rng, 400, forward)
    if not truncated:
        extra[:] = False
    taken = 0
    for q in analyse(mdp, goal, extra, sense=sense):
        n_red = int(q.row_groups.shape[0] - 1)
        groups = np.asarray(q.row_groups)
        reduced_choice = groups[:-1] + rng.integers(0, 1 << 20, n_red) % np.maximum(
            np.diff(groups), 1)
        before = quotient.lift_policy(mdp, q, reduced_choice)
        with monkeypatch.context() as patch:
            _forced(patch)
            after = quotient.lift_policy(mdp, q, reduced_choice)
        assert after.dtype == before.dtype == np.int64
        assert np.array_equal(after, before)
        if q.mecs.n_mecs:  # the NumPy route either way
            continue
        taken += 1
        want = _rules(mdp, q, reduced_choice)
        free = want == -2
        assert np.array_equal(after[~free], want[~free])
        # a maximum's removed value-1 states: a choice of their own, never leaving them
        # and the target (every successor of positive probability among them)
        keep = np.asarray(q.qualitative.one) | np.asarray(q.target)
        for s in np.flatnonzero(free):
            c = int(after[s])
            assert mdp.row_groups[s] <= c < mdp.row_groups[s + 1]
            assert keep[mdp.matrix.indices[mdp.matrix.indptr[c]:mdp.matrix.indptr[c + 1]]].all()
    if sense is Sense.MIN or forward:
        assert taken  # none collapsed: the compiled route was checked


def _chain_value(mdp: MDP, policy: np.ndarray, goal: np.ndarray) -> float:
    """The probability of reaching ``goal`` from the initial state under ``policy``
    (-1: the state is absorbing or the goal): the states that reach the goal in the
    chain, found by a fixpoint here, solved by one sparse linear system."""
    n = mdp.n_states
    dense = mdp.matrix.toarray()
    step = np.zeros((n, n))
    for s in range(n):
        if policy[s] >= 0 and not goal[s]:
            step[s] = dense[policy[s]]
    reach = goal.copy()
    grew = True
    while grew:
        grew = False
        for s in np.flatnonzero(~reach):
            if (step[s][reach] > 0).any():
                reach[s] = grew = True
    free = np.flatnonzero(reach & ~goal)
    a = np.eye(free.size) - step[np.ix_(free, free)]
    b = step[np.ix_(free, np.flatnonzero(goal))].sum(axis=1)
    x = np.linalg.solve(a, b) if free.size else np.zeros(0)
    init = int(mdp.initial)
    return 1.0 if goal[init] else (float(x[np.searchsorted(free, init)]) if reach[init] else 0.0)


def _min_lp(mdp: MDP, goal: np.ndarray) -> float:
    """Pmin of reaching ``goal`` by SciPy's LP (HiGHS): the largest ``sum x`` with ``x <= P
    x + P(goal)`` a choice on the states every policy reaches the goal from with
    positive probability (their set grown here, whole rounds of a dense matrix until
    none joins), 0 elsewhere; the constraints built as whole matrices."""
    dense, g = mdp.matrix.toarray(), np.asarray(mdp.row_groups)
    n = mdp.n_states
    owner = np.repeat(np.arange(n), np.diff(g))
    attract = goal.copy()
    while True:
        hit = dense[:, attract].sum(axis=1) > 0  # each choice: an entry into the set
        missed = np.bincount(owner, weights=~hit, minlength=n) == 0
        grown = attract | (missed & (np.diff(g) > 0))
        if np.array_equal(grown, attract):
            break
        attract = grown
    free = np.flatnonzero(attract & ~goal)
    init = int(mdp.initial)
    if not free.size:
        return 1.0 if goal[init] else 0.0
    rows = np.flatnonzero(np.isin(owner, free))
    a_ub = (owner[rows][:, None] == free[None, :]).astype(float) - dense[np.ix_(rows, free)]
    b_ub = dense[np.ix_(rows, np.flatnonzero(goal))].sum(axis=1)
    got = linprog(-np.ones(free.size), A_ub=a_ub, b_ub=b_ub, bounds=(0, 1), method="highs")
    assert got.status == 0
    if goal[init]:
        return 1.0
    return float(got.x[np.searchsorted(free, init)]) if attract[init] else 0.0


@pytest.mark.parametrize("seed", [0, 3, 5])
def test_lifted_minimum_is_optimal_and_bracketed(monkeypatch, seed: int) -> None:
    """Forward MDPs (no state avoids the goal by staying put), seeds whose Pmin is
    neither 0 nor 1."""
    rng = np.random.default_rng(8580 + seed)
    mdp, goal, _ = _mdp(rng, 150, forward=True)
    _forced(monkeypatch)
    exact = _min_lp(mdp, goal)
    assert 0.0 < exact < 1.0
    lp = solve_lp(mdp, goal, sense=Sense.MIN, progress=False)
    assert abs(_chain_value(mdp, lp.policy, goal) - exact) <= 1e-7
    got = interval_iteration(mdp, goal, sense=Sense.MIN, progress=False)
    assert got.value_lower - 1e-9 <= exact <= got.value_upper + 1e-9


def test_lift_states_kernel_small_case_by_hand() -> None:
    """Three states: 0 of the quotient (its reduced choice 1 is product choice 2), 1 a
    prob-0 state whose first choice leaves zero and second stays, 2 the target."""
    groups = np.array([0, 2, 4, 5], dtype=np.int64)
    m = sp.csr_array((np.array([1.0, 0.5, 0.5, 1.0, 1.0, 1.0]),
                      np.array([1, 0, 2, 2, 1, 2], dtype=np.int32),
                      np.array([0, 1, 3, 4, 5, 6], dtype=np.int32)), shape=(5, 3))
    zero = np.array([False, True, False])
    ends = np.array([False, False, True])
    state_map = np.array([0, -1, -1], dtype=np.int32)
    chosen = np.array([1], dtype=np.int32)
    kernel = lift_kernels.lift_states_kernel.py_func
    for search, want in ((True, [1, 3, -1]), (False, [1, 2, -1])):
        policy = np.full(3, -7, dtype=np.int64)
        kernel(groups, m.indptr, m.indices, m.data, zero, search, state_map, chosen, ends,
               policy)
        assert policy.tolist() == want


@pytest.mark.parametrize("wide", ["indices", "indptr", "state_map"])
def test_a_wide_index_array_keeps_the_numpy_route(monkeypatch, wide: str) -> None:
    """The kernel is compiled for int32 index arrays only: an int64 one (the matrix's
    indices or pointers, or the state map) takes the NumPy route, never a compile in a
    solve; with all int32 the gate asks the cache."""
    rng = np.random.default_rng(8599)
    mdp, goal, _ = _mdp(rng, 1500, forward=True)
    q = analyse(mdp, goal, sense=Sense.MIN)[0]
    chosen = np.asarray(q.choice_origin)[np.asarray(q.row_groups)[:-1]]
    monkeypatch.setattr(quotient.kernel_loader, "compiled_paid", lambda: True)
    monkeypatch.setattr(quotient, "LIFT_KERNEL_MIN_STATES", 1)
    monkeypatch.setattr(quotient, "_LIFT_STATES_WARM", [True])
    assert chosen.dtype == np.int32 and np.asarray(q.state_map).dtype == np.int32
    assert quotient._lift_states_compiled(mdp, q, chosen)
    m = sp.csr_array(mdp.matrix, copy=True)
    if wide == "state_map":
        q = type(q)(**{**{f: getattr(q, f) for f in q.__dataclass_fields__},
                       "state_map": np.asarray(q.state_map).astype(np.int64)})
    else:
        setattr(m, wide, getattr(m, wide).astype(np.int64))
        mdp = MDP(matrix=m, row_groups=mdp.row_groups, choice_actions=mdp.choice_actions,
                  action_names=mdp.action_names, initial=mdp.initial, target=mdp.target,
                  sink=mdp.sink, truncated=mdp.truncated, states=mdp.states)
    assert not quotient._lift_states_compiled(mdp, q, chosen)
