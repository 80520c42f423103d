"""The Bellman checks of the certificate (``certify._fails``) settle the convex rule by
the candidate's own extremes and recheck, after a repair, only the states whose rows
read a moved value (``_fails_among``, ``_touched``): the checks' verdicts against a
reference written here row by row in Python, brackets against exact values (rational
arithmetic over every deterministic policy), and wrong candidates refused."""

from __future__ import annotations

import itertools
from fractions import Fraction

import numpy as np
import pytest
import scipy.sparse as sp
from test_certify import exact_value  # rational: Gauss-Jordan on a policy's chain

from mitld_lp.mdp import ABSORB, MDP
from mitld_lp.solvers import certify as C
from mitld_lp.solvers.rounding import rounding
from mitld_lp.testing import random_mdp


def _mdp(rows: list[list[dict[int, Fraction]]], target: set[int], sink: set[int]
         ) -> tuple[MDP, list[dict[int, Fraction]]]:
    """An MDP from each state's choices (exact distributions); absorbing states get
    one self-loop."""
    n = len(rows)
    exact, groups, acts = [], [0], []
    for s, choices in enumerate(rows):
        for c in choices or [{s: Fraction(1)}]:
            exact.append(c)
            acts.append(ABSORB if not choices else len(acts) % 2)
        groups.append(len(exact))
    data, cols, ptr = [], [], [0]
    for row in exact:
        for t in sorted(row):
            cols.append(t)
            data.append(float(row[t]))
        ptr.append(len(cols))
    matrix = sp.csr_array((np.array(data), np.array(cols), np.array(ptr)),
                          shape=(len(exact), n))
    tgt = np.zeros(n, dtype=bool)
    tgt[list(target)] = True
    snk = np.zeros(n, dtype=bool)
    snk[list(sink)] = True
    mdp = MDP(matrix=matrix, row_groups=np.array(groups, dtype=np.int64),
              choice_actions=np.array(acts, dtype=np.int32), action_names=("a0", "a1"),
              initial=0, target=tgt, sink=snk, truncated=np.zeros(n, dtype=bool),
              states=list(range(n)))
    return mdp, exact


def _optima(mdp: MDP, exact: list[dict[int, Fraction]]
            ) -> tuple[list[Fraction], list[Fraction], dict]:
    groups = np.asarray(mdp.row_groups)
    target = np.asarray(mdp.target)
    values = {pol: exact_value(mdp, exact, target, pol) for pol in itertools.product(
        *[range(groups[s], groups[s + 1]) for s in range(mdp.n_states)])}
    n = mdp.n_states
    return ([max(v[s] for v in values.values()) for s in range(n)],
            [min(v[s] for v in values.values()) for s in range(n)], values)


def _ties(hops: int) -> tuple[MDP, list[dict[int, Fraction]]]:
    """State 0 chooses between two ways to the same last step (target 3/10, sink
    7/10): one hop, or ``hops`` hops of probability 1.  Both choices have the value
    3/10 exactly, the longer one a larger slack: the first candidate of a policy taking
    the short way fails on the long one (as on QVBS ``zeroconf_dl``'s tied choices)."""
    last, target, sink = hops + 1, hops + 2, hops + 3
    rows: list[list[dict[int, Fraction]]] = [[{last: Fraction(1)}, {1: Fraction(1)}]]
    rows += [[{k + 1: Fraction(1)}] for k in range(1, hops + 1)]  # 1 -> ... -> last
    rows.append([{target: Fraction(3, 10), sink: Fraction(7, 10)},
                 {target: Fraction(1, 10), sink: Fraction(9, 10)}])
    rows += [[], []]
    return _mdp(rows, {target}, {sink})


@pytest.mark.parametrize("hops", [2, 5])
def test_tied_choices_are_repaired_and_the_bracket_holds_the_exact_value(hops) -> None:
    mdp, exact = _ties(hops)
    pmax, pmin, _ = _optima(mdp, exact)
    assert pmax[0] == Fraction(3, 10) and pmin[0] == Fraction(1, 10)
    target = np.asarray(mdp.target)
    groups = np.asarray(mdp.row_groups)
    policy = np.where(target | np.asarray(mdp.sink), -1, groups[:-1])  # the short way
    zero = np.array([p == 0 for p in pmax])
    cert = C.certify(mdp, target, policy, sense="max", zero=zero, precision=1e-6)
    assert cert.certified
    assert Fraction(cert.lower) <= pmax[0] <= Fraction(cert.upper)
    assert Fraction(cert.upper) - Fraction(cert.lower) <= Fraction(1, 10**9)
    assert "states repaired" in cert.checks[1].detail  # the tie took the repair


