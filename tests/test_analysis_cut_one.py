"""The value-1 sets the analysis reports (``Quotient.qualitative.one``) after the goal's
value-1 states left the quotient, on random MDPs larger than exact policy enumeration
reaches (8-24 states, end components, self-loops, truncated states or none): since the
goal's own model is no longer searched a second time on the cut quotient
(:func:`~mitld_lp.solvers.analysis.analyse`), each model's set is checked against the
textbook fixpoints on a list-of-sets graph (Baier and Katoen, chapter 10.6; the brute
forces of ``test_rare_solve``): a maximum's ``Prob1E`` as the nested fixpoint ``nu X.
mu Y. T | {s : some choice stays in X and hits Y}``, a minimum's ``Prob1A`` as the
states that cannot reach ``Prob0E`` (``nu Z. {s not in T : some choice stays in Z}``)
through states outside the target."""

from __future__ import annotations

import numpy as np
import pytest
from test_analysis_half_quotient import as_mdp
from test_rare_solve import prob0_e, prob1_e, reach_avoiding

from mitld_lp.solvers.analysis import analyse
from mitld_lp.solvers.graph import Sense

SEEDS = range(40)


def _draw(seed: int, truncated: bool) -> tuple[np.ndarray, list[int]]:
    """A dense (choices x states) table: 8-24 states, the last absorbing (the goal), with
    ``truncated`` the one before it absorbing too; every other state 1-3 choices of 1-3
    successors anywhere (cycles), or a self-loop alone now and then."""
    rng = np.random.default_rng(4500 + seed)
    n = int(rng.integers(8, 25))
    absorbing = 2 if truncated else 1
    rows, owner = [], []
    for s in range(n):
        for _ in range(1 if s >= n - absorbing else int(rng.integers(1, 4))):
            w = np.zeros(n)
            if s >= n - absorbing or rng.random() < 0.12:
                w[s] = 1.0
            else:
                k = int(rng.integers(1, 4))
                w[rng.choice(n, k, replace=False)] = rng.integers(1, 5, k)
            rows.append(w / w.sum())
            owner.append(s)
    return np.array(rows), owner


def _choices(dense: np.ndarray, owner: list[int]) -> list[list[set[int]]]:
    """Each state's choices as the sets of their successors."""
    out: list[list[set[int]]] = [[] for _ in range(dense.shape[1])]
    for c, s in enumerate(owner):
        out[s].append(set(np.flatnonzero(dense[c] > 0).tolist()))
    return out


def _prob1a(choices: list[list[set[int]]], target: set[int]) -> set[int]:
    """``Prob1A``: the states with no path to ``Prob0E`` outside the target."""
    bad = reach_avoiding(choices, prob0_e(choices, target), target)
    return set(range(len(choices))) - bad


@pytest.mark.parametrize("truncated", [False, True])
@pytest.mark.parametrize("sense", [Sense.MIN, Sense.MAX])
def test_value_one_sets_of_both_models(sense: Sense, truncated: bool) -> None:
    removed = 0
    for seed in SEEDS:
        dense, owner = _draw(seed, truncated)
        mdp = as_mdp(dense, owner, truncated)
        n = dense.shape[1]
        goal = np.zeros(n, dtype=bool)
        goal[-1] = True
        extra = np.asarray(mdp.truncated)
        low, high = analyse(mdp, goal, extra, sense=sense)
        succ = _choices(dense, owner)
        for q, target in ((low, goal), (high, goal | extra)):
            t = set(np.flatnonzero(target).tolist())
            want = prob1_e(succ, t) if sense is Sense.MAX else _prob1a(succ, t)
            got = set(np.flatnonzero(np.asarray(q.qualitative.one)).tolist())
            assert got == want, (seed, sense, truncated)
        removed += int(np.count_nonzero((np.asarray(low.state_map) < 0)
                                        & np.asarray(low.qualitative.one) & ~goal))
    assert removed > 0  # some value-1 states did leave the quotient
