"""A maximum's end-component test after its Prob1E attractor (``analysis_ends``).

* :func:`~mitld_lp.solvers.compiled_graph.closed_among` against a greatest fixed point
  written here over Python sets (the states of the set keeping a choice whose support
  stays among the states kept, filtered until nothing changes), and its 0 against an
  enumeration of every subset for an end component;
* the lemma the analysis relies on: no end component of the maybe states meets the
  attractor of the prob-0 states (enumerated subsets, beside the attractor computed here
  as a least fixed point over sets);
* :func:`~mitld_lp.solvers.analysis_ends.ends_and_sure` against the route it replaces
  (:func:`end_components`, then :func:`prob1e_on_product`): the same components, value-1
  states and strategy, array for array, on the compiled walks.
"""

from __future__ import annotations

from itertools import combinations

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.mdp import MDP

pytest.importorskip("numba")

from mitld_lp.solvers import compiled_graph, walks  # noqa: E402
from mitld_lp.solvers.analysis_ends import end_components, ends_and_sure  # noqa: E402
from mitld_lp.solvers.analysis_singles import prob1e_on_product  # noqa: E402
from mitld_lp.solvers.graph import strong_components  # noqa: E402


def _mdp(rng: np.random.Generator, n: int, loops: float, extra: bool = False,
         ) -> tuple[MDP, list[list[set[int]]]]:
    """``n`` states, each 0-3 choices of 1-3 successors anywhere (a state without a
    choice now and then), a choice that stays put with probability ``loops``; the last
    state absorbing (the goal), with ``extra`` the one before it too (truncated)."""
    supports: list[list[set[int]]] = []
    groups = [0]
    for s in range(n):
        if s == n - 1 or (extra and s == n - 2):
            choices = [{s}]
        else:
            choices = []
            for _ in range(int(rng.choice([0, 1, 1, 2, 2, 3]))):
                if rng.random() < loops:
                    choices.append({s})
                    continue
                k = int(rng.integers(1, min(3, n) + 1))
                choices.append({int(t) for t in rng.choice(n, k, replace=False)})
        supports.append(choices)
        groups.append(groups[-1] + len(choices))
    # a dense table of the choices' rows: random positive weights on each support
    table = np.zeros((groups[-1], n))
    for row, post in enumerate(p for choices in supports for p in choices):
        weights = rng.random(len(post)) + 0.1
        table[row, sorted(post)] = weights / weights.sum()
    matrix = sp.csr_array(table)
    goal = np.zeros(n, dtype=bool)
    goal[-1] = True
    cut = np.zeros(n, dtype=bool)
    cut[n - 2] = extra
    no = np.zeros(n, dtype=bool)
    mdp = MDP(matrix=matrix, row_groups=np.asarray(groups, dtype=np.int64),
              choice_actions=np.zeros(groups[-1], dtype=np.int32), action_names=(),
              initial=0, target=goal | cut, sink=no, truncated=cut, states=range(n))
    return mdp, supports


def _kept_for_ever(supports: list[list[set[int]]], among: set[int]) -> set[int]:
    """The greatest subset of ``among`` whose every state has a choice with its whole
    support inside it (filtered until nothing changes)."""
    kept = set(among)
    while True:
        keep = {s for s in kept if any(post <= kept for post in supports[s])}
        if keep == kept:
            return kept
        kept = keep


def _is_end_component(supports: list[list[set[int]]], cs: set[int]) -> bool:
    """Whether ``cs`` is an end component: each state has a choice whose support stays
    inside, and those choices connect every state to every other."""
    inside = {s: [p for p in supports[s] if p <= cs] for s in cs}
    if not cs or any(not v for v in inside.values()):
        return False
    reach = {s: {s} for s in cs}
    for _ in range(len(cs)):
        for s in cs:
            for post in inside[s]:
                for t in post:
                    reach[s] |= reach[t]
    return all(reach[s] >= cs for s in cs)


def _has_end_component(supports: list[list[set[int]]], among: set[int]) -> bool:
    """Whether some subset of ``among`` is an end component, by enumeration."""
    return any(_is_end_component(supports, set(c)) for size in range(1, len(among) + 1)
               for c in combinations(sorted(among), size))


def _attractor(supports: list[list[set[int]]], seeds: set[int]) -> set[int]:
    """The least set holding ``seeds`` and each state with a choice whose every choice
    meets it."""
    got = set(seeds)
    while True:
        more = {s for s, choices in enumerate(supports)
                if choices and all(post & got for post in choices)}
        if more <= got:
            return got
        got |= more


def _mask(n: int, states: set[int]) -> np.ndarray:
    out = np.zeros(n, dtype=bool)
    out[sorted(states)] = True
    return out


