"""A minimum solved as a minimum, and rare values to relative precision.

The references are independent of the solvers: every deterministic policy of a small
MDP evaluated in exact rational arithmetic (``fractions.Fraction``; memoryless
deterministic policies attain both optima of reachability), the graph's 0/1 sets read
off those exact optima, and closed forms worked by hand.
"""

from __future__ import annotations

import itertools
from fractions import Fraction

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.mdp import ABSORB, MDP
from mitld_lp.solvers import Status, evaluate_policy, interval_iteration, solve_lp
from mitld_lp.solvers.analysis import analyse
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.quotient import prob0_min, prob1_max, prob1_min

# --------------------------------------------------------------------------- references


def _rows(mdp: MDP) -> list[list[dict[int, Fraction]]]:
    """Per state, per choice, the successor distribution as written: the stored floats
    as exact fractions, renormalised to sum 1 (so that 0 and 1 are exact)."""
    m = sp.csr_array(mdp.matrix)
    out = []
    for s in range(mdp.n_states):
        choices = []
        for c in range(int(mdp.row_groups[s]), int(mdp.row_groups[s + 1])):
            lo, hi = m.indptr[c], m.indptr[c + 1]
            dist = {int(t): Fraction(float(p)) for t, p in zip(m.indices[lo:hi], m.data[lo:hi],
                                                                strict=True) if p > 0}
            total = sum(dist.values())
            choices.append({t: p / total for t, p in dist.items()})
        out.append(choices)
    return out


def _chain_value(rows: list[list[dict[int, Fraction]]], pick: tuple[int, ...],
                 target: set[int]) -> list[Fraction]:
    """The exact probability of reaching ``target`` from every state under the policy
    ``pick`` (a choice index per state): Gauss-Jordan on the states that can reach it."""
    n = len(rows)
    succ = [rows[s][pick[s]] for s in range(n)]
    can = set(target)
    grew = True
    while grew:
        grew = False
        for s in range(n):
            if s not in can and any(t in can for t in succ[s]):
                can.add(s)
                grew = True
    solve = [s for s in range(n) if s in can and s not in target]
    index = {s: i for i, s in enumerate(solve)}
    k = len(solve)
    a = [[Fraction(0)] * (k + 1) for _ in range(k)]
    for s, i in index.items():
        a[i][i] += 1
        for t, p in succ[s].items():
            if t in target:
                a[i][k] += p
            elif t in index:
                a[i][index[t]] -= p
    for col in range(k):
        piv = next(r for r in range(col, k) if a[r][col] != 0)
        a[col], a[piv] = a[piv], a[col]
        inv = 1 / a[col][col]
        a[col] = [x * inv for x in a[col]]
        for r in range(k):
            if r != col and a[r][col] != 0:
                f = a[r][col]
                a[r] = [x - f * y for x, y in zip(a[r], a[col], strict=True)]
    value = [Fraction(1) if s in target else Fraction(0) for s in range(n)]
    for s, i in index.items():
        value[s] = a[i][k]
    return value


def brute_force(mdp: MDP, target: np.ndarray) -> tuple[list[Fraction], list[Fraction]]:
    """``(Pmin, Pmax)`` of every state: the least and greatest exact value over every
    deterministic memoryless policy."""
    rows = _rows(mdp)
    goal = {int(s) for s in np.flatnonzero(target)}
    best_min: list[Fraction] | None = None
    best_max: list[Fraction] | None = None
    for pick in itertools.product(*(range(len(r)) for r in rows)):
        v = _chain_value(rows, pick, goal)
        best_min = v if best_min is None else [min(a, b) for a, b in zip(best_min, v, strict=True)]
        best_max = v if best_max is None else [max(a, b) for a, b in zip(best_max, v, strict=True)]
    assert best_min is not None and best_max is not None
    return best_min, best_max


def small_mdp(seed: int, *, n: int = 7, rare: float = 1.0) -> MDP:
    """A random MDP of ``n`` states: the last is the target, the one before a sink;
    every other state has 1-3 choices of 1-3 successors (pure self-loops among them: end
    components); with ``rare`` < 1 every probability of entering the target is scaled
    by it (the rest of the row takes the difference), so values are powers of it."""
    rng = np.random.default_rng(seed)
    target, sink = n - 1, n - 2
    rows, cols, vals, groups, actions = [], [], [], [0], []
    for s in range(n):
        if s in (target, sink):
            k = 1
            dists = [{s: 1.0}]
        else:
            k = int(rng.integers(1, 4))
            dists = []
            for _ in range(k):
                if rng.random() < 0.15:
                    dists.append({s: 1.0})
                    continue
                succ = rng.choice(n, size=int(rng.integers(1, 4)), replace=False)
                w = rng.random(succ.size) + 0.05
                w = w / w.sum()
                d = {int(t): float(p) for t, p in zip(succ, w, strict=True)}
                if target in d and rare < 1.0 and len(d) > 1:
                    moved = d[target] * (1.0 - rare)
                    d[target] -= moved
                    other = next(t for t in d if t != target)
                    d[other] += moved
                dists.append(d)
        for d in dists:
            c = len(actions)
            actions.append(ABSORB if s in (target, sink) else len(actions) % 3)
            for t, p in d.items():
                rows.append(c)
                cols.append(t)
                vals.append(p)
        groups.append(len(actions))
    matrix = sp.csr_array((vals, (rows, cols)), shape=(len(actions), n))
    mask = np.zeros(n, dtype=bool)
    tmask, smask = mask.copy(), mask.copy()
    tmask[target] = True
    smask[sink] = True
    return MDP(matrix=matrix, row_groups=np.asarray(groups, dtype=np.int64),
               choice_actions=np.asarray(actions, dtype=np.int32),
               action_names=("a", "b", "c"), initial=0, target=tmask, sink=smask,
               truncated=mask, states=range(n))


