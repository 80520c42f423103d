"""Deep acyclic quotients (a deadline's product): the level walks' gate
(solvers.level_gate) and the LP stage on them.

* the gate: compiled walks from DEEP_LEVELS levels on a warm cache, never on a cold
  one, whatever the quotient's size;
* on random deep acyclic MDPs (chains of 200 levels and more, self-loops, several
  choices a state, both senses), walked compiled through the gate: the interval
  iteration's bounds, the LP's values at every state and the value of the LP's policy
  are those of a backward induction in exact arithmetic written here (a dict of
  Fractions, the states in reverse order), within 1e-12; the NumPy walks give the
  same floats bit for bit;
* the LP's values walk made in the iteration's pass and handed over: the LP's values,
  policy and objectives are those of its own walk bit for bit (random chains, exact
  ties, and near-ties where the LP's rule picks a choice one unit in the last place
  below the bound, so its values are not the bounds), its message says so, and the
  NumPy walks hand nothing over.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
from conftest import build_mdp

from mitld_lp.solvers import level_gate, shared_levels
from mitld_lp.solvers.analysis import analyse
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.iteration import interval_iteration
from mitld_lp.solvers.lp import solve_lp
from mitld_lp.solvers.topological import SingleLevels


@pytest.fixture
def warm(monkeypatch: pytest.MonkeyPatch) -> None:
    """The gate told the walks' cache is warm (numba compiles them on a miss)."""
    pytest.importorskip("numba")
    monkeypatch.setattr(level_gate, "_WARM", [True])


