"""The two truncation models' LPs build the single-state levels once (lp-78).

The plain route solves a model's LP and then the other's, on two quotients of one
analysis that share their matrix, order and row groups.  The first LP now leaves the
levels kept (``levels_after``) and the second takes them:

* over the two LPs ``SingleLevels`` is built once (it was twice), and each LP's
  values and policy are the same bits as with ``levels_after`` off;
* each model's value at every state equals the exact optimum of the model, by
  backward induction in fractions over the layers (a truncated state counts 0 in the
  lower model, 1 in the upper one), within the LP's tolerance;
* nothing is left kept after the second LP (it takes them), and an LP with
  ``levels_after`` whose follower never comes leaves them only while its quotient's
  matrix lives;
* ``keeping_zero(q, zero_only=True)`` (the LPs' call: only the known zeros' rows read)
  is, on the zero states, a loop's first choice that keeps 0, elsewhere the first;
  and ``first_staying`` is test_csma_mem's loop; both with their entries read in
  chunks of 1, a few and 8,192.
"""

from __future__ import annotations

import gc
from fractions import Fraction

import numpy as np
import pytest
from conftest import build_mdp
from test_peak_1e6 import brute_keeping_zero
from test_single_levels import layered_mdp, recursion_values

from mitld_lp.solvers import rows
from mitld_lp.solvers import shared_levels as shared_mod
from mitld_lp.solvers.analysis import analyse
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.lp import solve_lp
from mitld_lp.solvers.shared_levels import RUNS_MIN_LEVELS


def _layers(seed: int):
    """:func:`test_single_levels._layered`'s layers (40 of 3 states) with its dead end
    a truncated state: the MDP, each state's exact rows, the goal and the layers'
    states' count."""
    _, exact, goal = layered_mdp(seed, depth=40)
    states = [[(f"a{k}", row) for k, row in enumerate(rows)] for rows in exact]
    states += [[], []]
    return build_mdp(states, target=[goal], truncated=[goal + 1]), exact, goal


def _exact(exact, goal: int, cut_value: int, sense: Sense) -> list[Fraction]:
    """The exact optimum by backward induction (``recursion_values``): the truncated state
    counts 0, or 1 as a second goal (its mass added to the goal's, in fractions)."""
    if cut_value:
        exact = [[_merged(row, goal) for row in rows] for rows in exact]
    return recursion_values(exact, goal, goal, sense)


def _merged(row: dict, goal: int) -> dict:
    """``row`` with the truncated state's probability moved onto the goal, exactly."""
    out = {t: Fraction(p) for t, p in row.items() if t != goal + 1}
    out[goal] = out.get(goal, Fraction(0)) + Fraction(row.get(goal + 1, 0.0))
    return out


def _solve_both(mdp, quotients, after: bool):
    out = []
    for k, q in enumerate(quotients):
        out.append(solve_lp(mdp, np.asarray(q.target), quotient=q, sense=q.sense,
                            everywhere=True, flows=False,
                            levels_after=after and k + 1 < len(quotients)))
    return out


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
def test_the_second_lp_takes_the_first_lps_levels(seed: int, sense: Sense,
                                                    monkeypatch) -> None:
    mdp, exact, n = _layers(seed)  # (n: the goal, after the layers' n states)
    built = []
    original = shared_mod.SingleLevels

    def counting(*a, **k):
        built.append(1)
        return original(*a, **k)

    monkeypatch.setattr(shared_mod, "SingleLevels", counting)
    low, high = analyse(mdp, mdp.target, mdp.truncated, sense=sense)
    assert low.matrix is high.matrix and low.order is high.order  # one analysis
    assert low.order.n_levels >= RUNS_MIN_LEVELS  # the LP walks the shared levels
    shared = _solve_both(mdp, [low, high], after=True)
    assert len(built) == 1  # once for both LPs
    assert id(low.matrix) not in shared_mod._KEPT  # the second LP took them
    built.clear()
    alone = _solve_both(mdp, [low, high], after=False)
    assert len(built) == 2  # each LP its own, as before
    for a, b in zip(shared, alone, strict=True):
        assert a.status == b.status
        assert np.array_equal(a.values, b.values)
        assert np.array_equal(a.policy, b.policy)
    for r, cut_value in zip(shared, (0, 1), strict=True):
        want = np.array([float(x) for x in _exact(exact, n, cut_value, sense)])
        assert np.allclose(r.values[:n], want, rtol=0, atol=1e-7)


def test_levels_left_for_a_follower_go_with_their_matrix() -> None:
    mdp, _, _ = _layers(3)
    low, high = analyse(mdp, mdp.target, mdp.truncated, sense=Sense.MAX)
    key = id(low.matrix)
    solve_lp(mdp, np.asarray(low.target), quotient=low, sense=low.sense,
             everywhere=True, flows=False, levels_after=True)
    assert key in shared_mod._KEPT  # kept for the next LP
    del low, high
    gc.collect()
    assert key not in shared_mod._KEPT  # gone with the quotients' matrix


@pytest.mark.parametrize("chunk", [1, 5, 1 << 13])
@pytest.mark.parametrize("seed", range(8))
def test_keeping_zero_of_the_zero_states_only(seed: int, chunk: int, monkeypatch) -> None:
    """``keeping_zero(q, zero_only=True)``: on the zero states the choice a loop over
    their choices and entries finds (the first with no target mass and every successor
    known 0, else the first), the first choice on every other state."""
    from types import SimpleNamespace

    import scipy.sparse as sp

    from mitld_lp.solvers.reduced import keeping_zero

    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 40))
    groups = np.concatenate([[0], np.cumsum(rng.integers(1, 5, size=n))])
    m = int(groups[-1])
    indptr = np.concatenate([[0], np.cumsum(rng.integers(0, 4, size=m))]).astype(np.int32)
    indices = rng.integers(0, n, size=int(indptr[-1])).astype(np.int32)
    data = rng.random(indices.size)
    zero = rng.random(n) < rng.choice([0.05, 0.6])
    to_target = np.where(rng.random(m) < 0.3, rng.random(m), 0.0)
    q = SimpleNamespace(matrix=sp.csr_array((data, indices, indptr), shape=(m, n)),
                        zero=zero, to_target=to_target, row_groups=groups, n_choices=m)
    full = brute_keeping_zero(indptr, indices, zero, to_target, groups)
    want = [full[s] if zero[s] else int(groups[s]) for s in range(n)]
    monkeypatch.setattr(rows, "ENTRY_CHUNK", chunk)  # entries read at a time
    got = keeping_zero(q, zero_only=True)
    assert got.dtype == np.int64 and got.tolist() == want


@pytest.mark.parametrize("chunk", [1, 4, 1 << 13])
def test_first_staying_read_a_chunk_of_entries_at_a_time(chunk: int, monkeypatch) -> None:
    """``first_staying`` (only the states of several choices searched, their entries a
    chunk at a time) is test_csma_mem's loop over every state's rows, stored zeros
    included (no edge)."""
    from test_csma_mem import random_mdp, staying_by_loop, with_zeros

    from mitld_lp.solvers.quotient import first_staying

    monkeypatch.setattr(rows, "ENTRY_CHUNK", chunk)
    rng = np.random.default_rng(chunk)
    for mdp in [random_mdp(3), with_zeros(random_mdp(7), 7)]:
        inside = rng.random(mdp.n_states) < 0.6
        want = [staying_by_loop(mdp, inside, s) for s in range(mdp.n_states)]
        assert first_staying(mdp, inside).tolist() == want