@pytest.mark.parametrize("seed", range(5))
def test_random_small_mdps_bracket_the_exact_optimum(seed) -> None:
    mdp = random_mdp(7, seed=seed, max_choices=2, max_successors=3, target_fraction=0.2,
                     sink_fraction=0.15, self_loop_fraction=0.0)
    m = sp.csr_array(mdp.matrix)
    # the exact model: each stored row in rational arithmetic, divided by its exact
    # sum (a distribution; its floats are within a few units of roundoff of it)
    exact = []
    for r in range(m.shape[0]):
        row = {int(t): Fraction(float(p)) for t, p in zip(
            m.indices[m.indptr[r]:m.indptr[r + 1]], m.data[m.indptr[r]:m.indptr[r + 1]],
            strict=True)}
        total = sum(row.values())
        exact.append({t: p / total for t, p in row.items()})
    pmax, pmin, values = _optima(mdp, exact)
    target = np.asarray(mdp.target)
    best = max(values, key=lambda pol: [values[pol][s] for s in range(mdp.n_states)])
    dead = target | np.asarray(mdp.sink)
    policy = np.where(dead, -1, np.array(best))
    cert = C.certify(mdp, target, policy, sense="max",
                     zero=np.array([p == 0 for p in pmax]))
    assert cert.certified and Fraction(cert.lower) <= pmax[0] <= Fraction(cert.upper)
    worst = min(values, key=lambda pol: [values[pol][s] for s in range(mdp.n_states)])
    low = C.certify(mdp, target, np.where(dead, -1, np.array(worst)), sense="min",
                    zero=np.array([p == 0 for p in pmin]))
    assert Fraction(low.lower) <= pmin[0] <= Fraction(low.upper)


# ------------------------------------------------------------------ the checks themselves


def _reference(st: C.Rows, rnd, x: np.ndarray, free: np.ndarray, upper: bool
               ) -> np.ndarray:
    """``_fails`` from its definition, row by row in Python: the row's float sum in its
    entries' order, the rounding's factors for its count, the convex rule by Python's
    max / min over its stored columns."""
    m = st.matrix
    failing = np.zeros(st.n_states, dtype=bool)
    for s in range(st.n_states):
        if free[s]:
            continue
        for r in range(st.groups[s], st.groups[s + 1]):
            cols = m.indices[m.indptr[r]:m.indptr[r + 1]].tolist()
            vals = m.data[m.indptr[r]:m.indptr[r + 1]].tolist()
            total = 0.0
            for c, p in zip(cols, vals, strict=True):
                total += p * float(x[c])
            k = len(cols)
            if upper:
                bound = (total + rnd.slack_of[k]) * rnd.high_of[k]
                ok = bound <= x[s] or (not cols or max(x[cols]) <= x[s])
            else:
                bound = max((total - rnd.slack_of[k]) * rnd.low_of[k], 0.0)
                ok = bound >= x[s] or (not cols or min(x[cols]) >= x[s])
            if not ok:
                failing[s] = True
    return failing


def _candidate(rng: np.random.Generator, n: int) -> np.ndarray:
    x = rng.random(n)
    pick = rng.random(n)
    x[pick < 0.3] = 0.0
    x[pick > 0.65] = 1.0
    return x


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("upper", [True, False])
@pytest.mark.parametrize("batch", [7, 1 << 16])
def test_the_checks_agree_with_a_row_by_row_reference(seed, upper, batch,
                                                       monkeypatch) -> None:
    monkeypatch.setattr(C, "BATCH", batch)  # slices of a few rows, and one
    mdp = random_mdp(200, seed=seed, max_choices=3, max_successors=3, locality=6)
    st = C.Rows(sp.csr_array(mdp.matrix), np.asarray(mdp.row_groups, dtype=np.int64))
    rnd = rounding(st.matrix)
    rng = np.random.default_rng(seed)
    free = np.asarray(mdp.target, dtype=bool)
    for _ in range(3):
        x = _candidate(rng, mdp.n_states)
        want = _reference(st, rnd, x, free, upper)
        assert want.any()  # wrong candidates: refused in the same states
        assert np.array_equal(C._fails(st, rnd, x, free, upper), want)
        assert np.array_equal(C._fails_among(st, rnd, x, free, upper,
                                             np.diff(st.groups) > 0), want)
        # one value moved: the states its change can reach, checked alone, agree with
        # a whole check of the moved candidate
        y = x.copy()
        moved = rng.choice(mdp.n_states, 5, replace=False)
        y[moved] = rng.random(5)
        again = C._touched(st, y != x, None) | want
        assert np.array_equal(C._fails_among(st, rnd, y, free, upper, again),
                              _reference(st, rnd, y, free, upper))


