"""The deadline walks summed by SciPy's compiled CSR/CSC products (issue 45), to the bit,
on random acyclic MDPs with exact ties: the LP's values walk (its choice among near-ties
and the picks left to after the walk included) and the repair's level reads against
plain state-by-state loops written here; those two, the iteration's bounds walk and the
flow walk against the NumPy calls they replace (the bounds' and flow's plain loops are
``test_deadline_walks``', which run on the products too); and a small PRISM deadline
model with tied actions solved end to end against Storm's exact engine, the same bits
either way."""

from __future__ import annotations

import sys
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.solvers import certify as C
from mitld_lp.solvers import certify_repair as R
from mitld_lp.solvers import level_batches
from mitld_lp.solvers.analysis import analyse
from mitld_lp.solvers.certify_chain import support_layers
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.rounding import rounding
from mitld_lp.solvers.topological import SingleLevels

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_deadline_walks import _deadline_mdp, _plain_order, _plain_rows, _posed  # noqa: E402,I001


def _tied_deadline_mdp(seed: int, depth: int = 30, width: int = 5):
    """``test_deadline_walks``' deadline-like MDP with exact ties (repeated choices)."""
    return _deadline_mdp(seed, depth, width, ties=True)


def _singles(seed: int, sense: Sense):
    """The quotient of a tied deadline MDP and its single levels, walked by NumPy."""
    mdp = _tied_deadline_mdp(seed)
    q, _ = analyse(mdp, mdp.target, sense=sense)
    return q, SingleLevels(q, q.order, compiled=False)


def _rows(q, sl: SingleLevels, s: int):
    """State ``s``'s choices: (choice, self-loop, [(col, p)] in the matrix's order)."""
    return _plain_rows(q, sl, int(np.flatnonzero(sl.states == s)[0]))[1]


def _levels(sl: SingleLevels) -> list[list[int]]:
    """The single states of ``sl``, level by level."""
    return [[int(sl.states[i]) for i in level] for level in _plain_order(sl)]


def _plain_values(q, sl: SingleLevels, skip: np.ndarray, start: np.ndarray):
    """The values walk state by state: each choice's score from the values below, the
    best within TIE (relative) of the top, the larger one-step reward among those
    preferred (the smaller for a minimum), then the first."""
    maximum = q.sense is Sense.MAX
    v = start.copy()
    choice = np.full(q.n_states, -1, dtype=np.int64)
    weights = np.zeros(q.matrix.shape[0])
    for level in _levels(sl):
        for s in level:
            if skip[s]:
                continue
            scored = []
            for c, stay, entries in _rows(q, sl, s):
                acc = 0.0
                for col, p in entries:
                    acc += p * v[col]
                scored.append((c, min(max((q.to_target[c] + acc) / (1.0 - stay), 0.0),
                                      1.0)))
            top = (max if maximum else min)(score for _, score in scored)
            tied = [(c, score) for c, score in scored
                    if ((score - top) if maximum else (top - score)) >= -1e-12 * abs(top)]
            prefer = [q.to_target[c] if maximum else -q.to_target[c] for c, _ in tied]
            c, score = tied[prefer.index(max(prefer))]
            v[s], choice[s] = score, c
            weights[c] = 1.0
    return v, choice, weights


def _walk_values(q, sl: SingleLevels, skip: np.ndarray, start: np.ndarray):
    v = start.copy()
    choice = np.full(q.n_states, -1, dtype=np.int64)
    weights = np.zeros(q.matrix.shape[0])
    sl.values(0, q.order.n_levels, q.to_target, skip, v, choice, weights)
    return v, choice, weights


def _numpy_only(sl: SingleLevels) -> SingleLevels:
    """``sl`` walked by the NumPy calls the compiled products replace."""
    sl.ptr = None
    return sl


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
def test_values_walk_is_the_plain_loop_to_the_bit(seed: int, sense: Sense) -> None:
    q, sl = _singles(seed, sense)
    assert sl.ptr is not None and len(sl.runs) > 20
    rng = np.random.default_rng(seed)
    skip = rng.random(q.n_states) < 0.1  # kept as they are, read by the others
    start = np.where(skip, rng.random(q.n_states), 0.0)
    want = _plain_values(q, sl, skip, start)
    got = _walk_values(q, sl, skip, start)
    assert all(g.tobytes() == w.tobytes() for g, w in zip(got, want, strict=True))
    # exact ties were decided by the rule, not all by a lone best
    ties = sum(len(_rows(q, sl, s)) > 1 for s in sl.states.tolist())
    assert ties > 20
    numpy = _walk_values(q, _numpy_only(SingleLevels(q, q.order, compiled=False)),
                         skip, start)
    assert all(g.tobytes() == w.tobytes() for g, w in zip(got, numpy, strict=True))


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
def test_bounds_and_flow_by_compiled_products_are_the_numpy_walks(seed: int,
                                                                 sense: Sense) -> None:
    """The bounds and flow walks by SciPy's products against their NumPy calls (their
    plain state-by-state loops: ``test_deadline_walks``, run on the products too)."""
    q, fast = _singles(seed, sense)
    slow = _numpy_only(SingleLevels(q, q.order, compiled=False))
    rewards = np.column_stack([q.to_target, 0.25 * q.to_target, q.to_target ** 2])
    got, want = np.zeros((q.n_states, 3)), np.zeros((q.n_states, 3))
    fast.solve(0, q.order.n_levels, rewards, got)
    slow.solve(0, q.order.n_levels, rewards, want)
    assert got.tobytes() == want.tobytes() and np.any(got > 0)
    # the flow of the uniform randomised policy, upstream first, both ways
    counts = np.diff(q.row_groups)
    uniform = np.repeat(1.0 / np.maximum(counts, 1), counts)
    x0 = np.random.default_rng(seed).random(q.n_states)
    a, b = x0.copy(), x0.copy()
    fast.flow(0, q.order.n_levels, np.asarray(q.order.self_loop), uniform, a)
    slow.flow(0, q.order.n_levels, np.asarray(q.order.self_loop), uniform, b)
    assert a.tobytes() == b.tobytes() and not np.array_equal(a, x0)


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("upper", [True, False])
def test_repair_reads_by_compiled_product_as_by_bincount(seed: int, upper: bool) -> None:
    mdp = _tied_deadline_mdp(seed, depth=20)
    st = C.Rows(sp.csr_array(mdp.matrix), np.asarray(mdp.row_groups, dtype=np.int64))
    rnd = rounding(st.matrix)
    comp, level = support_layers(mdp)
    level_of = np.asarray(level)[np.asarray(comp)]
    live = np.flatnonzero(np.diff(st.groups) > 0)
    order = live[np.argsort(level_of[live], kind="stable")]
    walk = R._Walk(st, order, level_of[order])
    assert walk.row_entry is not None
    assert walk.filled
    rng = np.random.default_rng(seed)
    x = rng.random(mdp.n_states)
    mark = rng.random(mdp.n_states) < 0.05
    at = walk.level_at.tolist()
    m = st.matrix
    for a, z in zip(at[:-1], at[1:], strict=True):
        got = walk.needed(rnd, x, a, z, upper)
        # each state's need read again from its own rows (the state-by-state route)
        want = R._needed(st, rnd, x, order[a:z], upper)
        assert got.tobytes() == want.tobytes()
        # whether a row of a state's choices holds a marked state, by hand
        reads = [any(mark[m.indices[e]] for c in range(st.groups[s], st.groups[s + 1])
                     for e in range(m.indptr[c], m.indptr[c + 1]))
                 for s in order[a:z].tolist()]
        assert walk.reading(mark, a, z).tolist() == reads


