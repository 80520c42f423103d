"""The solve stage's memory-lean helpers answer what the plain constructions do: the
reversed graph built once for several backward searches (:class:`~mitld_lp.solvers.
graph.Reversed`: 4-byte indices, no float per edge), the support extremes read a batch
of rows at a time (:func:`~mitld_lp.solvers.rounding.support_extreme`), a block's rows
split once into the moves inside and out of it (:class:`~mitld_lp.solvers.topological.
Block`), the maximal end components from 4-byte edges, the Bellman check's rows'
states; each against a brute force written differently here, and the whole solve of
random PRISM MDPs against Storm's exact value."""

from __future__ import annotations

import random
import sys
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp import load_model, synthesize
from mitld_lp.mdp import MDP
from mitld_lp.solvers import lp_blocks, rounding
from mitld_lp.solvers.certify import Rows
from mitld_lp.solvers.graph import Reversed, backward_reachable, maximal_end_components
from mitld_lp.solvers.quotient import reduce
from mitld_lp.solvers.topological import Block
from mitld_lp.testing import random_mdp

sys.path.insert(0, str(Path(__file__).parent))
from storm_exact import random_prism, storm_rational  # noqa: E402


def _closure(n: int, source: np.ndarray, succ: np.ndarray, seeds: np.ndarray) -> np.ndarray:
    """States with a path to a seed: a fixpoint over the edge list, no graph library."""
    reached = np.asarray(seeds, dtype=bool).copy()
    edges = list(zip(source.tolist(), succ.tolist(), strict=True))
    changed = True
    while changed:
        changed = False
        for s, t in edges:
            if reached[t] and not reached[s]:
                reached[s] = changed = True
    return reached


def test_reversed_answers_each_seed_set_as_a_fresh_search() -> None:
    rng = np.random.default_rng(7)
    n, m = 60, 110
    source = rng.integers(0, n, m).astype(np.int32)
    succ = rng.integers(0, n, m).astype(np.int32)
    graph = Reversed(n, source, succ)
    # many seeds first, then fewer: the earlier search's seed row must not leak
    for k in (25, 3, 0, 1, 40):
        seeds = np.zeros(n, dtype=bool)
        seeds[rng.choice(n, k, replace=False)] = True
        expected = _closure(n, source, succ, seeds)
        assert np.array_equal(graph.reaching(seeds), expected)
        assert np.array_equal(backward_reachable(n, source.astype(np.int64),
                                                 succ.astype(np.int64), seeds), expected)


def test_support_extreme_in_batches_is_the_per_row_extreme(monkeypatch) -> None:
    rng = np.random.default_rng(3)
    dense = rng.random((40, 25)) * (rng.random((40, 25)) < 0.2)
    dense[5] = 0.0  # an empty row: its extreme is the empty max/min (-inf / inf)
    matrix = sp.csr_array(dense)
    x = rng.random(25)
    rows = rng.integers(0, 40, 33)
    monkeypatch.setattr(rounding, "BATCH", 4)  # several batches, the last one short
    for largest in (True, False):
        got = rounding.support_extreme(matrix, rows, x, largest)
        for i, r in enumerate(rows.tolist()):
            support = [x[j] for j in range(25) if dense[r, j] != 0.0]
            want = (max(support) if largest else min(support)) if support else (
                -np.inf if largest else np.inf)
            assert got[i] == want


def test_reversed_keeps_four_bytes_an_edge_and_no_weights() -> None:
    rng = np.random.default_rng(5)
    graph = Reversed(30, rng.integers(0, 30, 80), rng.integers(0, 30, 80))  # int64 in
    assert graph.indices.dtype == np.int32 and graph.indptr.dtype == np.int32
    assert graph.weights.strides == (0,)  # one value for every edge, not 8 bytes each


