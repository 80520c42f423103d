"""The single-state levels of the interval iteration (topological.SingleLevels): a
deadline-like product of many levels, each state its own component with self-loops,
against a backward recursion in exact arithmetic written here."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
from conftest import build_mdp

from mitld_lp.solvers import Status, interval_iteration
from mitld_lp.solvers.graph import Sense


def layered_mdp(seed: int, depth: int = 60, width: int = 3):
    """``depth`` layers of ``width`` states; each choice stays put, moves to the next
    layer, or reaches the goal / the dead end; the last layer's choices end there.
    Returns the MDP and each state's choices as exact ``(stay, {succ: p}, goal)``."""
    rng = np.random.default_rng(seed)
    n = depth * width
    goal, dead = n, n + 1
    states, exact = [], []
    for s in range(n):
        layer = s // width
        mine, ex = [], []
        for a in range(int(rng.integers(1, 4))):
            nxt = [goal, dead] + ([(layer + 1) * width + int(j) for j in
                                   rng.choice(width, size=2, replace=False)]
                                  if layer + 1 < depth else [])
            w = rng.integers(1, 9, size=len(nxt) + 1).astype(float)
            w[0] = w[0] if rng.random() < 0.5 else 0.0  # no goal move half the time
            p = w / w.sum()
            row = {s: float(p[0])} if p[0] > 0 else {}
            for t, q in zip(nxt, p[1:], strict=True):
                row[t] = row.get(t, 0.0) + float(q)
            total = sum(row.values())
            row[dead] += 1.0 - total  # rows sum to 1 in floats
            mine.append((f"a{a}", row))
            ex.append(row)
        states.append(mine)
        exact.append(ex)
    states += [[], []]
    return build_mdp(states, target=[goal], sink=[dead]), exact, goal


def recursion_values(exact, goal: int, n: int, sense: Sense) -> list[Fraction]:
    pick = max if sense is Sense.MAX else min
    v: dict[int, Fraction] = {goal: Fraction(1), goal + 1: Fraction(0)}
    for s in range(n - 1, -1, -1):  # later layers first
        scores = []
        for row in exact[s]:
            stay = Fraction(row.get(s, 0.0))
            gain = sum((Fraction(p) * v[t] for t, p in row.items() if t != s), Fraction(0))
            scores.append(gain / (1 - stay))
        v[s] = pick(scores)
    return [v[s] for s in range(n)]


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
def test_many_single_levels_match_the_exact_recursion(seed: int, sense: Sense) -> None:
    mdp, exact, goal = layered_mdp(seed)
    n = goal
    want = recursion_values(exact, goal, n, sense)
    r = interval_iteration(mdp, mdp.target, sense=sense, gap="max", progress=False)
    assert r.status is Status.OPTIMAL, r.message
    assert r.iterations == 0  # no cycle but the self-loops, solved exactly
    for s in range(n):
        # float sums of a few terms: within a few ulps of the exact value
        slack = Fraction(2.0 ** -48) * want[s]
        assert Fraction(r.lower[s]) - slack <= want[s] <= Fraction(r.upper[s]) + slack, s
    # gap="initial" leaves out what the initial state cannot reach, same value there
    first = interval_iteration(mdp, mdp.target, sense=sense, progress=False)
    assert first.value_lower == r.value_lower and first.value_upper == r.value_upper
