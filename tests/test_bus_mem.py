"""The bus family's memory cuts, each checked against an independent computation on
small models: the repair's closed-at-zero test read a slice of states at a time
(against a loop over every row's entries), and a one-LU chain walk that keeps the chain
itself beside its LU (its solves against NumPy's dense solve of ``I - Q``)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.solvers import certify_repair
from mitld_lp.solvers.certify_repair import Rows, closed_at_zero
from mitld_lp.solvers.chain_levels import WALK_MIN_STATES, ChainLevels


def _model(rng: np.random.Generator, n: int, nature: bool) -> Rows:
    """A random model of ``n`` states, 1-3 choices a state, with nature's rows (1-2 a
    choice) where asked, some of its entries stored zeros."""
    per_state = rng.integers(1, 4, size=n)
    groups = np.concatenate([[0], np.cumsum(per_state)])
    n_choices = int(groups[-1])
    if nature:
        per_choice = rng.integers(1, 3, size=n_choices)
        nat = np.concatenate([[0], np.cumsum(per_choice)])
        n_rows = int(nat[-1])
    else:
        nat, n_rows = None, n_choices
    dense = np.zeros((n_rows, n))
    for r in range(n_rows):
        cols = rng.choice(n, size=min(n, int(rng.integers(1, 4))), replace=False)
        dense[r, cols] = rng.random(cols.size)
    m = sp.csr_array(dense)
    # a few stored zeros: entries the pattern holds whose value is 0
    m.data[rng.random(m.nnz) < 0.1] = 0.0
    return Rows(m, groups, nat)


def _brute(st: Rows, zero: np.ndarray, x: np.ndarray) -> bool:
    """Every ``zero`` state is 0 in ``x`` and every stored entry of each of its rows
    (nature's included) has its column in ``zero``: row by row, from the definition."""
    m = st.matrix
    for s in np.flatnonzero(zero):
        if x[s] != 0.0:
            return False
        for c in range(int(st.groups[s]), int(st.groups[s + 1])):
            rows = (range(c, c + 1) if st.nature is None else
                    range(int(st.nature[c]), int(st.nature[c + 1])))
            for r in rows:
                for k in range(int(m.indptr[r]), int(m.indptr[r + 1])):
                    if not zero[m.indices[k]]:
                        return False
    return True


@pytest.mark.parametrize("slice_states", [1, 2, 3, 4096])
@pytest.mark.parametrize("nature", [False, True])
def test_closed_at_zero_matches_a_loop_over_the_rows(monkeypatch: pytest.MonkeyPatch,
                                                     slice_states: int,
                                                     nature: bool) -> None:
    monkeypatch.setattr(certify_repair, "CLOSED_SLICE", slice_states)
    rng = np.random.default_rng(7 + slice_states + 100 * nature)
    seen = {True: 0, False: 0}
    for _ in range(60):
        n = int(rng.integers(2, 12))
        st = _model(rng, n, nature)
        zero = rng.random(n) < 0.5
        if rng.random() < 0.5:  # close the set: every state reaching a non-zero one out
            m = st.matrix
            for _round in range(n):
                for s in np.flatnonzero(zero):
                    lo = int(st.groups[s])
                    hi = int(st.groups[s + 1])
                    if st.nature is not None:
                        lo, hi = int(st.nature[lo]), int(st.nature[hi])
                    if not zero[m.indices[m.indptr[lo]:m.indptr[hi]]].all():
                        zero[s] = False
        x = np.where(zero, 0.0, rng.random(n))
        if rng.random() < 0.2 and zero.any():
            x[np.flatnonzero(zero)[0]] = 0.5  # not 0 at a zero state: not closed
        want = _brute(st, zero, x)
        assert closed_at_zero(st, zero, x) is want
        seen[want] += 1
    assert seen[True] and seen[False]  # both answers were asked


def _chain(rng: np.random.Generator, n: int) -> sp.csr_array:
    """A random transient chain: each row's mass below 1, a self-loop on some."""
    dense = np.zeros((n, n))
    for r in range(n):
        cols = rng.choice(n, size=min(n, int(rng.integers(1, 4))), replace=False)
        dense[r, cols] = rng.random(cols.size)
        dense[r] *= rng.uniform(0.2, 0.95) / dense[r].sum()
    return sp.csr_array(dense)


@pytest.mark.parametrize("n", [5, 40, 300])
def test_one_lu_walk_solves_as_the_dense_solve(n: int) -> None:
    assert n < WALK_MIN_STATES  # one LU, no walk over components
    rng = np.random.default_rng(n)
    chain = _chain(rng, n)
    want_matrix = np.eye(n) - chain.toarray()
    walk = ChainLevels(chain)
    for _ in range(2):  # the second solves on the kept factorisation
        rhs = rng.random(n)
        np.testing.assert_allclose(walk.solve(rhs), np.linalg.solve(want_matrix, rhs),
                                   rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(walk.solve_transposed(rhs),
                                   np.linalg.solve(want_matrix.T, rhs),
                                   rtol=1e-10, atol=1e-12)
        two = rng.random((n, 2))
        np.testing.assert_allclose(walk.solve(two), np.linalg.solve(want_matrix, two),
                                   rtol=1e-10, atol=1e-12)
    # the rows kept beside the one LU are the walk's chain, not a copy of it
    (rows, _lu), = walk._cyclic.values()
    assert rows is walk.chain


def _linprog_max_reach(mdp) -> np.ndarray:  # type: ignore[no-untyped-def]
    """The maximal reachability probabilities of ``mdp.target`` by SciPy's ``linprog``:
    the least ``v`` in [0, 1] with ``v(s) >= sum_s' P(c, s') v(s')`` for every choice
    ``c`` of a non-target state ``s`` and ``v = 1`` on the target (min the sum of ``v``)."""
    from scipy.optimize import linprog

    n = mdp.n_states
    p = mdp.matrix.toarray()
    owner = np.repeat(np.arange(n), np.diff(mdp.row_groups))
    target = np.asarray(mdp.target)
    keep = ~target[owner]
    a_ub = p[keep].copy()
    a_ub[np.arange(a_ub.shape[0]), owner[keep]] -= 1.0  # P v - v(s) <= 0
    bounds = [(1.0, 1.0) if t else (0.0, 1.0) for t in target]
    res = linprog(np.ones(n), A_ub=a_ub, b_ub=np.zeros(a_ub.shape[0]), bounds=bounds,
                  method="highs")
    assert res.status == 0
    return res.x


@pytest.mark.parametrize("seed", range(3))
def test_lp_without_flows_values_as_linprog(seed: int) -> None:
    """``solve_lp(..., flows=False)`` (its flow freed before the values are lifted):
    every state's value as SciPy's own LP of the maximal reachability, and its policy's
    chain reaching the target with the initial state's value."""
    from mitld_lp.solvers import analysis
    from mitld_lp.solvers import lp as L
    from mitld_lp.solvers.graph import Sense
    from mitld_lp.solvers.iteration import interval_iteration
    from mitld_lp.testing import random_mdp

    mdp = random_mdp(60, seed=seed, locality=None if seed % 2 else 10)
    q = analysis.analyse(mdp, mdp.target, sense=Sense.MAX)[0]
    it = interval_iteration(mdp, mdp.target, quotient=q, sense=Sense.MAX, tol=1e-10,
                            precision=None, gap="max")
    got = L.solve_lp(mdp, mdp.target, quotient=q, sense=Sense.MAX, everywhere=True,
                     bounds=(it.lower, it.upper), flows=False)
    assert got.occupancy is None and got.randomized is None
    want = _linprog_max_reach(mdp)
    np.testing.assert_allclose(got.values, want, atol=1e-7)
    # the policy's own chain from 0 (the least fixed point: a loop that never reaches
    # the target stays 0), iterated densely until it no longer moves
    p = mdp.matrix.toarray()[np.asarray(got.policy)]
    target = np.asarray(mdp.target)
    x = target.astype(float)
    for _ in range(100_000):
        nxt = np.where(target, 1.0, p @ x)
        if np.max(np.abs(nxt - x)) < 1e-15:
            break
        x = nxt
    assert abs(x[mdp.initial] - want[mdp.initial]) < 1e-6


def test_route_trims_before_its_lps_and_the_answer_keeps_its_bits(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The plain route hands the free heap back between the interval iteration and the
    LPs (from TRIM_BEFORE_LP_FROM, lowered here to every product); the answer is the
    same to the bit as with no trim at all, and the iteration's bounds bracket it."""
    from pathlib import Path

    from mitld_lp import load_model, synthesize
    from mitld_lp.routes import plain
    from mitld_lp.solvers import lp as L

    model = load_model(Path(__file__).resolve().parent.parent / "models" / "bus_grid.toml")
    events: list[str] = []
    solve_lp = L.solve_lp

    def traced_lp(*a, **k):  # type: ignore[no-untyped-def]
        events.append("lp")
        return solve_lp(*a, **k)

    monkeypatch.setattr(L, "solve_lp", traced_lp)
    iterate = plain._iterate

    def traced_iterate(*a, **k):  # type: ignore[no-untyped-def]
        events.append("iteration")
        return iterate(*a, **k)

    monkeypatch.setattr(plain, "_iterate", traced_iterate)
    monkeypatch.setattr(plain, "TRIM_FROM_TRANSITIONS", 0)
    monkeypatch.setattr(plain, "TRIM_BEFORE_LP_FROM", 0)
    monkeypatch.setattr(plain, "release_free_memory", lambda: events.append("trim"))
    trimmed = synthesize(model)
    assert "lp" in events
    first_lp = events.index("lp")
    # the analysis's trim, the iteration, then a trim right before the first LP
    assert events[:first_lp] == ["trim", "iteration", "trim"]
    monkeypatch.setattr(plain, "TRIM_FROM_TRANSITIONS", 10**18)  # no trim at all
    monkeypatch.setattr(plain, "TRIM_BEFORE_LP_FROM", 10**18)
    events.clear()
    plain_run = synthesize(model)
    assert "trim" not in events
    assert np.float64(trimmed.lower).tobytes() == np.float64(plain_run.lower).tobytes()
    assert np.float64(trimmed.upper).tobytes() == np.float64(plain_run.upper).tobytes()
    assert trimmed.certified and plain_run.certified
    assert trimmed.lower <= 0.9244053 + 1e-6 and trimmed.upper >= 0.9244053 - 1e-6