def test_block_holds_each_entry_once_inside_or_out() -> None:
    mdp = random_mdp(80, seed=4, locality=6)
    q = reduce(mdp, np.asarray(mdp.target))
    rng = np.random.default_rng(0)
    for k in (1, 7, q.n_states // 2, q.n_states):
        states = np.sort(rng.choice(q.n_states, k, replace=False))
        block = Block.of(q, states)
        dense = q.matrix.toarray()[block.choices]  # the block's rows, whole
        inside = np.zeros(q.n_states, dtype=bool)
        inside[states] = True
        assert np.array_equal(block.inner.toarray(), dense[:, states])
        assert np.array_equal(block.outer.toarray(), np.where(inside, 0.0, dense))
        # every stored entry once: none of the block's columns kept in outer
        assert block.inner.nnz + block.outer.nnz == np.count_nonzero(dense)
        assert not inside[block.outer.indices].any()


def _mecs_by_hand(mdp: MDP, mask: np.ndarray) -> tuple[set[frozenset], set[int]]:
    """The maximal end components of ``mask``'s states and their internal choices: sets
    of states and of choices, mutual reachability by Python sets, no graph library."""
    m = sp.csr_array(mdp.matrix)
    support = [frozenset(m.indices[m.indptr[c]:m.indptr[c + 1]][
        m.data[m.indptr[c]:m.indptr[c + 1]] > 0].tolist()) for c in range(m.shape[0])]
    owner = {c: s for s in range(mdp.n_states) for c in mdp.choices(s)}
    alive = {s for s in range(mdp.n_states) if mask[s]}
    allowed = {c for c in owner if owner[c] in alive}
    while True:
        while True:  # choices that stay among the states left, states left a choice
            allowed = {c for c in allowed if owner[c] in alive and support[c] <= alive}
            kept = {s for s in alive if any(owner[c] == s for c in allowed)}
            if kept == alive:
                break
            alive = kept
        reach = {s: {s} for s in alive}
        for _ in range(len(alive)):
            for c in allowed:
                reach[owner[c]] |= set().union(*(reach[t] for t in support[c]))
        scc = {s: frozenset(t for t in reach[s] if s in reach[t]) for s in alive}
        leaving = {c for c in allowed if not support[c] <= scc[owner[c]]}
        if not leaving:
            return set(scc.values()), allowed
        allowed -= leaving


@pytest.mark.parametrize("seed", range(6))
def test_end_components_match_a_brute_force(seed: int) -> None:
    mdp = random_mdp(40, seed=seed, max_choices=3, max_successors=2, locality=3,
                     self_loop_fraction=0.2)
    mask = np.random.default_rng(seed).random(40) < 0.9
    found = maximal_end_components(mdp, mask)
    comps, internal = _mecs_by_hand(mdp, mask)
    got = {frozenset(np.flatnonzero(found.mec_of == k).tolist())
           for k in range(found.n_mecs)}
    assert got == comps
    assert set(np.flatnonzero(found.internal).tolist()) == internal


def test_row_states_are_four_bytes_where_the_states_fit() -> None:
    groups = np.array([0, 2, 2, 5, 6])  # state 1 without a choice
    rows = Rows(sp.csr_array(np.eye(6)), groups)
    got = rows.row_state()
    assert got.dtype == np.int32
    assert got.tolist() == [0, 0, 2, 2, 2, 3]


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("objective", ["max", "min"])
def test_solve_of_random_mdps_holds_storms_exact_value(tmp_path: Path, seed: int,
                                                       objective: str,
                                                       monkeypatch: pytest.MonkeyPatch,
                                                       ) -> None:
    # cycles and end components (random branches), every block tried greedily first
    monkeypatch.setattr(lp_blocks, "GREEDY_MIN_CHOICES", 0)
    rng = random.Random(seed)
    prism = random_prism(rng, rng.randint(8, 14))
    (tmp_path / "w.prism").write_text(prism)
    path = tmp_path / "w.toml"
    path.write_text(f'name = "w"\nspec = "F goal"\nobjective = "{objective}"\n'
                    '[prism]\nfile = "w.prism"\n')
    r = synthesize(load_model(path))
    exact = storm_rational(tmp_path / "w.prism", f'P{objective}=? [F "goal"]')
    assert r.certified
    assert Fraction(r.lower) <= exact <= Fraction(r.upper)
