"""The graph analysis (``mitld_lp.solvers.analysis.analyse``) against a brute-force fixed
point written here on Boolean matrices (a choice's support a row, a state's choices a
list of rows), on random small MDPs of three shapes: cyclic with end components of
several states, a deadline's shape (acyclic apart from self-loops: each staying state
an end component of its own) and one choice a state.  Both senses, both truncation
models (the goal, and the goal with the truncated states):

* ``Prob0A`` (no path): the least fixed point of one-step predecessors;
* ``Prob1E`` (a maximum's 1): the greatest ``X`` with ``X = mu Y. goal | {s : some
  choice stays in X and meets Y}``;
* ``Prob0E`` (a minimum's 0): the greatest set outside the goal in which every state
  has a choice staying inside;
* ``Prob1A`` (a minimum's 1): the states from which no path outside the goal reaches
  ``Prob0E``.

The lifted strategy on a maximum's value-1 states left out of the quotient
(``ATTRACTOR_STRATEGY``) is checked to reach the target almost surely: in its chain,
every state it plays reaches the target.  The entries a component holds inside it (the
gate of the compiled sweeps) are counted a chunk at a time and compared with one count
over every entry."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.mdp import MDP
from mitld_lp.solvers import analysis_patterns, walks
from mitld_lp.solvers.analysis import ATTRACTOR_STRATEGY, analyse
from mitld_lp.solvers.graph import Sense


def _mdp(seed: int, shape: str) -> tuple[MDP, list[np.ndarray], np.ndarray, np.ndarray]:
    """A random MDP of 6-14 states: goal, truncated and sink states absorbing; others
    1-3 choices (1 in ``"single"``) of 1-3 successors; in ``"cyclic"`` some goal states
    move on.  ``"deadline"``: successors only
    above the state, or a pure self-loop; ``"cyclic"``: anywhere, and some choices
    staying in a small group of neighbours (end components of several states).
    Returned with each state's choices as Boolean support rows, the goal and the
    truncated masks."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(6, 15))
    kind = rng.integers(0, 6, n)
    goal, extra, sink = kind == 0, kind == 1, kind == 2
    goal[n - 1], extra[n - 1], sink[n - 1] = True, False, False
    goal[0] = extra[0] = sink[0] = False
    supports: list[np.ndarray] = []
    rows, cols, vals, groups = [], [], [], [0]
    for s in range(n):
        posts: list[np.ndarray] = []
        if goal[s] and shape == "cyclic" and s < n - 1 and rng.random() < 0.5:
            # a goal state that moves on (not closed: the pattern of the maybe states'
            # rows is searched, not the product's own)
            post = np.zeros(n, dtype=bool)
            post[rng.integers(0, n, int(rng.integers(1, 3)))] = True
            posts.append(post)
        elif goal[s] or extra[s] or sink[s]:
            posts.append(np.arange(n) == s)
        else:
            for _ in range(1 if shape == "single" else int(rng.integers(1, 4))):
                post = np.zeros(n, dtype=bool)
                if shape == "deadline":
                    if s == n - 1 or rng.random() < 0.25:
                        post[s] = True
                    else:
                        post[rng.integers(s + 1, n, int(rng.integers(1, 4)))] = True
                elif shape == "cyclic" and rng.random() < 0.4:
                    lo = max(0, s - 2)
                    post[rng.integers(lo, min(n, s + 3), int(rng.integers(1, 3)))] = True
                else:
                    post[rng.integers(0, n, int(rng.integers(1, 4)))] = True
                posts.append(post)
        for i, post in enumerate(posts):
            cs = np.flatnonzero(post)
            p = rng.random(cs.size) + 0.1
            rows += [groups[-1] + i] * cs.size
            cols += cs.tolist()
            vals += (p / p.sum()).tolist()
        supports.append(np.array(posts))
        groups.append(groups[-1] + len(posts))
    matrix = sp.csr_array((vals, (rows, cols)), shape=(groups[-1], n))
    mdp = MDP(matrix=matrix, row_groups=np.asarray(groups, dtype=np.int64),
              choice_actions=np.zeros(groups[-1], dtype=np.int32), action_names=(),
              initial=0, target=goal | extra, sink=sink, truncated=extra, states=range(n))
    return mdp, supports, goal, extra


def _reach(supports: list[np.ndarray], target: np.ndarray, within: np.ndarray) -> np.ndarray:
    """States with a path to ``target`` whose states before it lie in ``within``."""
    got = target.copy()
    while True:
        more = np.array([w and not g and bool((c @ got).any())
                         for c, w, g in zip(supports, within, got, strict=True)])
        if not more.any():
            return got
        got |= more