def _within(got: float, exact: Fraction, rel: float) -> bool:
    return abs(Fraction(got) - exact) <= Fraction(rel) * exact


# --------------------------------------------------------------------------- the graph


@pytest.mark.parametrize("seed", range(12))
def test_qualitative_sets_are_the_exact_zeros_and_ones(seed: int) -> None:
    """Prob0A/Prob1E and Prob0E/Prob1A from the graph are exactly where the brute-force
    optima are 0 and 1, and every other optimum is strictly between."""
    mdp = small_mdp(seed)
    pmin, pmax = brute_force(mdp, mdp.target)
    for sense, exact in ((Sense.MAX, pmax), (Sense.MIN, pmin)):
        q = analyse(mdp, mdp.target, sense=sense)[0]
        decided = q.qualitative
        assert [bool(z) for z in decided.zero] == [v == 0 for v in exact], sense
        assert [bool(o) for o in decided.one] == [v == 1 for v in exact], sense
        assert [bool(z) for z in decided.unreachable] == [v == 0 for v in pmax], sense
    assert [bool(x) for x in prob0_min(mdp, mdp.target)] == [v == 0 for v in pmin]
    assert [bool(x) for x in prob1_min(mdp, mdp.target)] == [v == 1 for v in pmin]
    assert [bool(x) for x in prob1_max(mdp, mdp.target)] == [v == 1 for v in pmax]


@pytest.mark.parametrize("seed", range(6))
def test_truncated_models_share_one_minimum_quotient(seed: int) -> None:
    """Both truncation models of one analysis (target ``goal`` and ``goal | extra``):
    each model's decided sets and values are its own brute force's."""
    mdp = small_mdp(seed + 100, n=7)
    extra = np.zeros(mdp.n_states, dtype=bool)
    extra[mdp.n_states - 2] = True  # the sink counts as reached in the upper model
    low, high = analyse(mdp, mdp.target, extra, sense=Sense.MIN)
    for q, target in ((low, mdp.target), (high, mdp.target | extra)):
        pmin, _ = brute_force(mdp, target)
        assert [bool(z) for z in q.qualitative.zero] == [v == 0 for v in pmin]
        assert [bool(o) for o in q.qualitative.one] == [v == 1 for v in pmin]
        lp = solve_lp(mdp, target, quotient=q, sense=Sense.MIN, everywhere=True)
        assert lp.status is Status.OPTIMAL
        exact = evaluate_policy(mdp, target, lp.policy)
        for s in range(mdp.n_states):
            assert exact[s] == pytest.approx(float(pmin[s]), rel=1e-12, abs=1e-300), s


# --------------------------------------------------------------------------- the solvers


@pytest.mark.parametrize("rare", [1.0, 1e-20])
@pytest.mark.parametrize("seed", range(8))
def test_minimum_against_every_policy(seed: int, rare: float) -> None:
    """Interval iteration brackets Pmin of every state within the relative precision,
    and the LP's policy is worth the minimum (exactly: relative 1e-12), also when the
    values are powers of 1e-20."""
    mdp = small_mdp(seed, rare=rare)
    pmin, pmax = brute_force(mdp, mdp.target)
    it = interval_iteration(mdp, mdp.target, sense=Sense.MIN, gap="max", progress=False)
    assert it.status is Status.OPTIMAL
    for s in range(mdp.n_states):
        exact = pmin[s]
        assert Fraction(float(it.lower[s])) <= exact * (1 + Fraction(1, 10**12)), s
        assert Fraction(float(it.upper[s])) >= exact * (1 - Fraction(1, 10**12)), s
        assert Fraction(float(it.upper[s] - it.lower[s])) <= Fraction(1, 10**6) * exact, s
    lp = solve_lp(mdp, mdp.target, sense=Sense.MIN, everywhere=True,
                  bounds=(it.lower, it.upper))
    assert lp.status is Status.OPTIMAL
    worth = evaluate_policy(mdp, mdp.target, lp.policy)
    for s in range(mdp.n_states):
        assert _within(float(worth[s]), pmin[s], 1e-12), (s, worth[s], float(pmin[s]))
    # the greedy policy of the iteration is worth the minimum too (within its bracket)
    greedy = evaluate_policy(mdp, mdp.target, it.policy)
    assert np.all(greedy <= it.upper * (1 + 1e-12))
    # and the maximum of the same model keeps its own answer
    top = solve_lp(mdp, mdp.target, everywhere=True)
    best = evaluate_policy(mdp, mdp.target, top.policy)
    for s in range(mdp.n_states):
        assert _within(float(best[s]), pmax[s], 1e-12), s


