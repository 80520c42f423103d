"""The compiled prob-0 lift (:mod:`mitld_lp.solvers.lift_kernels`): per state, the first
choice whose every successor of positive probability stays inside a set, else the first
choice.  Checked against a plain Python loop over the rows written here, on matrices
with int32 and int64 indices and stored zeros, and through a minimum's lifted policy
(:func:`mitld_lp.solvers.quotient.lift_policy`) with the compiled path on and off."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

pytest.importorskip("numba")

from mitld_lp.solvers import analysis  # noqa: E402
from mitld_lp.solvers import quotient as Q  # noqa: E402
from mitld_lp.solvers.graph import Sense  # noqa: E402
from mitld_lp.solvers.lift_kernels import first_staying  # noqa: E402
from mitld_lp.testing import random_mdp  # noqa: E402


def _by_loop(groups, matrix, inside, states) -> list[int]:
    """The answer by Python loops over the dense rows (a zero is no edge)."""
    dense = matrix.toarray()
    out = []
    for s in states:
        first = int(groups[s])
        pick = first
        for c in range(first, int(groups[s + 1])):
            if all(inside[t] for t in range(dense.shape[1]) if dense[c, t] > 0):
                pick = c
                break
        out.append(pick)
    return out


def _random_rows(seed: int, index: type) -> tuple[np.ndarray, sp.csr_array, np.ndarray]:
    rng = np.random.default_rng(seed)
    n = 60
    sizes = rng.integers(1, 5, size=n)
    groups = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    m = int(groups[-1])
    dense = np.where(rng.random((m, n)) < 0.06, rng.random((m, n)), 0.0)
    dense[np.arange(m), rng.integers(0, n, size=m)] += 0.5  # every row has an entry
    matrix = sp.csr_array(dense)
    # a stored zero in some rows: not an edge
    data = matrix.data.copy()
    data[rng.random(data.size) < 0.1] = 0.0
    matrix = sp.csr_array((data, matrix.indices.astype(index), matrix.indptr.astype(index)),
                          shape=(m, n))
    inside = rng.random(n) < 0.6
    return groups, matrix, inside


@pytest.mark.parametrize("index", [np.int32, np.int64])
@pytest.mark.parametrize("seed", range(5))
def test_compiled_lift_matches_a_plain_loop(seed: int, index: type) -> None:
    groups, matrix, inside = _random_rows(seed, index)
    states = np.flatnonzero(np.random.default_rng(seed + 100).random(groups.size - 1) < 0.7)
    got = first_staying(groups, matrix, inside, states)
    assert got.dtype == np.int64
    assert got.tolist() == _by_loop(groups, matrix, inside, states)
    # read-only inputs (a product's arrays are) give the same
    ro = [a.view() for a in (groups, inside, states)]
    for a in ro:
        a.flags.writeable = False
    assert first_staying(ro[0], matrix, ro[1], ro[2]).tolist() == got.tolist()


def test_no_state_and_only_leaving_choices() -> None:
    groups = np.array([0, 2, 3], dtype=np.int64)
    m = sp.csr_array(np.array([[0.0, 1.0], [0.5, 0.5], [1.0, 0.0]]))
    inside = np.array([True, False])
    assert first_staying(groups, m, inside, np.zeros(0, dtype=np.int64)).size == 0
    # state 0: both choices reach state 1 (outside): its first; state 1: stays at 0
    assert first_staying(groups, m, inside, np.array([0, 1])).tolist() == [0, 2]


@pytest.mark.parametrize("seed", range(4))
def test_minimum_lifted_policy_same_with_the_kernel(monkeypatch, seed: int) -> None:
    mdp = random_mdp(400, seed=seed, sink_fraction=0.2)
    q = analysis.analyse(mdp, mdp.target, sense=Sense.MIN)[0]
    reduced = np.asarray(q.row_groups[:-1], dtype=np.int64)
    monkeypatch.setattr(Q, "lift_compiled", lambda n: False)
    plain = Q.lift_policy(mdp, q, reduced)
    monkeypatch.setattr(Q, "lift_compiled", lambda n: True)
    compiled = Q.lift_policy(mdp, q, reduced)
    assert compiled.tobytes() == plain.tobytes()
    # and each prob-0 state's choice stays among them where one does (checked here)
    zero = np.asarray(q.prob0)
    groups = np.asarray(mdp.row_groups)
    dense = mdp.matrix.toarray()
    for s in np.flatnonzero(zero):
        if compiled[s] < 0:
            continue
        can = [c for c in range(groups[s], groups[s + 1])
               if all(zero[t] for t in np.flatnonzero(dense[c] > 0))]
        if can:
            assert compiled[s] == can[0]
