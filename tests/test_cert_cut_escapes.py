"""The minimum's proof that no end component is left, walked on the rows of the states
that may hold one (:func:`mitld_lp.solvers.certify_chain.attracted`), against a fixed
point written differently: every state's choices re-read, round after round, over the
whole model, until nothing joins (no predecessor lists, no sub-matrix)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.solvers import certify as C
from mitld_lp.solvers.certify_chain import attracted, support_layers
from mitld_lp.testing import random_mdp


def _attractor_by_rounds(m: sp.csr_array, groups: np.ndarray, seeds: np.ndarray
                         ) -> np.ndarray:
    """The states from which every policy reaches ``seeds`` with positive probability:
    a state joins once each of its choices (it has one) has a successor in the set."""
    inside = seeds.copy()
    while True:
        grown = inside.copy()
        for s in np.flatnonzero(~inside):
            lo, hi = int(groups[s]), int(groups[s + 1])
            if hi == lo:
                continue
            if all(bool(np.any(inside[m.indices[m.indptr[c]:m.indptr[c + 1]]]))
                   for c in range(lo, hi)):
                grown[s] = True
        if np.array_equal(grown, inside):
            return inside
        inside = grown


def _with_gaps(mdp, rng: np.random.Generator) -> tuple[sp.csr_array, np.ndarray]:
    """``mdp``'s rows with some states' choices dropped (no choice: where a play stops)
    and some choices emptied (no entry: never hit), the cases the walk treats apart."""
    m = sp.csr_array(mdp.matrix)
    groups = np.asarray(mdp.row_groups, dtype=np.int64)
    n = groups.size - 1
    keep_state = rng.random(n) > 0.1
    rows, new_groups = [], [0]
    for s in range(n):
        if keep_state[s]:
            rows.extend(range(int(groups[s]), int(groups[s + 1])))
        new_groups.append(len(rows))
    sub = sp.csr_array(m[np.asarray(rows, dtype=np.int64)])
    lil = sub.tolil()
    for r in np.flatnonzero(rng.random(sub.shape[0]) < 0.05):
        lil.rows[r], lil.data[r] = [], []
    return sp.csr_array(lil), np.asarray(new_groups, dtype=np.int64)


@pytest.mark.parametrize("seed", range(8))
def test_attracted_is_the_whole_attractor_on_its_states(seed: int) -> None:
    rng = np.random.default_rng(seed)
    mdp = random_mdp(120, seed=seed, locality=4 + seed, self_loop_fraction=0.05 * seed,
                     max_choices=3)
    m, groups = _with_gaps(mdp, rng)
    has = np.diff(groups) > 0
    agreed = set()
    for k in range(12):
        inside = (rng.random(groups.size - 1) < rng.uniform(0.1, 0.95)) & has
        if k % 2:  # its states the others attract: a set every policy leaves
            inside &= _attractor_by_rounds(m, groups, ~inside)
        if not inside.any():
            continue
        truth = bool(np.all(_attractor_by_rounds(m, groups, ~inside)[inside]))
        assert attracted(m, groups, inside) == truth
        agreed.add(truth)
    assert agreed == {True, False}  # both verdicts met


def test_a_trap_of_two_states_is_not_attracted() -> None:
    """States 0 and 1 each have a choice staying between them (an end component) and a
    choice to 2; state 2 (outside) reaches nothing among them: the attractor of the
    others misses them.  With the staying choices removed, every choice leaves."""
    m = sp.csr_array(np.array([[0.0, 1.0, 0.0],   # 0: stay (to 1)
                               [0.0, 0.0, 1.0],   # 0: leave
                               [1.0, 0.0, 0.0],   # 1: stay (to 0)
                               [0.5, 0.0, 0.5],   # 1: mixed: hits 2
                               [0.0, 0.0, 1.0]]))  # 2
    groups = np.array([0, 2, 4, 5])
    inside = np.array([True, True, False])
    assert not attracted(m, groups, inside)
    leave = sp.csr_array(m[[1, 3, 4]])
    assert attracted(leave, np.array([0, 1, 2, 3]), inside)


@pytest.mark.parametrize("seed", range(4))
def test_escapes_agrees_with_the_whole_attractor(seed: int) -> None:
    mdp = random_mdp(300, seed=seed, locality=6, self_loop_fraction=0.03, max_choices=3)
    comp, _ = support_layers(mdp)
    m, groups = sp.csr_array(mdp.matrix), np.asarray(mdp.row_groups, dtype=np.int64)
    rng = np.random.default_rng(seed)
    from mitld_lp.solvers.analysis import may_cycle

    for _ in range(4):
        left = rng.random(mdp.n_states) < rng.uniform(0.2, 0.9)
        inside = left & may_cycle(mdp, np.asarray(comp))
        seeds = ~inside | (np.diff(groups) == 0)
        truth = bool(np.all(_attractor_by_rounds(m, groups, seeds)[inside]))
        assert C._escapes(mdp, left, np.asarray(comp)) == truth