def test_a_stored_zero_is_read_as_support() -> None:
    # state 0's only choice stores a 0.0 entry to state 2 (x = 1) beside state 1 (x = 0):
    # the upper candidate's 0 at state 0 passes the arithmetic's sum only by the
    # convex rule, which reads the stored columns: refused, as row by row
    matrix = sp.csr_array((np.array([1.0, 0.0, 1.0, 1.0]), np.array([1, 2, 1, 2]),
                           np.array([0, 2, 3, 4])), shape=(3, 3))
    st = C.Rows(matrix, np.array([0, 1, 2, 3], dtype=np.int64))
    rnd = rounding(matrix)
    x = np.array([0.0, 0.0, 1.0])
    free = np.array([False, False, True])
    want = _reference(st, rnd, x, free, True)
    assert want.tolist() == [True, False, False]
    assert np.array_equal(C._fails(st, rnd, x, free, True), want)


def test_a_candidate_below_the_exact_optimum_is_refused() -> None:
    mdp, exact = _ties(3)
    pmax, _, _ = _optima(mdp, exact)
    st = C.Rows(sp.csr_array(mdp.matrix), np.asarray(mdp.row_groups, dtype=np.int64))
    rnd = rounding(st.matrix)
    free = np.asarray(mdp.target, dtype=bool)
    x = np.array([float(p) for p in pmax]) * (1.0 + 1e-9)
    x[free] = 1.0
    x = np.minimum(x, 1.0)
    assert not C._fails(st, rnd, x, free, True).any()  # above the optimum: passes
    for s in np.flatnonzero((np.array(pmax) > 0) & ~free):
        low = x.copy()
        low[s] = float(pmax[s]) * (1.0 - 1e-9)  # one state below its exact optimum
        assert C._fails(st, rnd, low, free, True)[s]
    zero = x.copy()
    zero[0] = 0.0  # a 0 the graph does not give: its successors are positive
    assert C._fails(st, rnd, zero, free, True)[0]


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("loops", [0.0, 0.2])
def test_a_repair_skips_no_round_a_level_needs(seed, loops, monkeypatch) -> None:
    # a level none of whose rows reads the level stops after its first round: the same
    # bounds as taking every level up again (``inward`` True everywhere, as before)
    from mitld_lp.solvers import certify_repair as R
    from mitld_lp.solvers.certify_chain import support_layers

    mdp = random_mdp(400, seed=seed, locality=5, self_loop_fraction=loops, max_choices=3)
    st = C.Rows(sp.csr_array(mdp.matrix), np.asarray(mdp.row_groups, dtype=np.int64))
    rnd = rounding(st.matrix)
    comp, level = support_layers(mdp)
    level_of = np.asarray(level)[np.asarray(comp)]
    free = np.asarray(mdp.target, dtype=bool)
    rng = np.random.default_rng(seed)
    x0 = np.where(free, 1.0, rng.random(mdp.n_states) * 0.5)
    failing = C._fails(st, rnd, x0, free, True)
    assert failing.any()
    runs = []
    for always in (False, True):
        if always:
            init = R._Walk.__init__

            def everywhere(self, *args, init=init):
                init(self, *args)
                self.inward = np.ones_like(self.inward)
            monkeypatch.setattr(R._Walk, "__init__", everywhere)
        x = x0.copy()
        repair = R.Repair(st, rnd, free, level_of, None, True)
        runs.append((repair.run(x, failing), x, repair.moved))
    (ok_a, a, moved_a), (ok_b, b, moved_b) = runs
    assert ok_a == ok_b and np.array_equal(a, b) and moved_a == moved_b > 0
    if ok_a:
        assert not C._fails(st, rnd, a, free, True).any()


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("upper", [True, False])
def test_a_robust_games_recheck_agrees_with_the_whole_check(seed, upper) -> None:
    # nature's rows: a state's rows paired into choices (nature picks one of a pair)
    mdp = random_mdp(150, seed=seed, max_choices=4, max_successors=3, locality=5)
    groups = np.asarray(mdp.row_groups, dtype=np.int64)
    nature, per_state = [0], []
    for s in range(mdp.n_states):
        k = int(groups[s + 1] - groups[s])
        starts = list(range(int(groups[s]), int(groups[s + 1]), 2))
        nature += [min(a + 2, int(groups[s]) + k) for a in starts]
        per_state.append(len(starts))
    st = C.Rows(sp.csr_array(mdp.matrix),
                np.concatenate([[0], np.cumsum(per_state)]).astype(np.int64),
                np.array(nature, dtype=np.int64))
    rnd = rounding(st.matrix)
    rng = np.random.default_rng(seed)
    free = np.asarray(mdp.target, dtype=bool)
    x = _candidate(rng, mdp.n_states)
    whole = C._fails(st, rnd, x, free, upper)
    assert whole.any() and not whole.all()
    assert np.array_equal(C._fails_among(st, rnd, x, free, upper,
                                         np.diff(st.groups) > 0), whole)
    y = x.copy()
    y[rng.choice(mdp.n_states, 5, replace=False)] = rng.random(5)
    again = C._touched(st, y != x, None) | whole
    assert np.array_equal(C._fails_among(st, rnd, y, free, upper, again),
                          C._fails(st, rnd, y, free, upper))
