"""The policy's flow through the quotient (``lp_blocks.policy_flow``) where the policy
takes some choices with weight 0 (a deterministic policy takes one of each state's
choices, a randomised one may leave some out): a level walked by NumPy pushes its flow
out along the entries of the taken choices only, and a level settled whole by its
greedy walk finds each exit entry's state by a gather (``Walked.push``).

Checked against an exact route written here: the occupancy ``y(c) = w(c) x(owner(c))``
with ``x = b + P_w^T x`` solved in fractions (Gauss-Jordan on the rationals of the
float64 entries, ``mitld_lp.testing.exact``), so the float answer may differ from it by
rounding only."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

from mitld_lp.solvers import lp_blocks, shared_levels
from mitld_lp.solvers.iteration import interval_iteration
from mitld_lp.solvers.lp import solve_lp
from mitld_lp.solvers.quotient import reduce
from mitld_lp.solvers.topological import blocks
from mitld_lp.testing import random_mdp
from mitld_lp.testing.exact import chain_values


def _exact_flow(q, weights: np.ndarray, b: np.ndarray) -> list[Fraction]:
    """``y(c) = w(c) x(owner(c))``, ``x = b + P_w^T x`` in exact rationals: the chain
    ``P_w^T`` with ``b(s)`` as each state's step into a goal of its own, solved by the
    shared fractions elimination (``mitld_lp.testing.exact``)."""
    n = q.n_states
    groups = np.asarray(q.row_groups)
    m = q.matrix.tocsr()
    goal = n
    step: list[dict[int, Fraction]] = [{goal: Fraction(float(b[s]))} for s in range(n)]
    for s in range(n):  # P_w^T[t, s] += w(c) P(c, t) for each choice c of s
        for c in range(int(groups[s]), int(groups[s + 1])):
            w = Fraction(float(weights[c]))
            if w == 0:
                continue
            for k in range(int(m.indptr[c]), int(m.indptr[c + 1])):
                t = int(m.indices[k])
                step[t][s] = step[t].get(s, Fraction(0)) + w * Fraction(float(m.data[k]))
    x = chain_values(step, list(range(n)), goal)
    return [Fraction(float(weights[c])) * x[s]
            for s in range(n) for c in range(int(groups[s]), int(groups[s + 1]))]


def _weights(q, rng: np.random.Generator, randomised: bool) -> np.ndarray:
    """One choice a state with weight 1, or random weights summing to 1 with some
    choices left out (weight 0)."""
    groups = np.asarray(q.row_groups)
    w = np.zeros(q.n_choices)
    for s in range(q.n_states):
        lo, hi = int(groups[s]), int(groups[s + 1])
        if not randomised:
            w[rng.integers(lo, hi)] = 1.0
            continue
        raw = rng.random(hi - lo) * (rng.random(hi - lo) < 0.6)
        if raw.sum() == 0.0:
            raw[rng.integers(0, hi - lo)] = 1.0
        w[lo:hi] = raw / raw.sum()
    return w


@pytest.mark.parametrize("randomised", [False, True])
@pytest.mark.parametrize("seed", range(4))
def test_flow_with_untaken_choices_is_the_exact_one(seed: int, randomised: bool) -> None:
    """The NumPy level walk (no runs, no walks kept) on a quotient with cyclic and
    single-state levels: the flow of a policy that leaves choices out is the exact
    occupancy up to rounding, and 0 (not merely small) on every choice left out."""
    mdp = random_mdp(45, seed=700 + seed, max_choices=3, target_fraction=0.08,
                     self_loop_fraction=0.1, locality=8)
    q = reduce(mdp, mdp.target)
    assert q.n_states > 0
    blk = blocks(q)
    rng = np.random.default_rng(seed)
    w = _weights(q, rng, randomised)
    b = rng.random(q.n_states)
    y = lp_blocks.policy_flow(q, blk, w, b)
    want = _exact_flow(q, w, b)
    err = max(abs(Fraction(float(got)) - exact) for got, exact in zip(y, want, strict=True))
    assert err <= Fraction(1, 10**10) * max(1, max(want))
    assert np.all(y[w == 0.0] == 0.0)
    assert np.any(w == 0.0)  # the path under test: some choices are left out


def test_levels_walked_by_numpy_include_cyclic_and_single_ones() -> None:
    """The MDPs above exercise both kinds of level the filter touches or leaves alone:
    a level of single states only, and one with a cyclic component."""
    kinds = set()
    for seed in range(4):
        mdp = random_mdp(45, seed=700 + seed, max_choices=3, target_fraction=0.08,
                         self_loop_fraction=0.1, locality=8)
        blk = blocks(reduce(mdp, mdp.target))
        for level in blk.walk(upstream_first=True):
            kinds.add("cyclic" if level.rest.size else "single")
    assert kinds == {"cyclic", "single"}


_GREEDY_SEEDS = (300, 301, 303, 305, 309)


@pytest.mark.parametrize("seed", _GREEDY_SEEDS)
def test_greedy_walked_levels_flow_is_the_exact_one(
        seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """Every block answered by the greedy check (its levels settled whole push their
    flow along their exits, each exit's state found by a gather): the returned
    occupancy is the exact flow of the returned randomised policy from every state
    (start weight 1 on each), up to rounding."""
    monkeypatch.setattr(lp_blocks, "GREEDY_MIN_CHOICES", 0)
    monkeypatch.setattr(lp_blocks, "RUNS_MIN_LEVELS", 1)
    monkeypatch.setattr(shared_levels, "RUNS_MIN_LEVELS", 1)
    pushed = []
    push = lp_blocks.Walked.push
    monkeypatch.setattr(lp_blocks.Walked, "push",
                        lambda self, *a: (pushed.append(self.row.size), push(self, *a)))
    mdp = random_mdp(60, seed=seed, max_choices=3, target_fraction=0.08,
                     self_loop_fraction=0.05, locality=12)
    it = interval_iteration(mdp, mdp.target, gap="max", tol=1e-12, precision=None,
                            progress=False)
    got = solve_lp(mdp, mdp.target, everywhere=True, bounds=(it.lower, it.upper))
    assert got.status.value == "optimal"
    q = reduce(mdp, mdp.target)
    w = np.asarray(got.randomized)[q.choice_origin]
    b = np.ones(q.n_states)  # every level carries flow, the walked ones too
    y = np.asarray(got.occupancy)[q.choice_origin]
    want = _exact_flow(q, w, b)
    err = max(abs(Fraction(float(g)) - e) for g, e in zip(y, want, strict=True))
    assert err <= Fraction(1, 10**10) * max(1, max(want))


def test_some_greedy_level_pushed_exits(monkeypatch: pytest.MonkeyPatch) -> None:
    """The seeds above reach a level settled whole whose exits push flow."""
    monkeypatch.setattr(lp_blocks, "GREEDY_MIN_CHOICES", 0)
    pushed = []
    push = lp_blocks.Walked.push
    monkeypatch.setattr(lp_blocks.Walked, "push",
                        lambda self, *a: (pushed.append(self.row.size), push(self, *a)))
    for seed in _GREEDY_SEEDS:
        mdp = random_mdp(60, seed=seed, max_choices=3, target_fraction=0.08,
                         self_loop_fraction=0.05, locality=12)
        it = interval_iteration(mdp, mdp.target, gap="max", tol=1e-12, precision=None,
                                progress=False)
        solve_lp(mdp, mdp.target, everywhere=True, bounds=(it.lower, it.upper))
    assert pushed and max(pushed) > 0