DEADLINE = """mdp
const int D = 40;
module m
  t : [0..D] init 0;
  x : [0..10] init 0;
  [go] t<D & x<10 -> 0.3 : (x'=x+1)&(t'=t+1) + 0.1 : (x'=0)&(t'=t+1) + 0.6 : (t'=t+1);
  [go2] t<D & x<10 -> 0.3 : (x'=x+1)&(t'=t+1) + 0.1 : (x'=0)&(t'=t+1) + 0.6 : (t'=t+1);
  [slow] t<D & x<10 -> 0.2 : (x'=x+1)&(t'=t+1) + 0.7 : (t'=t+1) + 0.1 : (t'=t);
  [jump] t<D-1 & x<9 -> 0.15 : (x'=x+2)&(t'=t+2) + 0.85 : (t'=t+2);
  [stop] t=D | x=10 -> true;
endmodule
label "goal" = x=10;
"""


@pytest.mark.parametrize("objective, prop", [("max", "Pmax=? [F \"goal\"]"),
                                             ("min", "Pmin=? [F \"goal\"]")])
def test_prism_deadline_with_ties_holds_storms_exact_value(tmp_path, monkeypatch,
                                                           objective: str,
                                                           prop: str) -> None:
    from mitld_lp import load_model, synthesize

    model, exact = _posed(tmp_path, DEADLINE, "x=10", objective, prop)
    fast = synthesize(load_model(model))
    assert fast.certified, fast.failed_checks
    assert Fraction(fast.lower) <= exact <= Fraction(fast.upper)
    assert fast.upper - fast.lower < 1e-6
    assert 0.01 < float(exact) < 0.99  # not decided by the graph alone
    # the NumPy calls the compiled products replace: the same bits
    monkeypatch.setattr(level_batches, "sparsetools", None)
    monkeypatch.setattr(R, "sparsetools", None)
    slow = synthesize(load_model(model))
    assert (slow.lower, slow.upper) == (fast.lower, fast.upper)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_chain_levels_by_compiled_product_as_by_bincount(seed: int, monkeypatch) -> None:
    """The certificate's chain walk (``certify_chain._Singles.solve``) sums a level by
    SciPy's CSR product where it can: the same ``v`` and ``w`` to the bit as the
    bincounts, and ``v`` the chain's solution (a dense solve, written apart)."""
    from mitld_lp.solvers import certify_chain as CC

    monkeypatch.setattr(CC, "level_kernels", lambda *a: None)  # the NumPy walk
    rng = np.random.default_rng(seed)
    n = 60
    rows, cols, vals = [], [], []
    for s in range(n):  # a transient chain: entries to higher states only, a self-loop
        succ = rng.choice(np.arange(s, n), size=min(3, n - s), replace=False)
        p = rng.random(succ.size)
        p = 0.9 * p / p.sum()
        rows += [s] * succ.size
        cols += succ.tolist()
        vals += p.tolist()
    sub = sp.csr_array((np.array(vals), (np.array(rows), np.array(cols))), shape=(n, n))
    b = rng.random(n) * 0.1
    kappa = np.full(n, 1e-16)
    calls = []

    class Spy:  # SciPy's product, counted
        def csr_matvec(self, *a):
            calls.append(1)
            return st.csr_matvec(*a)

    st, spy = CC.sparsetools, Spy()
    monkeypatch.setattr(CC, "sparsetools", spy)
    v, w = CC._solve(sub, b, kappa, None)
    assert calls  # the compiled product was used
    monkeypatch.setattr(CC, "sparsetools", None)
    v0, w0 = CC._solve(sub, b, kappa, None)
    assert np.array_equal(v, v0) and np.array_equal(w, w0)
    dense = np.linalg.solve(np.eye(n) - sub.toarray(), b)
    assert np.allclose(v, dense, rtol=1e-12, atol=1e-14)
