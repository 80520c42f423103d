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
  is, on the zero states, a loop's first choice that keeps 0, elsewhere the first.
"""

from __future__ import annotations

import gc
from fractions import Fraction

import numpy as np
import pytest
from conftest import build_mdp

from mitld_lp.solvers import shared_levels as shared_mod
from mitld_lp.solvers.analysis import analyse
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.lp import solve_lp
from mitld_lp.solvers.shared_levels import RUNS_MIN_LEVELS


def _layers(seed: int, depth: int = 40, width: int = 3):
    """``depth`` layers of ``width`` states; each choice may stay put, moves on to two
    states of the next layer, to the goal, to a sink and to a truncated state; the
    last layer ends there.  The MDP and each state's exact rows."""
    rng = np.random.default_rng(seed)
    n = depth * width
    goal, sink, cut = n, n + 1, n + 2
    states, exact = [], []
    for s in range(n):
        layer = s // width
        mine, ex = [], []
        for a in range(int(rng.integers(1, 4))):
            nxt = [goal, sink, cut] + ([(layer + 1) * width + int(j) for j in
                                        rng.choice(width, size=2, replace=False)]
                                       if layer + 1 < depth else [])
            w = rng.integers(1, 9, size=len(nxt) + 1).astype(float)
            w[0] = w[0] if rng.random() < 0.5 else 0.0  # a self-loop half the time
            p = w / w.sum()
            row = {s: float(p[0])} if p[0] > 0 else {}
            for t, x in zip(nxt, p[1:], strict=True):
                row[t] = row.get(t, 0.0) + float(x)
            row[sink] += 1.0 - sum(row.values())  # rows sum to 1 in floats
            mine.append((f"a{a}", row))
            ex.append(row)
        states.append(mine)
        exact.append(ex)
    states += [[], [], []]
    mdp = build_mdp(states, target=[goal], sink=[sink], truncated=[cut])
    return mdp, exact, n


def _exact(exact, n: int, cut_value: int, sense: Sense) -> list[Fraction]:
    """Backward induction over the layers in fractions of the stored floats."""
    pick = max if sense is Sense.MAX else min
    v = {n: Fraction(1), n + 1: Fraction(0), n + 2: Fraction(cut_value)}
    for s in range(n - 1, -1, -1):
        scores = []
        for row in exact[s]:
            stay = Fraction(row.get(s, 0.0))
            gain = sum((Fraction(p) * v[t] for t, p in row.items() if t != s), Fraction(0))
            scores.append(gain / (1 - stay))
        v[s] = pick(scores)
    return [v[s] for s in range(n)]


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
    mdp, exact, n = _layers(seed)
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


@pytest.mark.parametrize("seed", range(8))
def test_keeping_zero_of_the_zero_states_only(seed: int) -> None:
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
    want = []
    for s in range(n):
        pick = int(groups[s])
        if zero[s]:
            for c in range(groups[s], groups[s + 1]):
                succ = indices[indptr[c]:indptr[c + 1]]
                if to_target[c] == 0.0 and all(zero[t] for t in succ):
                    pick = c
                    break
        want.append(pick)
    got = keeping_zero(q, zero_only=True)
    assert got.dtype == np.int64 and got.tolist() == want