@pytest.mark.parametrize("seed", range(60))
def test_closed_among_is_the_greatest_set_kept_for_ever(seed: int) -> None:
    rng = np.random.default_rng(780_000 + seed)
    n = int(rng.integers(2, 11))
    mdp, supports = _mdp(rng, n, loops=float(rng.choice([0.0, 0.2, 0.5])))
    m = sp.csr_array(mdp.matrix)
    for _ in range(4):
        among = {int(s) for s in np.flatnonzero(rng.random(n) < rng.random())}
        states = np.array(sorted(among), dtype=np.int64)
        got = compiled_graph.closed_among(m.indptr, m.indices, mdp.row_groups, states,
                                          _mask(n, among))
        kept = _kept_for_ever(supports, among)
        assert got == len(kept), (seed, among)
        assert (got == 0) == (not _has_end_component(supports, among)), (seed, among)


@pytest.mark.parametrize("seed", range(40))
def test_no_end_component_meets_the_prob0_attractor(seed: int) -> None:
    """The lemma of ``analysis_ends``: an end component among states outside the
    seeds lies wholly outside the seeds' attractor."""
    rng = np.random.default_rng(781_000 + seed)
    n = int(rng.integers(3, 10))
    _, supports = _mdp(rng, n, loops=0.3)
    seeds = {int(s) for s in np.flatnonzero(rng.random(n) < 0.25)}
    outside = set(range(n)) - _attractor(supports, seeds)
    rest = set(range(n)) - seeds
    for size in range(1, len(rest) + 1):
        for c in combinations(sorted(rest), size):
            if _is_end_component(supports, set(c)):
                assert set(c) <= outside, (seed, c)


def _same(a: object, b: object) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    return a.dtype == b.dtype and np.array_equal(a, b)


@pytest.fixture
def compiled(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every walk compiled, whatever the graph's size."""
    monkeypatch.setattr(walks, "COMPILED_LOADED_MIN_ENTRIES", 0)
    monkeypatch.setattr(walks, "COMPILED_MIN_ENTRIES", 0)


@pytest.mark.parametrize("seed", range(80))
def test_ends_and_sure_answers_as_the_route_it_replaces(seed: int, compiled: None) -> None:
    _check(seed)


def test_every_branch_is_met(compiled: None) -> None:
    """Over those seeds: no end component with value-1 states found early, some end
    component (searched as before), and products of single-state components."""
    kinds = {_check(seed) for seed in range(80)}
    assert kinds >= {"none, some sure", "some", "single", "some among the seeds"}, kinds


def _check(seed: int) -> str:
    """One product's comparison (the test above); the branch it met."""
    rng = np.random.default_rng(782_000 + seed)
    n = int(rng.integers(3, 12))
    # with a truncated state, as the analysis poses it: the maybe states those of the
    # wider target, the prob-0 states the goal's (a maybe state may be one of them)
    mdp, supports = _mdp(rng, n, loops=float(rng.choice([0.0, 0.1, 0.4])), extra=seed % 2 == 1)
    goal = np.asarray(mdp.target & ~mdp.truncated)
    wide = np.asarray(mdp.target)
    maybe = _mask(n, _reaching(supports, set(np.flatnonzero(wide).tolist()))) & ~wide
    zero = ~_mask(n, _reaching(supports, set(np.flatnonzero(goal).tolist()))) & ~goal
    _, comp = strong_components(sp.csr_array(
        (np.ones(mdp.matrix.nnz), mdp.matrix.indices,
         np.asarray(mdp.matrix.indptr)[mdp.row_groups]), shape=(n, n)))
    comp = np.asarray(comp, dtype=np.int64)
    mecs, got = ends_and_sure(mdp, comp, maybe, zero)
    want = end_components(mdp, comp, maybe)
    assert mecs.n_mecs == want.n_mecs
    assert np.array_equal(mecs.mec_of, want.mec_of)
    assert np.array_equal(mecs.internal, want.internal)
    if got is None:  # some end component, or every component one state: as before
        if not want.n_mecs or int(np.bincount(comp).max()) == 1:
            return "single"
        return "some among the seeds" if bool(np.all(zero[np.asarray(want.mec_of) >= 0])) \
            else "some"
    assert want.n_mecs == 0
    sure, played = got
    sure_want, played_want = prob1e_on_product(mdp, sp.csr_array(mdp.matrix), maybe, zero,
                                               want)
    assert _same(sure, sure_want)
    assert (played is None) == (played_want is None)
    if played is not None:
        for field in played.__dataclass_fields__:
            assert _same(getattr(played, field), getattr(played_want, field)), field
    # and the states of value 1, written here: those some policy keeps out of the
    # prob-0 attractor (no end component among the maybe states)
    assert np.array_equal(sure, maybe & ~_mask(n, _attractor(supports, set(
        np.flatnonzero(zero).tolist()))))
    return "none, some sure" if sure.any() else "none"


def _reaching(supports: list[list[set[int]]], target: set[int]) -> set[int]:
    got = set(target)
    while True:
        more = {s for s, choices in enumerate(supports) if any(p & got for p in choices)}
        if more <= got:
            return got
        got |= more