def _prob1e(supports: list[np.ndarray], target: np.ndarray) -> np.ndarray:
    x = np.ones(target.size, dtype=bool)
    while True:
        y = target.copy()
        while True:
            more = np.array([not y[s] and any(bool((c[~x]).sum() == 0 and (c & y).any())
                                              for c in supports[s])
                             for s in range(target.size)])
            if not more.any():
                break
            y |= more
        if np.array_equal(x, y):
            return x
        x = y


def _prob0e(supports: list[np.ndarray], target: np.ndarray) -> np.ndarray:
    x = ~target
    while True:
        y = np.array([x[s] and any(not c[~x].any() for c in supports[s])
                      for s in range(target.size)])
        if np.array_equal(x, y):
            return x
        x = y


def _prob1a(supports: list[np.ndarray], target: np.ndarray) -> np.ndarray:
    return ~_reach(supports, _prob0e(supports, target), ~target)


@pytest.fixture(params=["numpy", "numpy_chunked"])
def route(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> str:
    """The NumPy walks (no numba compile in a test), and with the compiled sweeps' gate
    counted over chunks of a few entries and asked on every product."""
    monkeypatch.setattr(walks, "COMPILED_LOADED_MIN_ENTRIES", 10**12)
    monkeypatch.setattr(walks, "COMPILED_MIN_ENTRIES", 10**12)
    if request.param == "numpy_chunked":
        monkeypatch.setattr(analysis_patterns, "CHUNK_ENTRIES", 3)
    return request.param


@pytest.mark.parametrize("shape", ["cyclic", "deadline", "single"])
@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
def test_qualitative_sets_against_fixed_points(route: str, shape: str, sense: Sense) -> None:
    met_one = met_inside = 0
    for seed in range(40):
        mdp, supports, goal, extra = _mdp(seed, shape)
        n = mdp.n_states
        low, high = analyse(mdp, goal, extra, sense=sense)
        found = []
        for q, target in ((low, goal), (high, goal | extra)):
            where = f"seed {seed}, {shape}, {sense}, {route}"
            no_path = ~_reach(supports, target, np.ones(n, dtype=bool))
            decided = q.qualitative
            assert np.array_equal(decided.unreachable, no_path), where
            if sense is Sense.MAX:
                zero, one = no_path, _prob1e(supports, target)
            else:
                zero, one = _prob0e(supports, target), _prob1a(supports, target)
            assert np.array_equal(decided.zero, zero), where
            assert np.array_equal(decided.one, one), where
            met_one += int((one & ~target).any())
            met_inside += int((~zero & ~one).any())
            found.append((zero, one))
        # the shared quotient holds no target state, no state of value 0 in both models
        # and none of the goal's states of value 1
        kept = np.asarray(high.state_map) >= 0
        assert np.array_equal(kept, np.asarray(low.state_map) >= 0)
        assert not (kept & (goal | extra | found[1][0] | found[0][1])).any(), where
        strategy = high.shared.get(ATTRACTOR_STRATEGY)
        if sense is Sense.MAX and strategy is not None:
            _reaches_almost_surely(mdp, supports, goal, strategy)
    assert met_one and met_inside  # both kinds of states are met


def _reaches_almost_surely(mdp: MDP, supports: list[np.ndarray], goal: np.ndarray,
                           strategy: object) -> None:
    """In the chain of the strategy's states playing their choice (every other state
    absorbing unless it is the goal's), every played state reaches the goal, and the
    chain never leaves the played states but into the goal."""
    states = np.asarray(strategy.states)  # type: ignore[attr-defined]
    choices = np.asarray(strategy.choices)  # type: ignore[attr-defined]
    n = mdp.n_states
    played = np.zeros(n, dtype=bool)
    played[states] = True
    chain = [np.zeros((1, n), dtype=bool) for _ in range(n)]
    for s, c in zip(states.tolist(), choices.tolist(), strict=True):
        assert mdp.row_groups[s] <= c < mdp.row_groups[s + 1]
        post = supports[s][c - int(mdp.row_groups[s])]
        assert not (post & ~played & ~goal).any()
        chain[s] = post[None, :]
    assert _reach(chain, goal, played)[played].all()


def test_component_entries_counted_in_chunks(monkeypatch: pytest.MonkeyPatch) -> None:
    """The compiled sweeps' gate: the most entries inside one component, a chunk of
    states at a time, equal to one count over every entry (its owner's and its column's
    component compared), on random patterns and component labellings."""
    rng = np.random.default_rng(7)
    for _ in range(100):
        n = int(rng.integers(1, 40))
        per = rng.integers(0, 4, n)
        groups = np.concatenate([[0], np.cumsum(per)])
        counts = rng.integers(0, 4, int(groups[-1]))
        indptr = np.concatenate([[0], np.cumsum(counts)])
        indices = rng.integers(0, n, int(indptr[-1]))
        m = sp.csr_array((np.ones(indices.size), indices, indptr), shape=(groups[-1], n))
        comp = rng.integers(0, max(1, n // 3), n)
        owner = np.concatenate([np.full(int(indptr[groups[s + 1]] - indptr[groups[s]]), comp[s])
                                for s in range(n)] + [np.zeros(0, dtype=comp.dtype)])
        expect = max([int(np.sum((owner == k) & (comp[indices] == k)))
                      for k in range(int(comp.max()) + 1)] + [0])
        monkeypatch.setattr(analysis_patterns, "CHUNK_ENTRIES", int(rng.integers(1, 30)))
        assert analysis_patterns.largest_inside(m, groups, comp) == expect


@pytest.mark.parametrize("shape", ["cyclic", "deadline", "single"])
def test_value_one_on_the_product_as_on_the_copied_pattern(shape: str) -> None:
    """A maximum's value-1 states and strategy read by one attractor over the product's
    own rows (``prob1e_on_product``) are those of the pattern of the maybe states' rows
    copied (``value_one.prob1e_first`` without end components, ``prob1e_single_states``
    with single-state ones), wherever the product's other states are closed."""
    from mitld_lp.solvers.analysis_singles import (
        prob1e_on_product,
        prob1e_single_states,
        single_states,
    )
    from mitld_lp.solvers.end_components import maximal_end_components
    from mitld_lp.solvers.value_one import prob1e_first

    compared = 0
    for seed in range(40):
        mdp, supports, goal, extra = _mdp(seed, shape)
        n = mdp.n_states
        wide = goal | extra
        maybe = _reach(supports, wide, np.ones(n, dtype=bool)) & ~wide
        zero = ~_reach(supports, goal, np.ones(n, dtype=bool)) & ~goal
        mecs = maximal_end_components(mdp, maybe)
        if mecs.n_mecs and not single_states(mecs):
            continue
        m = sp.csr_array(mdp.matrix)
        got = prob1e_on_product(mdp, m, maybe, zero, mecs)
        if got is None:  # a goal state that moves on: the copied pattern only
            continue
        first = prob1e_first if not mecs.n_mecs else prob1e_single_states
        expect = first(mdp, m, maybe, zero, mecs)
        assert np.array_equal(got[0], expect[0]), f"seed {seed}"
        assert got[1] == expect[1], f"seed {seed}"
        compared += 1
    assert compared >= 10


def test_candidates_pattern_as_the_rows_copied() -> None:
    """The end components' candidates' pattern, made a slice at a time in the index
    type, has the pattern of their rows copied and renumbered (every other state one
    extra absorbing column), on random matrices with the slices forced small."""
    from mitld_lp.solvers import quotient_rows

    rng = np.random.default_rng(3)
    for _ in range(50):
        n = int(rng.integers(2, 30))
        per = rng.integers(1, 4, n)
        groups = np.concatenate([[0], np.cumsum(per)])
        counts = rng.integers(1, 4, int(groups[-1]))
        indptr = np.concatenate([[0], np.cumsum(counts)])
        m = sp.csr_array((rng.random(int(indptr[-1])) + 0.1,
                          rng.integers(0, n, int(indptr[-1])), indptr),
                         shape=(int(groups[-1]), n))
        cand = np.flatnonzero(rng.random(n) < 0.5)
        choices = np.concatenate([np.arange(groups[s], groups[s + 1]) for s in cand] +
                                 [np.zeros(0, dtype=np.int64)]).astype(np.int64)
        old = quotient_rows.SLICE
        quotient_rows.SLICE = int(rng.integers(1, 6))
        try:
            got = analysis_patterns.candidates_pattern(m, choices, cand, n)
        finally:
            quotient_rows.SLICE = old
        local = np.full(n, cand.size)
        local[cand] = np.arange(cand.size)
        rows = [local[m.indices[m.indptr[c]:m.indptr[c + 1]]].tolist() for c in choices]
        rows.append([cand.size])
        assert got.shape == (choices.size + 1, cand.size + 1)
        assert [got.indices[got.indptr[r]:got.indptr[r + 1]].tolist()
                for r in range(got.shape[0])] == rows
        assert np.all(got.data == 1.0)
