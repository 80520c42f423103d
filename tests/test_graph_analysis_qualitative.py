"""The graph analysis (mitld_lp.solvers.analysis.analyse) on small random MDPs, with and
without cycles, against constructions written differently here: the qualitative sets
(prob0 / prob1 of both truncation models, for a maximum and a minimum) by plain fixed
points over Python sets, and the maximal end components by enumerating every subset of
states.  Each MDP is analysed on three routes: the NumPy walks (a small graph's reach
propagated up its levels), the NumPy walks with every graph counted large (the reach
searched once a seed set after the levels: ``level_search.reaching``, the levels'
probe and search, the attractor's counts by a sort), and the compiled walks (numba)."""

from __future__ import annotations

from itertools import combinations

import numpy as np
import pytest
import scipy.sparse as sp
from test_rare_solve import prob0_e  # Prob0E: the greatest fixed point over sets

from mitld_lp.mdp import MDP
from mitld_lp.solvers import graph, walks
from mitld_lp.solvers.analysis import analyse
from mitld_lp.solvers.graph import Sense

ROUTES = ("numpy", "numpy_large", "compiled")


def _random_mdp(seed: int, acyclic: bool) -> tuple[MDP, list[list[set[int]]], np.ndarray,
                                                    np.ndarray]:
    """An MDP of 4-9 states: the last two or three absorbing (goal, and an 'extra' set
    of truncated states when there are three), each other state 1-3 choices of 1-3
    successors (only to higher states when ``acyclic``; self-loops allowed else).
    Returned with each state's choices' supports, the goal and the extra mask."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(4, 10))
    n_abs = int(rng.integers(2, 4))
    goal = np.zeros(n, dtype=bool)
    extra = np.zeros(n, dtype=bool)
    goal[n - 1] = True
    if n_abs == 3:
        extra[n - 2] = True
    # the absorbing states that are neither goal nor extra: a plain sink (n_abs == 2: n-2)
    supports: list[list[set[int]]] = []
    rows, cols, vals, groups = [], [], [], [0]
    for s in range(n):
        if s >= n - n_abs:
            choices = [{s}]
        else:
            choices = []
            for _ in range(int(rng.integers(1, 4))):
                low = s + 1 if acyclic else 0
                k = int(rng.integers(1, min(3, n - low) + 1))
                choices.append({int(t) for t in rng.choice(np.arange(low, n), k,
                                                           replace=False)})
        supports.append(choices)
        for i, post in enumerate(choices):
            p = rng.random(len(post)) + 0.1
            rows += [groups[-1] + i] * len(post)
            cols += sorted(post)
            vals += (p / p.sum()).tolist()
        groups.append(groups[-1] + len(choices))
    n_choices = groups[-1]
    matrix = sp.csr_array((vals, (rows, cols)), shape=(n_choices, n))
    no = np.zeros(n, dtype=bool)
    mdp = MDP(matrix=matrix, row_groups=np.asarray(groups, dtype=np.int64),
              choice_actions=np.zeros(n_choices, dtype=np.int32), action_names=(),
              initial=0, target=goal | extra, sink=no, truncated=extra, states=range(n))
    return mdp, supports, goal, extra


def _pre_exists(supports: list[list[set[int]]], into: set[int], within: set[int]) -> set[int]:
    """States of ``within`` with a choice whose support meets ``into``."""
    return {s for s in within if any(post & into for post in supports[s])}


def _reach(supports: list[list[set[int]]], target: set[int]) -> set[int]:
    """States with a path to ``target`` (the target's states included)."""
    found = set(target)
    while True:
        more = _pre_exists(supports, found, set(range(len(supports))) - found)
        if not more:
            return found
        found |= more


def _prob1e(supports: list[list[set[int]]], target: set[int]) -> set[int]:
    """Some policy reaches the target almost surely: the nested fixed point (greatest
    outer, least inner) of Baier & Katoen's Alg. 45."""
    u = set(range(len(supports)))
    while True:
        r = set(target)
        while True:
            more = {s for s in u - r
                    if any(post <= u and post & r for post in supports[s])}
            if not more:
                break
            r |= more
        if r == u:
            return u
        u = r


def _prob1a(supports: list[list[set[int]]], target: set[int]) -> set[int]:
    """Every policy reaches the target almost surely: the states from which no path
    avoiding the target leads to a state of Prob0E."""
    bad = prob0_e(supports, target)
    found = set(bad)
    while True:
        more = _pre_exists(supports, found, set(range(len(supports))) - found - target)
        if not more:
            break
        found |= more
    return set(range(len(supports))) - found


def _brute_mecs(supports: list[list[set[int]]], among: set[int]) -> set[frozenset[int]]:
    """The maximal end components among the states ``among``, by enumeration: every
    subset with a choice a state that stays inside, strongly connected by those choices,
    and contained in no larger such subset."""
    ecs = []
    for size in range(1, len(among) + 1):
        for c in combinations(sorted(among), size):
            cs = set(c)
            inside = {s: [p for p in supports[s] if p <= cs] for s in cs}
            if any(not v for v in inside.values()):
                continue
            kept = [inside.get(s, []) for s in range(len(supports))]
            # strongly connected by the kept choices: every state reaches each one
            strongly = all(cs <= _reach(kept, {s}) for s in cs)
            if strongly:
                ecs.append(frozenset(cs))
    return {e for e in ecs if not any(e < f for f in ecs)}


def _mask(n: int, states: set[int]) -> np.ndarray:
    out = np.zeros(n, dtype=bool)
    out[sorted(states)] = True
    return out


@pytest.fixture(params=ROUTES)
def route(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> str:
    if request.param == "numpy":
        monkeypatch.setattr(walks, "COMPILED_LOADED_MIN_ENTRIES", 10**12)
        monkeypatch.setattr(walks, "COMPILED_MIN_ENTRIES", 10**12)
    elif request.param == "numpy_large":  # every graph past SMALL: reach searched
        monkeypatch.setattr(walks, "COMPILED_LOADED_MIN_ENTRIES", 10**12)
        monkeypatch.setattr(walks, "COMPILED_MIN_ENTRIES", 10**12)
        monkeypatch.setattr(graph, "SMALL", 0)
        monkeypatch.setattr(graph, "PROBE_LEVELS", 1)
        monkeypatch.setattr(graph, "SORTED_COUNTS", 1)  # the attractor's counts sorted
    else:
        pytest.importorskip("numba")
        monkeypatch.setattr(walks, "COMPILED_LOADED_MIN_ENTRIES", 0)
        monkeypatch.setattr(walks, "COMPILED_MIN_ENTRIES", 0)
    return request.param


@pytest.mark.parametrize("acyclic", [False, True])
@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
def test_qualitative_sets_and_end_components(route: str, acyclic: bool,
                                             sense: Sense) -> None:
    for seed in range(25):
        mdp, supports, goal, extra = _random_mdp(seed, acyclic)
        n = mdp.n_states
        low, high = analyse(mdp, goal, extra, sense=sense)
        sets = (set(np.flatnonzero(goal).tolist()),
                set(np.flatnonzero(goal | extra).tolist()))
        for q, target in zip((low, high), sets, strict=True):
            where = f"seed {seed}, {route}, {sense}, {'acyclic' if acyclic else 'cyclic'}"
            unreachable = _mask(n, set(range(n)) - _reach(supports, target))
            decided = q.qualitative
            assert np.array_equal(decided.unreachable, unreachable), where
            if sense is Sense.MAX:
                assert np.array_equal(decided.zero, unreachable), where
                assert np.array_equal(decided.one, _mask(n, _prob1e(supports, target))), where
            else:
                assert np.array_equal(decided.zero, _mask(n, prob0_e(supports, target))), where
                assert np.array_equal(decided.one, _mask(n, _prob1a(supports, target))), where
        # the end components: among the upper model's maybe states for a maximum (less
        # the goal's value-1 states, which leave the quotient), none for a minimum (the
        # states left have none: they could avoid the target)
        maybe = _reach(supports, sets[1]) - sets[1] - _prob1e(supports, sets[0])
        expect = _brute_mecs(supports, maybe) if sense is Sense.MAX else set()
        if acyclic:  # no cycle among the transient states, so no end component
            assert expect == set()
        mec_of = np.asarray(high.mecs.mec_of)
        got = {frozenset(np.flatnonzero(mec_of == i).tolist())
               for i in range(high.mecs.n_mecs)}
        assert got == expect, f"seed {seed}, {route}, {sense}"
        assert low.mecs is high.mecs
        internal = {(s, i) for s in range(n) for i, post in enumerate(supports[s])
                    if mec_of[s] >= 0 and post <= set(np.flatnonzero(mec_of == mec_of[s]))}
        flags = np.asarray(high.mecs.internal)
        got_internal = {(s, c - int(mdp.row_groups[s])) for s in range(n)
                        for c in mdp.choices(s) if flags[c]}
        assert got_internal == internal, f"seed {seed}, {route}, {sense}"


def test_the_generator_makes_both_kinds() -> None:
    """The cyclic MDPs hold end components among their transient states for some seeds,
    the acyclic ones never: both branches of the analysis are met."""
    found = [bool(_brute_mecs(s, _reach(s, set(np.flatnonzero(g | e).tolist()))
                              - set(np.flatnonzero(g | e).tolist())))
             for s, g, e in (_random_mdp(seed, False)[1:] for seed in range(25))]
    assert any(found) and not all(found)