@pytest.fixture
def cold(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(level_gate, "_WARM", [False])


def _chain(seed: int, depth: int):
    """A chain of ``depth`` steps, one state a step but a few with a second one beside
    it; a state's choices stay (sometimes), go one to three steps on, reach the goal or
    the dead end, with probabilities in sixteenths (exact in binary).  Returns the MDP,
    each state's rows and the goal's index."""
    rng = np.random.default_rng(seed)
    spots = [[s] for s in range(depth)]
    n = depth
    for s in range(0, depth, 7):  # a twin beside some steps: levels of two states
        spots[s].append(n)
        n += 1
    goal, dead = n, n + 1
    rows: list[list[dict[int, float]]] = [[] for _ in range(n)]
    for step in range(depth):
        for s in spots[step]:
            for _ in range(int(rng.integers(1, 4))):
                later = [spots[t][int(rng.integers(len(spots[t])))]
                         for t in range(step + 1, min(step + 4, depth))]
                succ = [goal, dead, *later]
                w = rng.integers(0, 5, size=len(succ) + 1)
                w[0] = w[0] if rng.random() < 0.3 else 0  # a self-loop now and then
                w[3 if later else 1] += 1  # every row moves on (no row all self-loop)
                w = w * 16 // max(int(w.sum()), 1)
                w[2] += 16 - int(w.sum())  # sixteenths summing to 16, rest to the dead end
                row: dict[int, float] = {}
                for t, k in zip([s, *succ], w.tolist(), strict=True):
                    if k > 0:
                        row[t] = row.get(t, 0.0) + k / 16
                rows[s].append(row)
    choices = [[(f"a{i}", r) for i, r in enumerate(rs)] for rs in rows] + [[], []]
    return build_mdp(choices, target=[goal], sink=[dead]), rows, goal


def _induction(rows, goal: int, sense: Sense) -> list[Fraction]:
    """The optimum by backward induction in exact arithmetic: a state after every state
    it can move to (the states are numbered so that higher steps come later, twins
    after all steps: solved by repeated passes until every successor is known)."""
    pick = max if sense is Sense.MAX else min
    v: dict[int, Fraction] = {goal: Fraction(1), goal + 1: Fraction(0)}
    left = list(range(len(rows)))
    while left:
        waiting = []
        for s in reversed(left):
            if any(t not in v for r in rows[s] for t in r if t != s):
                waiting.append(s)
                continue
            scores = []
            for r in rows[s]:
                stay = Fraction(r.get(s, 0.0))
                out = sum((Fraction(p) * v[t] for t, p in r.items() if t != s), Fraction(0))
                scores.append(out / (1 - stay))
            v[s] = pick(scores)
        assert len(waiting) < len(left)
        left = sorted(waiting)
    return [v[s] for s in range(len(rows))]


def _policy_value(rows, goal: int, policy: np.ndarray, mdp) -> list[Fraction]:
    """The exact value of a deterministic policy (a choice row per state)."""
    groups = np.asarray(mdp.row_groups)
    chosen = [[rows[s][int(policy[s]) - int(groups[s])]] for s in range(len(rows))]
    return _induction(chosen, goal, Sense.MAX)


def test_the_gate_takes_deep_quotients_on_a_warm_cache(monkeypatch) -> None:
    monkeypatch.setattr(level_gate, "_WARM", [True])
    assert not level_gate.deep(level_gate.DEEP_LEVELS - 1)
    assert level_gate.deep(level_gate.DEEP_LEVELS)
    monkeypatch.setattr(level_gate, "_WARM", [False])  # a cold cache: never
    assert not level_gate.deep(10 * level_gate.DEEP_LEVELS)


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize("seed", [0, 1])
def test_deep_chains_walked_compiled_match_exact_induction(warm, seed: int,
                                                           sense: Sense) -> None:
    mdp, rows, goal = _chain(seed, depth=240)
    q, _ = analyse(mdp, mdp.target, sense=sense)
    assert q.order.n_levels >= level_gate.DEEP_LEVELS
    assert not bool((q.order.size > 1).any())  # acyclic up to self-loops
    assert SingleLevels(q, q.order).kernels is not None  # walked compiled
    truth = _induction(rows, goal, sense)
    it = interval_iteration(mdp, mdp.target, quotient=q, sense=sense, progress=False,
                            gap="max")
    lp = solve_lp(mdp, mdp.target, quotient=q, sense=sense, everywhere=True,
                  bounds=(it.lower, it.upper), progress=False)
    assert lp.status.value == "optimal"
    n = len(rows)
    exact = np.array([float(x) for x in truth])
    assert np.all(np.asarray(it.lower)[:n] <= exact + 1e-12)
    assert np.all(np.asarray(it.upper)[:n] >= exact - 1e-12)
    assert np.max(np.abs(np.asarray(it.upper)[:n] - np.asarray(it.lower)[:n])) <= 1e-12
    assert np.max(np.abs(np.asarray(lp.values)[:n] - exact)) <= 1e-12
    got = _policy_value(rows, goal, np.asarray(lp.policy), mdp)  # attains the optimum
    assert max(abs(float(a - b)) for a, b in zip(got, truth, strict=True)) <= 1e-12


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
def test_compiled_and_numpy_walks_give_the_same_bits(monkeypatch, sense: Sense) -> None:
    pytest.importorskip("numba")
    mdp, _, _ = _chain(2, depth=220)
    got = []
    for hot in (True, False):
        monkeypatch.setattr(level_gate, "_WARM", [hot])
        shared_levels._KEPT.clear()
        q, _ = analyse(mdp, mdp.target, sense=sense)
        assert (SingleLevels(q, q.order).kernels is not None) is hot  # a small quotient
        it = interval_iteration(mdp, mdp.target, quotient=q, sense=sense, progress=False)
        lp = solve_lp(mdp, mdp.target, quotient=q, sense=sense, progress=False,
                      bounds=(it.lower, it.upper))
        got.append([np.asarray(x) for x in (it.lower, it.upper, lp.values, lp.policy)])
    for a, b in zip(*got, strict=True):
        assert np.array_equal(a.view(np.int64), b.view(np.int64))


def _lp_both_ways(monkeypatch, mdp, sense: Sense, everywhere: bool):
    """The iteration and the LP stage as the plain route runs them (one quotient, the
    iteration's bounds), once with the walk handed over and once without."""
    from mitld_lp.solvers import iteration

    out = []
    for hand in (True, False):
        shared_levels._KEPT.clear()
        if not hand:
            monkeypatch.setattr(iteration, "walk_handing", lambda *a: False)
        q, _ = analyse(mdp, mdp.target, sense=sense)
        it = interval_iteration(mdp, mdp.target, quotient=q, sense=sense, progress=False,
                                gap="max" if everywhere else "initial")
        lp = solve_lp(mdp, mdp.target, quotient=q, sense=sense, everywhere=everywhere,
                      bounds=(it.lower, it.upper), progress=False)
        out.append((it, lp))
    monkeypatch.undo()
    return out


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize("seed", [3, 4])
@pytest.mark.parametrize("everywhere", [True, False])
def test_the_lp_takes_the_iterations_walk_to_the_bit(warm, monkeypatch, seed: int,
                                                     sense: Sense, everywhere: bool) -> None:
    mdp, rows, goal = _chain(seed, depth=230)
    (it, lp), (it0, lp0) = _lp_both_ways(monkeypatch, mdp, sense, everywhere)
    assert "made in the interval iteration's pass" in lp.message  # said where it came from
    assert "made in the interval iteration's pass" not in lp0.message
    assert lp.status.value == lp0.status.value == "optimal"
    for a, b in ((it.lower, it0.lower), (it.upper, it0.upper), (lp.values, lp0.values),
                 (lp.policy, lp0.policy)):
        assert np.array_equal(np.asarray(a).view(np.int64), np.asarray(b).view(np.int64))
    assert lp.primal_objective == lp0.primal_objective
    assert lp.dual_objective == lp0.dual_objective
    truth = _induction(rows, goal, sense)  # and both are the exact optimum
    assert abs(lp.value - float(truth[0])) <= 1e-12
    got = _policy_value(rows, goal, np.asarray(lp.policy), mdp)
    reached = np.asarray(lp.values)[:len(rows)]
    assert abs(float(got[0] - truth[0])) <= 1e-12
    if everywhere:
        assert max(abs(float(a - b)) for a, b in zip(got, truth, strict=True)) <= 1e-12
        assert np.max(np.abs(reached - np.array([float(x) for x in truth]))) <= 1e-12


def tied_mdp(near: bool):
    """A chain of 220 steps where every state has the value 1/2 by three choices: to the
    goal and the dead end, half each; a quarter (``near``: 0.3, not a binary fraction,
    so its score may differ from 1/2 in its last bits) to the goal and the rest through
    the next state; all through the next state: ties where the LP's rule (the larger
    one-step target probability, for a minimum the least) decides."""
    depth = 220
    goal, dead = depth, depth + 1
    r = 0.3 if near else 0.25
    rows: list[list[dict[int, float]]] = []
    for s in range(depth):
        if s + 1 == depth:
            rows.append([{goal: 0.5, dead: 0.5}])
            continue
        p = (0.5 - r) / 0.5  # r + p / 2 = 1/2
        rows.append([{goal: 0.5, dead: 0.5},
                     {goal: r, s + 1: p, dead: 1.0 - r - p},
                     {s + 1: 1.0}])
    choices = [[(f"a{i}", r) for i, r in enumerate(rs)] for rs in rows] + [[], []]
    return build_mdp(choices, target=[goal], sink=[dead]), rows, goal


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize("near", [False, True])
def test_ties_go_as_the_lps_own_walk_breaks_them(warm, monkeypatch, sense: Sense,
                                                 near: bool) -> None:
    mdp, rows, goal = tied_mdp(near)
    (it, lp), (_, lp0) = _lp_both_ways(monkeypatch, mdp, sense, True)
    assert np.array_equal(np.asarray(lp.policy), np.asarray(lp0.policy))
    assert np.array_equal(np.asarray(lp.values).view(np.int64),
                          np.asarray(lp0.values).view(np.int64))
    truth = _induction(rows, goal, sense)
    got = _policy_value(rows, goal, np.asarray(lp.policy), mdp)
    assert max(abs(float(a - b)) for a, b in zip(got, truth, strict=True)) <= 1e-12


def test_nothing_handed_for_the_numpy_walks(cold, monkeypatch) -> None:
    mdp, _, _ = _chain(5, depth=210)
    shared_levels._KEPT.clear()
    q, _ = analyse(mdp, mdp.target, sense=Sense.MAX)
    it = interval_iteration(mdp, mdp.target, quotient=q, progress=False)
    assert not shared_levels._KEPT[id(q.matrix)][5]  # the NumPy walk hands nothing
    lp = solve_lp(mdp, mdp.target, quotient=q, bounds=(it.lower, it.upper), progress=False)
    assert "made in the interval iteration's pass" not in lp.message


def _near(depth: int = 220):
    """A chain where each state's choice of the larger one-step target probability
    scores one unit in the last place below its other choice (the walk's floats, made
    here from the end): the LP's rule picks it, so its value is not the iteration's
    bound to the bit (the bound is the larger score)."""
    goal, dead = depth, depth + 1
    rows: list[list[dict[int, float]]] = [[] for _ in range(depth)]
    rows[depth - 1] = [{goal: 0.5, dead: 0.5}]
    v = 0.5  # the walk's bound at the next state
    r, p = 0.125, 0.75
    for s in range(depth - 2, -1, -1):
        score = r + p * v
        g = float(np.nextafter(score, 0.0))
        rows[s] = [{goal: g, dead: 1.0 - g}, {goal: r, s + 1: p, dead: 1.0 - r - p}]
        v = score
    choices = [[(f"a{i}", x) for i, x in enumerate(rs)] for rs in rows] + [[], []]
    return build_mdp(choices, target=[goal], sink=[dead]), rows, goal


def test_near_ties_hand_over_the_lps_own_values_not_the_bounds(warm, monkeypatch) -> None:
    mdp, rows, goal = _near()
    (it, lp), (_, lp0) = _lp_both_ways(monkeypatch, mdp, Sense.MAX, True)
    assert "made in the interval iteration's pass" in lp.message
    n = len(rows)
    picked = np.asarray(lp.policy)[:n - 1] - np.asarray(mdp.row_groups)[:n - 1]
    assert np.all(picked == 0)  # the tie went to the larger one-step probability
    assert np.all(np.asarray(lp.values)[:n - 1] < np.asarray(it.lower)[:n - 1])  # below
    for a, b in ((lp.values, lp0.values), (lp.policy, lp0.policy)):
        assert np.array_equal(np.asarray(a).view(np.int64), np.asarray(b).view(np.int64))
    truth = _induction(rows, goal, Sense.MAX)
    got = _policy_value(rows, goal, np.asarray(lp.policy), mdp)
    assert max(abs(float(a - b)) for a, b in zip(got, truth, strict=True)) <= 1e-12


def _truncated(seed: int, depth: int = 215):
    """:func:`_chain` with a truncated end beside the goal and the dead end: some rows
    send a sixteenth there, so the lower and the upper model differ."""
    mdp, rows, goal = _chain(seed, depth)
    cut = goal + 2
    rng = np.random.default_rng(seed + 100)
    for rs in rows:
        for r in rs:
            dead = goal + 1
            if r.get(dead, 0.0) >= 1 / 16 and rng.random() < 0.5:
                r[dead] -= 1 / 16
                r[cut] = 1 / 16
                if r[dead] == 0.0:
                    del r[dead]
    choices = [[(f"a{i}", r) for i, r in enumerate(rs)] for rs in rows] + [[], [], []]
    return build_mdp(choices, target=[goal], sink=[goal + 1], truncated=[cut]), rows, goal


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
def test_both_truncation_models_take_their_own_walk(warm, monkeypatch, sense: Sense) -> None:
    from mitld_lp.solvers import iteration
    from mitld_lp.solvers.iteration import interval_iterations

    mdp, rows, goal = _truncated(6)
    got = []
    for hand in (True, False):
        shared_levels._KEPT.clear()
        if not hand:
            monkeypatch.setattr(iteration, "walk_handing", lambda *a: False)
        low, up = analyse(mdp, mdp.target, mdp.truncated, sense=sense)
        assert low is not up and low.matrix is up.matrix
        its = interval_iterations(mdp, [low, up], progress=False, gap="max")
        lps = [solve_lp(mdp, np.asarray(q.target), quotient=q, sense=sense,
                        everywhere=True, bounds=(it.lower, it.upper), progress=False)
               for q, it in zip((low, up), its, strict=True)]
        assert all(("made in the interval iteration's pass" in lp.message) is hand
                   for lp in lps)
        got.append(lps)
    monkeypatch.undo()
    for a, b in zip(*got, strict=True):
        for x, y in ((a.values, b.values), (a.policy, b.policy)):
            assert np.array_equal(np.asarray(x).view(np.int64), np.asarray(y).view(np.int64))
    assert not np.array_equal(np.asarray(got[0][0].values), np.asarray(got[0][1].values))
    n = len(rows)  # the lower model: the truncated end loses; exact induction
    truth = _induction([[{t: p for t, p in r.items() if t != goal + 2} | (
        {goal + 1: r.get(goal + 1, 0.0) + r[goal + 2]} if goal + 2 in r else {})
        for r in rs] for rs in rows], goal, sense)
    assert np.max(np.abs(np.asarray(got[0][0].values)[:n] - np.array(
        [float(x) for x in truth]))) <= 1e-12
