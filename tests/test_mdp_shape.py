"""The shape every MDP-shaped record shares (mitld_lp.mdp.MDPShape): sizes, choice to
state and successors of the product's MDP, the interval MDP, the robust game, the
quotient and a DRN file's model, each against a count made here from the record's own
arrays by a loop over dense rows."""

from __future__ import annotations

import numpy as np
import pytest

from mitld_lp.mdp import MDPShape
from mitld_lp.model import Model
from mitld_lp.routes.robust import interval_export, robust_game
from mitld_lp.solvers.quotient import reduce
from mitld_lp.solvers.robust_export import interval_drn
from mitld_lp.testing import random_mdp
from mitld_lp.worlds.grid import GridWorld


def brute(record: MDPShape, rows, groups, n_states: int) -> None:  # noqa: ANN001
    """``record``'s shape against ``rows`` (its distributions, dense) grouped by
    ``groups`` per choice (None: one each), over ``n_states`` states."""
    n_choices = len(groups) - 1 if groups is not None else rows.shape[0]
    assert record.n_states == n_states
    assert record.n_choices == n_choices
    assert record.n_transitions == int(np.count_nonzero(rows))  # no stored zeros here
    owner = [s for s in range(n_states) for _ in record.choices(s)]
    assert owner == record.choice_state().tolist()
    assert sorted(c for s in range(n_states) for c in record.choices(s)) == list(
        range(n_choices))
    for c in range(n_choices):
        mine = range(c, c + 1) if groups is None else range(groups[c], groups[c + 1])
        reach = sorted({int(t) for r in mine for t in np.flatnonzero(rows[r] > 0)})
        assert record.successors(c).tolist() == reach, c


@pytest.fixture(scope="module")
def band_product():
    """A band on one event: an interval MDP with ambiguous choices."""
    from mitld_lp.distributions.literal import from_table

    world = GridWorld.make(3, 2, start=(0, 0), slip=0.1, regions={"A": [(2, 1)]})
    band = from_table({"geometric": [0.2, 0.4]}, "distributions.mu")
    model = Model.from_game(world, "D[mu] b & F(b & F[0,2] A)", distributions={"mu": band})
    return interval_export(model)


@pytest.mark.parametrize("seed", range(3))
def test_an_mdp_and_its_quotient(seed: int) -> None:
    mdp = random_mdp(60, seed=seed, locality=4 if seed else None, sink_fraction=0.1)
    brute(mdp, mdp.matrix.toarray(), None, len(mdp.states))
    assert mdp.n_choices == len(mdp.choice_actions)
    q = reduce(mdp, mdp.target)
    brute(q, q.matrix.toarray(), None, int(q.state_map.max()) + 1)
    assert q.n_choices == q.choice_origin.size


def test_the_interval_mdp_its_robust_game_and_its_drn(band_product) -> None:  # noqa: ANN001
    imdp, target = band_product
    assert imdp.ambiguous_choices > 0
    brute(imdp, imdp.branches.toarray(), imdp.branch_groups, len(imdp.states))
    game = robust_game(imdp)
    brute(game, game.matrix.toarray(), game.vertex_groups, len(imdp.states))
    # no band reaches 0 or 1: every branch is some vertex's possible outcome
    for c in range(imdp.n_choices):
        assert game.successors(c).tolist() == imdp.successors(c).tolist()
    model = interval_drn(imdp, target)
    outcomes = sum(int(imdp.branch_groups[c + 1] - imdp.branch_groups[c])
                   for c in range(imdp.n_choices)
                   if imdp.band_groups[c + 1] > imdp.band_groups[c])
    brute(model, model.matrix.toarray(), None, imdp.n_states + outcomes)


def test_a_stored_zero_is_an_entry_but_no_successor() -> None:
    from dataclasses import replace

    import scipy.sparse as sp

    mdp = random_mdp(30, seed=5)
    m = mdp.matrix.tocoo()
    free = int(np.setdiff1d(np.arange(30), m.col[m.row == 0])[0])
    rows, cols = np.append(m.row, 0), np.append(m.col, free)
    order = np.lexsort((cols, rows))
    indptr = np.concatenate([[0], np.cumsum(np.bincount(rows, minlength=m.shape[0]))])
    stored = sp.csr_array((np.append(m.data, 0.0)[order], cols[order], indptr), shape=m.shape)
    zero = replace(mdp, matrix=stored)
    assert zero.n_transitions == mdp.n_transitions + 1
    assert free not in zero.successors(0).tolist()
    assert zero.successors(0).tolist() == mdp.successors(0).tolist()
