"""Deep acyclic quotients (a deadline's product): the level walks' gate
(solvers.level_gate) and the LP stage on them.

* the gate: compiled walks from DEEP_LEVELS levels on a warm cache, never on a cold
  one, whatever the quotient's size;
* on random deep acyclic MDPs (chains of 200 levels and more, self-loops, several
  choices a state, both senses), walked compiled through the gate: the interval
  iteration's bounds, the LP's values at every state and the value of the LP's policy
  are those of a backward induction in exact arithmetic written here (a dict of
  Fractions, the states in reverse order), within 1e-12; the NumPy walks give the
  same floats bit for bit.
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
