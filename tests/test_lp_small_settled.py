"""The LP stage on quotients of single states (acyclic up to self-loops, as a deadline
makes them), where :func:`mitld_lp.solvers.settled_levels.settled_by_bounds` takes the
level walk's answer from the iteration's bounds: its policy's value against independent
routes (scipy's linprog on the occupancy LP written here, exact backward induction in
fractions, a dense solve of the policy's chain), and the shortcut forced on and off
giving the same policy and values to the bit, with sound, wrong and open bounds."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.optimize import linprog

from mitld_lp.mdp import ABSORB, MDP
from mitld_lp.solvers import lp_blocks, settled_levels
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.iteration import interval_iteration
from mitld_lp.solvers.lp import solve_lp
from mitld_lp.testing import random_mdp


def _layered(seed: int, layers: int = 24, width: int = 6, *, ties: bool = False) -> MDP:
    """An MDP acyclic up to self-loops: ``layers`` layers of ``width`` states, each
    state's choices moving to the next layer (or to the target), most with a self-loop
    below 1; the last layer moves to the target and the sink.  State 0 (the
    first layer's first) is initial.  ``ties``: every state's last choice repeats its
    first (an exact tie) and another one is the first with its rows' weights nudged
    (a near tie)."""
    rng = np.random.default_rng(seed)
    n_inner = layers * width
    target, sink = n_inner, n_inner + 1
    n = n_inner + 2
    rows: list[dict[int, float]] = []
    groups = [0]
    for s in range(n_inner):
        layer = s // width
        nxt = list(range((layer + 1) * width, (layer + 2) * width)) + [target]
        choices = []
        for _ in range(int(rng.integers(1, 4))):
            # the last layer's choices to both ends, the others' to the next layer
            # and the target (no choice avoids the target surely: a minimum is not 0)
            succ = (np.array([target, sink]) if layer == layers - 1 else
                    rng.choice(nxt, size=int(rng.integers(1, 4)), replace=False))
            w = rng.random(succ.size) + 0.05
            row = {int(t): float(x) for t, x in zip(succ, w, strict=True)}
            if rng.random() < 0.7:  # a self-loop below 1
                row[s] = float(rng.random())
            choices.append(row)
        if ties:
            choices.append(dict(choices[0]))
            nudged = {t: x * (1.0 + 1e-14 * (t % 3)) for t, x in choices[0].items()}
            choices.append(nudged)
        for row in choices:
            total = sum(row.values())
            rows.append({t: x / total for t, x in row.items()})
        groups.append(groups[-1] + len(choices))
    for s in (target, sink):  # absorbing
        rows.append({s: 1.0})
        groups.append(groups[-1] + 1)
    m = len(rows)
    r = np.repeat(np.arange(m), [len(x) for x in rows])
    c = np.array([t for x in rows for t in x], dtype=np.int64)
    v = np.array([p for x in rows for p in x.values()])
    matrix = sp.csr_array((v, (r, c)), shape=(m, n))
    matrix.sum_duplicates()
    actions = np.zeros(m, dtype=np.int32)
    g = np.asarray(groups, dtype=np.int64)
    for s in range(n):
        actions[g[s]:g[s + 1]] = np.arange(g[s + 1] - g[s])
    actions[g[target]] = actions[g[sink]] = ABSORB
    mask = np.zeros(n, dtype=bool)
    return MDP(matrix=matrix, row_groups=g, choice_actions=actions,
               action_names=tuple(f"a{i}" for i in range(8)), initial=0,
               target=np.eye(1, n, target, dtype=bool).ravel(),
               sink=np.eye(1, n, sink, dtype=bool).ravel(), truncated=mask,
               states=tuple(range(n)))


def _exact_values(mdp: MDP, sense: Sense) -> list[Fraction]:
    """Backward induction in fractions on an MDP acyclic up to self-loops (states
    numbered so that every other successor has a larger index): ``v(s) = best_c
    sum_{s' != s} P(c, s') v(s') / (1 - P(c, s))``, 1 on the target, 0 on the sink."""
    n = mdp.n_states
    m = sp.csr_array(mdp.matrix)
    v = [Fraction(0)] * n
    pick = max if sense is Sense.MAX else min
    for s in range(n - 1, -1, -1):
        if mdp.target[s]:
            v[s] = Fraction(1)
            continue
        if mdp.sink[s]:
            continue
        scores = []
        for c in range(int(mdp.row_groups[s]), int(mdp.row_groups[s + 1])):
            lo, hi = int(m.indptr[c]), int(m.indptr[c + 1])
            stay, out = Fraction(0), Fraction(0)
            for t, p in zip(m.indices[lo:hi].tolist(), m.data[lo:hi].tolist(), strict=True):
                if t == s:
                    stay += Fraction(p)
                else:
                    assert t > s, "not acyclic up to self-loops"
                    out += Fraction(p) * v[t]
            scores.append(out / (1 - stay))
        v[s] = pick(scores)
    return v


def _occupancy_lp(mdp: MDP, sense: Sense) -> float:
    """The occupancy LP on the product itself by HiGHS: one ``y(c) >= 0`` per choice of
    a state that is neither target nor sink, flow conserved from the initial state,
    the flow into the target the objective (an MDP without end components there)."""
    m = sp.csr_array(mdp.matrix)
    free = ~(mdp.target | mdp.sink)
    owner = np.repeat(np.arange(mdp.n_states), np.diff(mdp.row_groups))
    cols = np.flatnonzero(free[owner])
    p = m[cols].toarray()
    a = np.zeros((mdp.n_states, cols.size))
    a[owner[cols], np.arange(cols.size)] += 1.0
    a -= p.T
    b = np.zeros(mdp.n_states)
    b[mdp.initial] = 1.0
    gain = p[:, mdp.target].sum(axis=1)
    sign = -1.0 if sense is Sense.MAX else 1.0
    res = linprog(sign * gain, A_eq=a[free], b_eq=b[free], bounds=(0, None),
                  method="highs", options={"primal_feasibility_tolerance": 1e-10,
                                           "dual_feasibility_tolerance": 1e-10})
    assert res.status == 0
    return float(gain @ res.x)


def _policy_values(mdp: MDP, policy: np.ndarray) -> np.ndarray:
    """The deterministic ``policy``'s reach probability of the target, by a dense solve
    of its chain (the target 1, the sink 0; no end component among the others)."""
    free = np.flatnonzero(~(mdp.target | mdp.sink))
    p = sp.csr_array(mdp.matrix)[policy[free]].toarray()
    q = p[:, free]
    r = p[:, mdp.target].sum(axis=1)
    v = mdp.target.astype(float)
    v[free] = np.linalg.solve(np.eye(free.size) - q, r)
    return v


def _solved(mdp: MDP, sense: Sense, settled: bool, bounds=None, **kw):
    if bounds is None:
        it = interval_iteration(mdp, mdp.target, sense=sense, gap="max", progress=False)
        bounds = (it.lower, it.upper)
    was = settled_levels.SETTLED_BY_BOUNDS
    settled_levels.SETTLED_BY_BOUNDS = settled
    try:
        got = solve_lp(mdp, mdp.target, sense=sense, everywhere=True, bounds=bounds, **kw)
    finally:
        settled_levels.SETTLED_BY_BOUNDS = was
    assert got.status.value == "optimal" and got.values is not None
    assert got.policy is not None
    return got


@pytest.fixture
def calls(monkeypatch: pytest.MonkeyPatch) -> list[bool]:
    """What each call of :func:`settled_by_bounds` answered (``True``: it wrote the
    level walk's answer)."""
    seen: list[bool] = []
    real = settled_levels.settled_by_bounds

    def spy(*a, **k):
        seen.append(real(*a, **k))
        return seen[-1]
    monkeypatch.setattr(lp_blocks, "settled_by_bounds", spy)
    return seen


def _same(a, b) -> None:
    """The same policy and the same values, bit for bit."""
    assert np.array_equal(np.asarray(a.policy), np.asarray(b.policy))
    assert np.array_equal(np.asarray(a.values).view(np.int64),
                          np.asarray(b.values).view(np.int64))
    assert a.value == b.value


@pytest.mark.parametrize("ties", [False, True])
@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize("seed", range(4))
def test_acyclic_policy_value_is_the_exact_optimum(seed: int, sense: Sense, ties: bool,
                                                   calls: list[bool]) -> None:
    mdp = _layered(seed, ties=ties)
    exact = np.array([float(x) for x in _exact_values(mdp, sense)])
    got = _solved(mdp, sense, True)
    assert calls == [True]  # the shortcut answered (the rest of its checks below)
    np.testing.assert_allclose(got.values, exact, rtol=0, atol=1e-12)
    np.testing.assert_allclose(_policy_values(mdp, np.asarray(got.policy)), exact,
                               rtol=0, atol=1e-12)
    assert got.value == pytest.approx(_occupancy_lp(mdp, sense), abs=1e-8)


@pytest.mark.parametrize("ties", [False, True])
@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize("seed", range(4))
def test_shortcut_on_and_off_give_the_same_bits(seed: int, sense: Sense,
                                                ties: bool) -> None:
    mdp = _layered(10 + seed, ties=ties)
    _same(_solved(mdp, sense, True), _solved(mdp, sense, False))


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize("seed", range(3))
def test_wrong_bounds_are_walked_not_taken(seed: int, sense: Sense,
                                           calls: list[bool]) -> None:
    """Bounds that are not the walk's values (a few states nudged by an ulp, or every
    state by 1e-9) fail the check there, and the walk answers those states and every
    state above them: the same bits as the walk alone."""
    mdp = _layered(20 + seed)
    want = _solved(mdp, sense, False)
    exact = np.asarray(want.values)
    rng = np.random.default_rng(seed)
    some = exact.copy()
    inner = np.flatnonzero(~(mdp.target | mdp.sink) & (exact > 0) & (exact < 1))
    hit = rng.choice(inner, size=3, replace=False)
    some[hit] = np.nextafter(some[hit], 2.0)
    every = np.clip(exact + 1e-9, 0.0, 1.0)
    for bound in (some, every):
        _same(_solved(mdp, sense, True, bounds=(bound, bound)), want)
    assert calls == [False, True, True]  # off, then tried on both


def test_open_bounds_leave_the_walk(calls: list[bool]) -> None:
    """Bounds the iteration left open somewhere (lower below upper) are not tried."""
    mdp = _layered(30)
    want = _solved(mdp, Sense.MAX, False)
    lo = np.zeros(mdp.n_states)
    hi = np.ones(mdp.n_states)
    lo[mdp.target] = 1.0
    hi[mdp.sink] = 0.0
    _same(_solved(mdp, Sense.MAX, True, bounds=(lo, hi)), want)
    assert calls == [False, False]  # off, then not tried


@pytest.mark.parametrize("seed", range(3))
def test_random_cyclic_mdps_keep_their_optimum(seed: int, calls: list[bool]) -> None:
    """Random MDPs with cycles (blocks: the shortcut is not tried), the same answer
    either way and the occupancy LP's optimum by HiGHS on the product."""
    mdp = random_mdp(60, seed=seed, target_fraction=0.1, sink_fraction=0.1,
                     self_loop_fraction=0.0, max_choices=3, max_successors=3)
    on, off = _solved(mdp, Sense.MAX, True), _solved(mdp, Sense.MAX, False)
    _same(on, off)
    value = _policy_values_any(mdp, np.asarray(on.policy))[mdp.initial]
    assert value == pytest.approx(_occupancy_lp(mdp, Sense.MAX), abs=1e-8)
    assert on.value == pytest.approx(value, abs=1e-9)


def _policy_values_any(mdp: MDP, policy: np.ndarray) -> np.ndarray:
    """The policy's reach probability where its chain may loop for ever: 0 on the
    states that cannot reach the target under it, a dense solve on the others."""
    p = sp.csr_array(mdp.matrix).toarray()[policy]
    stop = mdp.target | mdp.sink
    reach = mdp.target.copy()
    while True:
        more = reach | (~stop & (p[:, reach] > 0).any(axis=1))
        if np.array_equal(more, reach):
            break
        reach = more
    live = np.flatnonzero(reach & ~mdp.target)
    v = mdp.target.astype(float)
    v[live] = np.linalg.solve(np.eye(live.size) - p[np.ix_(live, live)],
                              p[live][:, mdp.target].sum(axis=1))
    return v


@pytest.mark.parametrize("seed", range(3))
def test_mid_sized_block_greedy_or_lp_the_same_optimum(seed: int) -> None:
    """A block of 1,000 to 10,000 choices (the bounds' greedy policy answers it since
    ``GREEDY_MIN_CHOICES`` is 1,000): its policy attains HiGHS's optimum of the
    occupancy LP on the product, and so does Clarabel's on the same block
    (``greedy=False``), both values within 1e-9."""
    mdp = random_mdp(1200, seed=40 + seed, target_fraction=0.05, sink_fraction=0.3,
                     self_loop_fraction=0.0, max_choices=4, max_successors=5)
    it = interval_iteration(mdp, mdp.target, sense=Sense.MAX, gap="max", progress=False)
    bounds = (it.lower, it.upper)
    greedy = solve_lp(mdp, mdp.target, everywhere=True, bounds=bounds)
    lp = solve_lp(mdp, mdp.target, everywhere=True, bounds=bounds, greedy=False)
    assert "by the bounds' greedy policy" in greedy.message
    assert "block states by the bounds' greedy policy" not in lp.message
    assert 1_000 <= lp.lp_shape[1] < 10_000
    want = _occupancy_lp(mdp, Sense.MAX)
    for got in (greedy, lp):
        attained = _policy_values_any(mdp, np.asarray(got.policy))
        assert attained[mdp.initial] == pytest.approx(want, abs=1e-9)
        np.testing.assert_allclose(attained, np.asarray(lp.values), rtol=0, atol=1e-9)


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
def test_compiled_walk_and_shortcut_give_the_same_bits(sense: Sense,
                                                       monkeypatch: pytest.MonkeyPatch,
                                                       calls: list[bool]) -> None:
    """Where the level walk is the compiled one (numba's kernels, forced on this small
    quotient), the shortcut's NumPy sums and picks are its values and choices too."""
    pytest.importorskip("numba")
    from mitld_lp.solvers import topological

    monkeypatch.setattr(topological, "LEVEL_KERNEL_MIN_ENTRIES", 0)
    monkeypatch.setattr(topological, "LEVEL_KERNEL_MIN_LEVELS", 0)
    walks: list[bool] = []
    spy = lp_blocks.settled_by_bounds

    def seen(q, blk, singles, *a):
        walks.append(singles.kernels is not None)
        return spy(q, blk, singles, *a)
    monkeypatch.setattr(lp_blocks, "settled_by_bounds", seen)
    for seed in range(3):
        mdp = _layered(50 + seed, ties=True)
        _same(_solved(mdp, sense, True), _solved(mdp, sense, False))
    assert calls == [True, False] * 3
    assert walks == [True] * 6  # the compiled walks' levels
