"""What the certificate frees and how much it holds at once (cert-mem): the chain's
slack and sets are gone before the everywhere check (weak references), and the
everywhere check, the chain's columns and the NumPy Bellman check each stay within a
traced bound computed here from the sizes: below what one array of every state (or
row, or entry) of the kind they used to make would take."""

from __future__ import annotations

import tracemalloc
import weakref

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.solvers import certify as C
from mitld_lp.solvers import certify_chain, certify_everywhere
from mitld_lp.solvers.analysis import analyse
from mitld_lp.solvers.certify_repair import Rows
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.iteration import interval_iteration
from mitld_lp.solvers.lp import solve_lp
from mitld_lp.solvers.rounding import rounding
from mitld_lp.testing import random_mdp


def _traced_peak(call):
    """``call()``'s result and the traced peak above the traced size before it."""
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        tracemalloc.reset_peak()
        out = call()
        return out, tracemalloc.get_traced_memory()[1] - before
    finally:
        tracemalloc.stop()


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
def test_the_chains_slack_and_sets_are_freed_before_the_everywhere_check(
        monkeypatch: pytest.MonkeyPatch, sense: Sense) -> None:
    mdp = random_mdp(300, seed=4, max_choices=3, max_successors=3, locality=8)
    it = interval_iteration(mdp, mdp.target, sense=sense, gap="max", progress=False)
    lp = solve_lp(mdp, mdp.target, sense=sense, everywhere=True,
                  bounds=(it.lower, it.upper), greedy=False)
    q, _ = analyse(mdp, mdp.target, sense=sense)
    made, seen = [], []
    chain, everywhere = C.chain, C.everywhere

    def keep_refs(*a, **k):
        ch = chain(*a, **k)
        made.append([weakref.ref(x) for x in (ch.w, ch.solved, ch.sure, ch.never)])
        return ch

    def look(*a, **k):
        seen.append([r() is None for r in made[-1]])
        return everywhere(*a, **k)

    monkeypatch.setattr(C, "chain", keep_refs)
    monkeypatch.setattr(C, "everywhere", look)
    low = sense is Sense.MIN
    cert = C.certify(mdp, mdp.target, lp.policy, sense=str(sense),
                     zero=q.qualitative.zero, one=q.qualitative.one if low else None,
                     mec_of=None if low else q.mecs.mec_of, layers=q.layers,
                     fallback_lower=it.lower, fallback_upper=it.upper, precision=1e-6)
    assert len(cert.checks) == 3 and seen == [[True] * 4]


def test_the_everywhere_check_holds_a_batch_not_a_float_a_state(
        monkeypatch: pytest.MonkeyPatch) -> None:
    n, batch = 400_000, 1 << 12
    monkeypatch.setattr(certify_everywhere, "EVERYWHERE_BATCH", batch)
    rng = np.random.default_rng(1)
    lower = rng.random(n)
    upper = lower + 1e-3 * (rng.random(n) < 0.5)  # half the states apart
    check, peak = _traced_peak(lambda: C.everywhere(lower, upper, 0, 1e-6))
    assert not check.passed
    # a batch's gap, scale, product, mask, indices and ratios: some 6 floats a state
    # of the batch; the whole vectors' temporaries were three floats a state
    assert peak < 8 * 8 * batch + 65536 < 8 * n


def test_the_chains_columns_hold_the_output_and_one_batch(
        monkeypatch: pytest.MonkeyPatch) -> None:
    batch = 1 << 8
    monkeypatch.setattr(certify_chain, "COLUMNS_BATCH", batch)
    n, k = 200_000, 4
    rng = np.random.default_rng(2)
    cols = rng.integers(0, n, size=n * k)
    m = sp.csr_array((rng.random(n * k) + 0.1, cols, np.arange(0, n * k + 1, k)),
                     shape=(n, n))
    rows = np.arange(n, dtype=np.int64)
    counts = m.indptr[rows + 1] - m.indptr[rows]
    (dst, pos), peak = _traced_peak(lambda: certify_chain._columns(m, rows, counts,
                                                                   np.int32))
    assert pos is None and dst.size == n * k
    # the int32 columns kept, and a batch's entries (columns, values, mask) and
    # pointers; every row's float values at once alone took 8 bytes an entry
    assert peak < dst.nbytes + 40 * k * batch + 65536 < dst.nbytes + 8 * n * k


def test_the_bellman_check_holds_no_index_a_row(monkeypatch: pytest.MonkeyPatch) -> None:
    batch = 1 << 8
    monkeypatch.setattr(C, "BATCH", batch)
    mdp = random_mdp(60_000, seed=5, max_choices=3, max_successors=3, locality=20)
    st = Rows(sp.csr_array(mdp.matrix), np.asarray(mdp.row_groups, dtype=np.int64))
    rnd = rounding(st.matrix)
    rng = np.random.default_rng(5)
    x = rng.random(mdp.n_states)
    free = np.asarray(mdp.target, dtype=bool)
    rows, n = st.matrix.shape[0], mdp.n_states
    ok, peak = _traced_peak(lambda: C.numpy_checks(st, rnd, x, free, True))
    assert ok.size == rows
    # the verdict a row (kept), the states past the bottom (a bool a state) and one
    # batch's temporaries; the state of every row (4 bytes a row) and a float a state
    # for the rule were held through the whole check before
    assert peak < rows + n + 400 * batch + 65536 < 5 * rows + 8 * n
