"""The Bellman check read in batches of rows (certify._fails, the certificate's memory
peak): on a strict pre- / sub-fixed point built from the exact values (a backward
recursion in fractions), the states it reports are exactly those moved across the
exact value, whatever the batch; the whole certificate is the same to the last bit
with batches that split every state's rows, and its bracket holds the exact value."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
import scipy.sparse as sp
from test_single_levels import layered_mdp, recursion_values

from mitld_lp.solvers import certify as certify_mod
from mitld_lp.solvers.analysis import analyse
from mitld_lp.solvers.certify_repair import Rows
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.iteration import interval_iteration
from mitld_lp.solvers.lp import solve_lp
from mitld_lp.solvers.rounding import rounding


def _exact(seed: int, sense: Sense):
    mdp, exact, goal = layered_mdp(seed, depth=15)
    return mdp, recursion_values(exact, goal, goal, sense), goal


@pytest.mark.parametrize("batch", [1, 4, 1 << 16])
@pytest.mark.parametrize("upper", [True, False])
def test_the_check_fails_exactly_the_states_moved_across_their_value(
        monkeypatch: pytest.MonkeyPatch, batch: int, upper: bool) -> None:
    monkeypatch.setattr(certify_mod, "BATCH", batch)
    # an upper bound checks every choice of a maximum, a lower bound every choice of a
    # minimum (the policy's rows): the exact values of that sense
    mdp, v, goal = _exact(5, Sense.MAX if upper else Sense.MIN)
    eps = Fraction(1, 10**6)
    # every choice leaves for the dead end with probability >= 1/46: v + eps (v - eps)
    # is a strict pre- (sub-) fixed point by more than eps/46, far above rounding
    x = np.array([float(min(max(f + eps if upper else f - eps, Fraction(0)), Fraction(1)))
                  for f in v] + [1.0, 0.0])
    moved = [3, 17, 30]
    for s in moved:  # across the exact value: the check must catch each
        x[s] = float(v[s] - eps) if upper else float(v[s] + eps)
    st = Rows(sp.csr_array(mdp.matrix), np.asarray(mdp.row_groups, dtype=np.int64))
    rnd = rounding(st.matrix)
    free = np.zeros(x.size, dtype=bool)
    free[[goal, goal + 1]] = True
    fails = certify_mod._fails(st, rnd, x, free, upper)
    assert np.flatnonzero(fails).tolist() == moved


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
def test_the_certificate_is_the_same_with_batches_that_split_the_rows(
        monkeypatch: pytest.MonkeyPatch, sense: Sense) -> None:
    mdp, v, _ = _exact(6, sense)
    it = interval_iteration(mdp, mdp.target, sense=sense, gap="max", progress=False)
    lp = solve_lp(mdp, mdp.target, sense=sense, everywhere=True,
                  bounds=(it.lower, it.upper), greedy=False)
    q, _ = analyse(mdp, mdp.target, sense=sense)
    decided, low = q.qualitative, sense is Sense.MIN
    got = []
    for batch in (3, 1 << 16):
        monkeypatch.setattr(certify_mod, "BATCH", batch)
        cert = certify_mod.certify(mdp, mdp.target, lp.policy, sense=str(sense),
                                   zero=decided.zero, one=decided.one if low else None,
                                   mec_of=None if low else q.mecs.mec_of, layers=q.layers,
                                   fallback_lower=it.lower, fallback_upper=it.upper,
                                   precision=1e-6)
        assert cert.certified, cert.checks
        got.append(cert)
    a, b = got
    assert (a.lower, a.upper, a.checks) == (b.lower, b.upper, b.checks)
    assert np.array_equal(a.values, b.values)
    s0 = int(mdp.initial)
    assert Fraction(a.lower) <= v[s0] <= Fraction(a.upper)
