"""The certificate read in small pieces (cert-mem): the everywhere check a batch of
states at a time, the chain's columns a batch of rows at a time, the Bellman check's
row states found per batch, the chain's slack kept on its solved states.  Whatever the
batch, the brackets hold the exact optima (fractions, a backward recursion written in
the test) in every state, in both senses, and the certificate is the same to the bit
as with one batch; each piece agrees with a plain loop written here."""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest
import scipy.sparse as sp
from test_single_levels import layered_mdp, recursion_values

from mitld_lp.solvers import certify as C
from mitld_lp.solvers import certify_chain, certify_everywhere
from mitld_lp.solvers.analysis import analyse
from mitld_lp.solvers.certify_repair import Rows
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.iteration import interval_iteration
from mitld_lp.solvers.lp import solve_lp
from mitld_lp.solvers.rounding import rounding
from mitld_lp.testing import random_mdp


def _small_batches(monkeypatch: pytest.MonkeyPatch, batch: int) -> None:
    monkeypatch.setattr(C, "BATCH", batch)
    monkeypatch.setattr(certify_everywhere, "EVERYWHERE_BATCH", batch)
    monkeypatch.setattr(certify_chain, "COLUMNS_BATCH", batch)


def _solved(mdp, sense: Sense):
    it = interval_iteration(mdp, mdp.target, sense=sense, gap="max", progress=False)
    lp = solve_lp(mdp, mdp.target, sense=sense, everywhere=True,
                  bounds=(it.lower, it.upper), greedy=False)
    q, _ = analyse(mdp, mdp.target, sense=sense)
    return it, lp, q


@pytest.mark.parametrize("seed", [3, 8])
@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
def test_brackets_hold_the_exact_optimum_in_every_state_with_tiny_batches(
        monkeypatch: pytest.MonkeyPatch, seed: int, sense: Sense) -> None:
    mdp, exact, goal = layered_mdp(seed, depth=12)
    want = recursion_values(exact, goal, goal, sense) + [Fraction(1), Fraction(0)]
    it, lp, q = _solved(mdp, sense)
    low = sense is Sense.MIN
    decided = q.qualitative
    got = []
    for batch in (1, 2, 1 << 16):
        _small_batches(monkeypatch, batch)
        cert = C.certify(mdp, mdp.target, lp.policy, sense=str(sense), zero=decided.zero,
                         one=decided.one if low else None,
                         mec_of=None if low else q.mecs.mec_of, layers=q.layers,
                         fallback_lower=it.lower, fallback_upper=it.upper,
                         precision=1e-6)
        assert cert.certified, cert.checks
        got.append(cert)
        # both sides' vectors, every state: the optimum between them, exactly
        rnd = rounding(mdp.matrix)
        ch = C.chain(mdp, mdp.target, lp.policy, rnd, q.layers, guess=it.lower)
        assert ch.w.size == int(np.count_nonzero(ch.solved))  # the solved states' only
        if low:
            below = C.optimum_lower(mdp, ch, rnd, zero=decided.zero, one=decided.one,
                                    layers=q.layers, fallback=it.lower)
            above = C.policy_upper(mdp, ch, rnd)
        else:
            below = C.policy_lower(mdp, ch, rnd)
            above = C.optimum_upper(mdp, ch, rnd, zero=decided.zero, layers=q.layers,
                                    mec_of=q.mecs.mec_of, fallback=it.upper)
        assert below.check.passed and above.check.passed
        for s, v in enumerate(want):
            assert Fraction(float(below.vector[s])) <= v <= Fraction(float(above.vector[s])), s
    first = got[0]
    for other in got[1:]:  # the same certificate to the bit whatever the batch
        assert (first.lower, first.upper, first.checks) == \
            (other.lower, other.upper, other.checks)
        assert np.array_equal(first.values, other.values)
    s0 = int(mdp.initial)
    assert Fraction(first.lower) <= want[s0] <= Fraction(first.upper)


def _everywhere_loop(lower, upper, initial, precision, complement):
    """The check as a loop over the states in Python floats (the same IEEE
    operations): the count of states apart and the first of the largest ratio."""
    at = (1.0 - float(upper[initial])) if complement else float(lower[initial])
    count, worst, top = 0, -1, -math.inf
    for s in range(len(lower)):
        lo, hi = float(lower[s]), float(upper[s])
        gap = hi - lo
        value = 1.0 - hi if complement else lo
        scale = max(value, at)
        if gap > precision * scale:
            count += 1
            ratio = gap / max(scale, 1e-300)
            if ratio > top:
                top, worst = ratio, s
    return count, worst


@pytest.mark.parametrize("complement", [False, True])
@pytest.mark.parametrize("batch", [1, 3, 7, 1 << 16])
def test_everywhere_agrees_with_a_loop_over_the_states(
        monkeypatch: pytest.MonkeyPatch, complement: bool, batch: int) -> None:
    monkeypatch.setattr(certify_everywhere, "EVERYWHERE_BATCH", batch)
    rng = np.random.default_rng(batch)
    n = 50
    lower = rng.random(n) * 0.5
    upper = lower.copy()
    apart = rng.choice(n, size=9, replace=False)
    upper[apart] += rng.choice([1e-3, 2e-3, 1e-3], size=9)  # ties of the largest ratio
    upper[apart[:2]] = lower[apart[:2]] * (1 + 1e-9)  # within the precision
    for initial in (0, int(apart[3])):
        check = C.everywhere(lower, upper, initial, 1e-6, complement=complement)
        count, worst = _everywhere_loop(lower, upper, initial, 1e-6, complement)
        assert check.passed is (count == 0)
        assert f"{count} states apart" in check.detail
        assert f"e.g. state {worst}:" in check.detail
    same = C.everywhere(lower, lower, 0, 1e-6, complement=complement)
    assert same.passed and f"in all {n} states" in same.detail