@pytest.mark.parametrize("decompose", [True, False])
def test_minimum_lp_routes_agree_on_random_models(decompose: bool) -> None:
    """The block LPs and the one monolithic LP give the brute-force minimum."""
    for seed in range(4):
        mdp = small_mdp(seed + 40)
        pmin, _ = brute_force(mdp, mdp.target)
        lp = solve_lp(mdp, mdp.target, sense=Sense.MIN, decompose=decompose,
                      everywhere=True)
        assert lp.status is Status.OPTIMAL
        worth = evaluate_policy(mdp, mdp.target, lp.policy)
        for s in range(mdp.n_states):
            assert _within(float(worth[s]), pmin[s], 1e-12), (seed, s)


def _cycle(stay: float, rare: tuple[float, float]) -> MDP:
    """Two states that pass the run to each other with ``stay``; each may enter the
    target with ``rare[0]`` (choice ``a``) or ``rare[1]`` (``b``), else the sink.
    By hand, each optimum is ``rare / (1 - stay)`` in both states."""
    from conftest import build_mdp

    def gamble(other: int, p: float) -> dict[int, float]:
        return {other: stay, 2: p, 3: 1.0 - stay - p}

    return build_mdp([[("a", gamble(1, rare[0])), ("b", gamble(1, rare[1]))],
                      [("a", gamble(0, rare[0])), ("b", gamble(0, rare[1]))], [], []],
                     target=[2], sink=[3])


@pytest.mark.parametrize("sense", [Sense.MIN, Sense.MAX])
def test_the_iteration_stops_on_a_relative_gap(sense: Sense) -> None:
    """A cycle of values 2e-12 / 6e-12: closed to ``tol`` = 1e-9 alone the bracket says
    nothing of them; with the relative precision (the default, 1e-6) it holds the
    closed form to six digits."""
    mdp = _cycle(0.5, (1e-12, 3e-12))
    exact = Fraction(1e-12 if sense is Sense.MIN else 3e-12) / (1 - Fraction(0.5))
    loose = interval_iteration(mdp, mdp.target, sense=sense, precision=None, gap="max",
                               progress=False)
    tight = interval_iteration(mdp, mdp.target, sense=sense, gap="max", progress=False)
    for r in (loose, tight):
        assert r.status is Status.OPTIMAL
        assert Fraction(r.value_lower) <= exact <= Fraction(r.value_upper)
    assert loose.value_upper - loose.value_lower < 1e-9
    assert loose.value_upper - loose.value_lower > 1e-6 * float(exact)
    assert tight.value_upper - tight.value_lower <= 1e-6 * float(exact)


@pytest.mark.parametrize("sense", [Sense.MIN, Sense.MAX])
def test_a_slow_rare_block_is_jumped_to_relative_precision(sense: Sense) -> None:
    """A cycle left once in a thousand steps, values 1e-17 / 2e-17: a sweep shrinks the
    gap by 0.999, so six digits would take some 14,000 sweeps; the policy jump (checked
    on the policy's choices for its own bound, on every choice for the other, in the
    sense asked) proves both after a hundred."""
    mdp = _cycle(0.999, (1e-20, 2e-20))
    rate = Fraction(1e-20 if sense is Sense.MIN else 2e-20)
    exact = rate / (1 - Fraction(0.999))
    r = interval_iteration(mdp, mdp.target, sense=sense, gap="max", progress=False)
    assert r.status is Status.OPTIMAL, r.message
    assert r.iterations < 1000
    for s in (0, 1):
        assert Fraction(float(r.lower[s])) <= exact <= Fraction(float(r.upper[s]))
        assert r.upper[s] - r.lower[s] <= 1e-6 * float(exact)
    # the policy: the rarer gamble for the least, the likelier for the most
    assert mdp.action_name(int(r.policy[0])) == ("a" if sense is Sense.MIN else "b")


def test_a_quotient_answers_only_the_sense_it_was_reduced_for() -> None:
    mdp = small_mdp(3)
    q = analyse(mdp, mdp.target, sense=Sense.MIN)[0]
    with pytest.raises(ValueError, match="reduced for a minimum, not the maximum"):
        solve_lp(mdp, mdp.target, quotient=q)
