"""The certificate on the analysis's quotient levels (``Quotient.layers`` lifted from the
quotient, -1 outside it) holds the exact optimum, as it does on the product's own levels.

Small random MDPs with end components and with states of value 1 that leave the quotient
(a choice straight to the goal), dyadic probabilities (every float exact).  The optimum is
found apart, by enumerating every deterministic memoryless policy and solving its chain
in fractions (Gaussian elimination on the states that reach the goal).  The certificate
reads a random policy (its candidates fail, so the repair walks the levels) and the
optimal one; the bounds it reports on the optimum, and the whole bracket, are compared
with the exact values in fractions.
"""

from __future__ import annotations

import itertools
import random
from fractions import Fraction

import numpy as np
from conftest import build_mdp

from mitld_lp.mdp import absorbing_states
from mitld_lp.solvers.analysis import analyse
from mitld_lp.solvers.certify import (
    certify,
    chain,
    optimum_lower,
    optimum_upper,
    rounding,
    support_layers,
)
from mitld_lp.solvers.graph import Sense

SEEDS = range(16)


def _mdp(seed: int):
    """States 0..n-3 with 1-3 choices, the goal n-2 and the dead end n-1 (absorbing).  A
    choice spreads eighths over a few states near it, itself included (loops, end
    components), the goal or the dead end; one state in three has a choice straight to
    the goal (value 1 for a maximum)."""
    rng = random.Random(seed)
    n = rng.randint(5, 8)
    goal, dead = n - 2, n - 1
    states = []
    for s in range(n - 2):
        choices = []
        for a in range(rng.randint(1, 3)):
            near = [t for t in (s - 1, s, s + 1, rng.randrange(n - 2)) if 0 <= t < n - 2]
            pool = near + [goal, dead] if rng.random() < 0.6 else near
            picks = rng.sample(pool, min(len(pool), rng.randint(1, 3)))
            cuts = sorted(rng.sample(range(1, 8), len(picks) - 1))
            weights = [b - a for a, b in zip([0, *cuts], [*cuts, 8], strict=True)]
            dist: dict[int, float] = {}
            for t, w in zip(picks, weights, strict=True):
                dist[t] = dist.get(t, 0.0) + w / 8
            choices.append((f"a{a}", dist))
        if s % 3 == 1:
            choices.append(("go", {goal: 1.0}))
        states.append(choices)
    states += [[], []]
    return build_mdp(states, target=[goal], sink=[dead])


def _chain_value(p: list[list[dict[int, Fraction]]], policy: tuple[int, ...],
                 goal: int) -> list[Fraction]:
    """The exact probability of reaching ``goal`` under ``policy`` (a choice index per
    state that has choices): 0 where the chain cannot reach it, else the unique
    solution of ``x = P x`` with ``x[goal] = 1`` there."""
    n = len(p)
    succ = [set(p[s][policy[s]]) if p[s] else set() for s in range(n)]
    reach = {goal}
    grew = True
    while grew:
        grew = False
        for s in range(n):
            if s not in reach and succ[s] & reach:
                reach.add(s)
                grew = True
    live = [s for s in sorted(reach) if s != goal]
    at = {s: i for i, s in enumerate(live)}
    k = len(live)
    a = [[Fraction(0)] * (k + 1) for _ in range(k)]
    for i, s in enumerate(live):
        a[i][i] += 1
        for t, q in p[s][policy[s]].items():
            if t == goal:
                a[i][k] += q
            elif t in at:
                a[i][at[t]] -= q
    for c in range(k):  # Gauss-Jordan in fractions (the matrix is invertible)
        piv = next(r for r in range(c, k) if a[r][c] != 0)
        a[c], a[piv] = a[piv], a[c]
        f = a[c][c]
        a[c] = [v / f for v in a[c]]
        for r in range(k):
            if r != c and a[r][c] != 0:
                g = a[r][c]
                a[r] = [v - g * w for v, w in zip(a[r], a[c], strict=True)]
    x = [Fraction(0)] * n
    x[goal] = Fraction(1)
    for s, i in at.items():
        x[s] = a[i][k]
    return x


