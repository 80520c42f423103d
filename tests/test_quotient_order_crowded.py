"""The analysis's tests of the product's components (:func:`~mitld_lp.solvers.
quotient_order.mixed`, :func:`~mitld_lp.solvers.quotient_order.may_split`,
:func:`~mitld_lp.solvers.quotient_order.split`) read only the states of components of
more than one state (:func:`~mitld_lp.solvers.quotient_order.crowded`): each checked
against its definition counted a component at a time in plain Python, with the crowd
given and found, on random labels (hypothesis) and on labels of single states only; and
a maximum's attractor strategy against a first choice found by a loop."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mitld_lp.solvers.quotient_order import crowded, may_split, mixed, split


def _members(comp: np.ndarray) -> dict[int, list[int]]:
    out: dict[int, list[int]] = {}
    for s, c in enumerate(comp.tolist()):
        out.setdefault(c, []).append(s)
    return out


@st.composite
def _labelled(draw: st.DrawFn) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n = draw(st.integers(0, 60))
    top = draw(st.integers(1, 70))
    comp = np.array(draw(st.lists(st.integers(0, top - 1), min_size=n, max_size=n)),
                    dtype=draw(st.sampled_from([np.int32, np.int64])))
    maybe = np.array(draw(st.lists(st.booleans(), min_size=n, max_size=n)), dtype=bool)
    sure = np.array(draw(st.lists(st.booleans(), min_size=n, max_size=n)), dtype=bool)
    if draw(st.booleans()):  # the analysis's case: no state in both
        sure &= ~maybe
    return comp, maybe, sure


@settings(max_examples=300, deadline=None)
@given(_labelled())
def test_the_components_tests_against_their_definitions(
        case: tuple[np.ndarray, np.ndarray, np.ndarray]) -> None:
    comp, maybe, sure = case
    groups = _members(comp)
    crowd = crowded(comp)
    assert crowd.tolist() == [s for s in range(comp.size) if len(groups[int(comp[s])]) > 1]
    want_mixed = any(len({bool(maybe[s]) for s in v}) == 2 for v in groups.values())
    want_may = any(len(v) > 1 and any(maybe[s] for s in v) for v in groups.values())
    want_split = any(any(maybe[s] for s in v) and any(sure[s] for s in v)
                     for v in groups.values())
    for given_crowd in (None, crowd):
        assert mixed(comp, maybe, given_crowd) is want_mixed
        assert may_split(comp, maybe, given_crowd) is want_may
        assert split(comp, maybe, sure, given_crowd) is want_split


def test_single_states_have_no_crowd() -> None:
    """Every component one state (a deadline's product): no crowd, and no component
    is mixed or may split; one split only where a state is in both sets."""
    rng = np.random.default_rng(3)
    comp = rng.permutation(500).astype(np.int32)
    maybe = rng.random(500) < 0.5
    assert crowded(comp).size == 0
    assert not mixed(comp, maybe) and not may_split(comp, maybe)
    assert not split(comp, maybe, ~maybe)
    both = ~maybe
    both[int(np.flatnonzero(maybe)[0])] = True
    assert split(comp, maybe, both)
    assert crowded(np.zeros(0, dtype=np.int64)).size == 0


def test_the_attractor_strategy_plays_each_states_first_spared_choice() -> None:
    """:func:`~mitld_lp.solvers.value_one.attractor_strategy` without end components:
    each sure state's first choice (in row order) that the attractor spared, by a loop."""
    from mitld_lp.solvers.end_components import EndComponents
    from mitld_lp.solvers.value_one import attractor_strategy
    from mitld_lp.testing import random_mdp

    rng = np.random.default_rng(11)
    for seed in range(30):
        mdp = random_mdp(int(rng.integers(2, 40)), seed=seed)
        n, k = mdp.n_states, mdp.n_choices
        groups = np.asarray(mdp.row_groups)
        spared = rng.random(k) < 0.6
        sure = rng.random(n) < 0.5
        for s in range(n):  # each sure state keeps one spared choice (the fixed point's)
            if sure[s] and not spared[groups[s]:groups[s + 1]].any():
                spared[int(rng.integers(groups[s], groups[s + 1]))] = True
        got = attractor_strategy(mdp, sure, spared, groups, np.arange(k), np.arange(n), n,
                                 EndComponents.none(n, k))
        want = [(s, next(c for c in range(groups[s], groups[s + 1]) if spared[c]))
                for s in range(n) if sure[s]]
        assert got is not None
        assert list(zip(got.states.tolist(), got.choices.tolist(), strict=True)) == want


def test_a_graph_past_int32_takes_numpys_walks(monkeypatch) -> None:
    """The compiled components walk int32 graphs only (``compiled_graph.fits``): with the
    bound lowered below a graph's size, the levels and the end components are NumPy's
    (no compiled kernel called), the same as the compiled walk's below it."""
    import scipy.sparse as sp

    from mitld_lp.solvers import graph
    from mitld_lp.solvers.end_components import maximal_end_components
    from mitld_lp.testing import random_mdp

    pytest.importorskip("numba")
    from mitld_lp.solvers import compiled_graph, walks

    mdp = random_mdp(300, seed=4)
    m, groups = sp.csr_array(mdp.matrix), np.asarray(mdp.row_groups)
    assert compiled_graph.fits(mdp.n_states, m.nnz)
    fast = graph.state_levels(m, groups, walks=compiled_graph)
    monkeypatch.setattr(walks, "compiled_walks", lambda entries: compiled_graph)
    monkeypatch.setattr(graph, "compiled_walks", lambda entries: compiled_graph)
    from mitld_lp.solvers import end_components
    monkeypatch.setattr(end_components, "compiled_walks", lambda entries: compiled_graph)
    mecs_fast = maximal_end_components(mdp, np.ones(mdp.n_states, dtype=bool))
    monkeypatch.setattr(compiled_graph, "INDEX_LIMIT", mdp.n_states)  # the graph past it
    assert not compiled_graph.fits(mdp.n_states, m.nnz)
    for name in ("state_levels", "components_and_levels", "end_components_among"):
        def refuse(*args, name=name):
            raise AssertionError(f"{name} called past the bound")
        monkeypatch.setattr(compiled_graph, name, refuse)
    slow = graph.state_levels(m, groups, walks=compiled_graph)
    assert np.array_equal(slow.component, fast.component)
    assert np.array_equal(slow.level, fast.level)
    mecs_slow = maximal_end_components(mdp, np.ones(mdp.n_states, dtype=bool))
    assert mecs_slow.n_mecs == mecs_fast.n_mecs
    assert np.array_equal(np.asarray(mecs_slow.mec_of), np.asarray(mecs_fast.mec_of))
    assert np.array_equal(np.asarray(mecs_slow.internal), np.asarray(mecs_fast.internal))