def test_row_states_of_a_batch_are_the_states_of_its_rows() -> None:
    rng = np.random.default_rng(0)
    choices = rng.integers(0, 3, size=40)  # states without a choice too
    groups = np.concatenate([[0], np.cumsum(choices)]).astype(np.int64)
    rows_per = rng.integers(1, 3, size=int(groups[-1]))
    nature = np.concatenate([[0], np.cumsum(rows_per)]).astype(np.int64)
    n_rows = int(nature[-1])
    m = sp.csr_array((n_rows, 40))
    owner_plain = [s for s in range(40) for _ in range(int(choices[s]))]
    owner_nature = [owner_plain[c] for c in range(int(groups[-1]))
                    for _ in range(int(rows_per[c]))]
    for st, owner in ((Rows(sp.csr_array((int(groups[-1]), 40)), groups), owner_plain),
                      (Rows(m, groups, nature), owner_nature)):
        total = len(owner)
        for a in range(total):
            for z in range(a + 1, min(total, a + 9) + 1):
                assert st.row_states(a, z).tolist() == owner[a:z], (a, z)


@pytest.mark.parametrize("batch", [1, 2, 5, 1 << 14])
def test_the_chains_columns_are_the_rows_entries_whatever_the_batch(
        monkeypatch: pytest.MonkeyPatch, batch: int) -> None:
    monkeypatch.setattr(certify_chain, "COLUMNS_BATCH", batch)
    mdp = random_mdp(60, seed=batch, max_choices=3, max_successors=4)
    m = sp.csr_array(mdp.matrix)
    rows = np.arange(0, m.shape[0], 2, dtype=np.int64)
    want_cols = [int(c) for r in rows for c in m.indices[m.indptr[r]:m.indptr[r + 1]]]
    counts = m.indptr[rows + 1] - m.indptr[rows]
    dst, pos = certify_chain._columns(m, rows, counts, np.int32)
    assert dst.dtype == np.int32 and dst.tolist() == want_cols
    assert pos is None  # every stored entry positive
    # a stored zero: marked, in its place
    z = m.copy()
    first = int(z.indptr[rows[3]])
    z.data[first] = 0.0
    dst, pos = certify_chain._columns(z, rows, counts, np.int32)
    want_pos = [float(v) > 0 for r in rows for v in z.data[z.indptr[r]:z.indptr[r + 1]]]
    assert dst.tolist() == want_cols and pos is not None and pos.tolist() == want_pos


@pytest.mark.parametrize("batch", [1, 3, 1 << 16])
def test_reaching_with_its_seeds_written_in_batches_is_a_plain_search(
        monkeypatch: pytest.MonkeyPatch, batch: int) -> None:
    from mitld_lp.solvers import reach

    monkeypatch.setattr(reach, "SEED_BATCH", batch)
    rng = np.random.default_rng(batch)
    n = 40
    source = rng.integers(0, n, size=70)
    succ = rng.integers(0, n, size=70)
    edges = reach.Reversed(n, source, succ)
    for _ in range(3):  # several searches on the one reversal
        seeds = rng.random(n) < 0.15
        back = {s: set() for s in range(n)}
        for a, b in zip(source.tolist(), succ.tolist(), strict=True):
            back[b].add(a)
        seen, todo = set(np.flatnonzero(seeds).tolist()), list(np.flatnonzero(seeds))
        while todo:
            for p in back[int(todo.pop())]:
                if p not in seen:
                    seen.add(p)
                    todo.append(p)
        assert np.flatnonzero(edges.reaching(seeds)).tolist() == sorted(seen)


def test_a_solved_state_in_the_zero_set_leaves_the_others_their_own_slack() -> None:
    """A minimum's candidate reads the slack of the solved states outside its free set
    (``Chain.w`` holds every solved state's, in order): a policy that does not avoid
    the target from state 1, which some policy avoids it from (the zero set), makes 1
    solved and free between the solved 0 and 2, whose candidates must each be their
    own value less their own slack (the chain's slack of every state), and below the
    minimum: 3/4 at 0 (through 2 alone), 1/2 at 2 (by hand)."""
    from conftest import build_mdp

    goal, dead = 3, 4
    mdp = build_mdp([[("a", {goal: 0.5, 2: 0.5})],
                     [("go", {goal: 0.25, dead: 0.75}), ("stay", {1: 1.0})],
                     [("a", {goal: 0.5, dead: 0.5})], [], []],
                    target=[goal], sink=[dead])
    policy = np.array([0, 1, 3, -1, -1])  # state 1 plays "go" (row 1), not "stay"
    target = np.asarray(mdp.target, dtype=bool)
    zero = np.array([False, True, False, False, True])
    rnd = rounding(mdp.matrix)
    ch = C.chain(mdp, target, policy, rnd)
    assert np.flatnonzero(ch.solved).tolist() == [0, 1, 2]
    full = ch.slack  # W of every state, 0 outside the solved ones
    assert full[0] > 0 and full[2] > 0 and len({full[0], full[1], full[2]}) == 3
    side = C.optimum_lower(mdp, ch, rnd, zero=zero, layers=C.support_layers(mdp))
    assert side.check.passed and "slack x1," in side.check.detail, side.check.detail
    for s in (0, 2):
        assert side.vector[s] == max(ch.values[s] - full[s], 0.0)
    assert side.vector[1] == 0.0
    assert Fraction(float(side.vector[0])) <= Fraction(3, 4)
    assert Fraction(float(side.vector[2])) <= Fraction(1, 2)