def _optimum(mdp, sense: Sense) -> tuple[list[Fraction], list[int]]:
    """Per state the exact optimum over every deterministic memoryless policy (one is
    optimal in every state at once for reachability), and such a policy's rows."""
    m = mdp.matrix.tocsr()
    groups = np.asarray(mdp.row_groups)
    goal = int(np.flatnonzero(mdp.target)[0])
    n = mdp.n_states
    p = []
    for s in range(n):
        if s == goal or groups[s + 1] - groups[s] == 0:
            p.append([])
            continue
        rows = []
        for r in range(groups[s], groups[s + 1]):
            lo, hi = m.indptr[r], m.indptr[r + 1]
            rows.append({int(t): Fraction(float(v)) for t, v in
                         zip(m.indices[lo:hi], m.data[lo:hi], strict=True)})
        p.append(rows)
    # an absorbing state (one self-loop) plays its one choice
    ranges = [range(len(c)) if c else range(1) for c in p]
    best, arg = None, None
    for policy in itertools.product(*ranges):
        x = _chain_value(p, policy, goal)
        if best is None:
            best, arg = list(x), [list(policy) for _ in range(n)]
            continue
        for s in range(n):
            if (x[s] > best[s]) if sense is Sense.MAX else (x[s] < best[s]):
                best[s], arg[s] = x[s], list(policy)
    # one policy optimal everywhere: the state-wise best's own choices
    rows = [int(groups[s]) + arg[s][s] if p[s] else -1 for s in range(n)]
    return best, rows


def _random_policy(mdp, rng: random.Random) -> np.ndarray:
    groups = np.asarray(mdp.row_groups)
    policy = np.array([rng.randrange(groups[s], groups[s + 1]) if groups[s + 1] > groups[s]
                       else -1 for s in range(mdp.n_states)], dtype=np.int64)
    policy[mdp.target | absorbing_states(mdp)] = -1
    return policy


def test_bounds_on_the_optimum_hold_the_exact_value_on_either_levels() -> None:
    """A random policy's candidates (repaired along the levels) and the optimal
    policy's certificate, on the quotient's lifted levels and on the product's: each
    bound on the optimum is on the right side of the exact optimum in every state."""
    seen = {"repaired": 0, "lifted": 0, "removed": 0, "mecs": 0}
    for seed in SEEDS:
        mdp = _mdp(seed)
        rng = random.Random(1000 + seed)
        for sense in (Sense.MAX, Sense.MIN):
            exact, best_rows = _optimum(mdp, sense)
            q, _ = analyse(mdp, mdp.target, sense=sense)
            comp, level = (np.asarray(a) for a in q.layers)
            lifted = bool(np.any(level < 0))  # the quotient's levels (the product's: none)
            seen["lifted"] += lifted
            seen["removed"] += int(np.count_nonzero(
                (np.asarray(q.state_map) < 0) & ~np.asarray(q.prob0) & ~mdp.target))
            seen["mecs"] += int(q.mecs.n_mecs)
            rnd = rounding(mdp.matrix)
            decided = q.qualitative
            best = np.array(best_rows, dtype=np.int64)
            best[mdp.target | absorbing_states(mdp)] = -1
            for layers in (q.layers, support_layers(mdp)):
                for policy in (_random_policy(mdp, rng), best):
                    ch = chain(mdp, mdp.target, policy, rnd, layers)
                    if sense is Sense.MAX:
                        side = optimum_upper(mdp, ch, rnd, zero=decided.zero,
                                             layers=layers, mec_of=q.mecs.mec_of)
                        assert all(Fraction(float(v)) >= e for v, e in
                                   zip(side.vector, exact, strict=True)), (seed, side.check)
                    else:
                        side = optimum_lower(mdp, ch, rnd, zero=decided.zero,
                                             one=decided.one, layers=layers)
                        assert all(Fraction(float(v)) <= e for v, e in
                                   zip(side.vector, exact, strict=True)), (seed, side.check)
                    seen["repaired"] += (lifted and layers is q.layers
                                         and "repaired" in side.check.detail)
                cert = certify(mdp, mdp.target, best, sense=str(sense), zero=decided.zero,
                               one=decided.one if sense is Sense.MIN else None,
                               mec_of=None if sense is Sense.MIN else q.mecs.mec_of,
                               layers=layers)
                assert cert.certified, (seed, sense, cert.checks)
                s0 = int(mdp.initial)
                assert Fraction(cert.lower) <= exact[s0] <= Fraction(cert.upper), (seed, sense)
    # the draws reach what the change touches: repairs on the quotient's levels, levels
    # lifted from it, value-1 states removed from the quotient, end components collapsed
    assert all(v > 0 for v in seen.values()), seen
