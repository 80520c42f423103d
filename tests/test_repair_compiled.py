"""The repair's rounds on a large level by one compiled call
(:func:`mitld_lp.solvers.certify_compiled.compiled_rounds`) against the NumPy rounds
they replace: the same bounds to the bit, the same moves and the same verdict, on
random MDPs with cycles and tied choices; and on small rare-event MDPs with ties the
certificate's bracket, repaired through the kernel, holds the exact optimum computed
here in rational arithmetic by trying every deterministic policy."""

from __future__ import annotations

import itertools
from fractions import Fraction

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.solvers import certify as C
from mitld_lp.solvers import certify_compiled as CC
from mitld_lp.solvers import certify_repair as R
from mitld_lp.solvers.certify_chain import support_layers
from mitld_lp.solvers.rounding import rounding
from mitld_lp.testing import random_mdp
from mitld_lp.util import kernel_loader


@pytest.fixture
def hot(monkeypatch):
    """The compiled rounds on (their load counted as paid, their cache as warm), every
    level read as a large one, and a count of the kernel's calls."""
    monkeypatch.setattr(kernel_loader, "compiled_paid", lambda: True)
    monkeypatch.setattr(CC, "_ROUNDS_WARM", [True])
    monkeypatch.setattr(R, "SPARSE_LEVEL", 1)
    calls = []
    real = CC.compiled_rounds

    def counted(*args):
        got = real(*args)
        calls.append(got is not None)
        return got

    monkeypatch.setattr(R, "compiled_rounds", counted)
    return calls


def _run(mdp, x0, free, upper, compiled: bool, monkeypatch, rounds: int | None = None):
    """The repair of ``x0`` (compiled rounds or NumPy's), the matrix's indices in int32
    as a product's are (so these tests leave the kernel's cache file a product reads)."""
    m = sp.csr_array(mdp.matrix)
    m = sp.csr_array((m.data, m.indices.astype(np.int32), m.indptr.astype(np.int32)),
                     shape=m.shape)
    st = C.Rows(m, np.asarray(mdp.row_groups, dtype=np.int64))
    rnd = rounding(st.matrix)
    comp, level = support_layers(mdp)
    level_of = np.asarray(level)[np.asarray(comp)]
    x = x0.copy()
    failing = C._fails(st, rnd, x, free, upper)
    with monkeypatch.context() as mp:
        if not compiled:
            mp.setattr(R, "compiled_rounds", lambda *a: None)
        if rounds is not None:
            mp.setattr(R, "ROUNDS", rounds)
        rep = R.Repair(st, rnd, free, level_of, None, upper)
        ok = rep.run(x, failing)
    return ok, x, rep.moved, st, rnd


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("upper", [True, False])
def test_compiled_rounds_move_the_bounds_of_the_numpy_rounds(seed, upper, hot,
                                                             monkeypatch) -> None:
    """Cycles (self-loops, states reading upstream ones) and tied choices: the kernel's
    rounds give the NumPy rounds' bounds bit for bit, their count of moves and their
    verdict, and where the repair closed the whole Bellman check passes."""
    mdp = random_mdp(300, seed=seed, locality=6, self_loop_fraction=0.3, max_choices=3)
    free = np.asarray(mdp.target, dtype=bool)
    rng = np.random.default_rng(seed)
    x0 = np.where(free, 1.0, rng.random(mdp.n_states) * (0.5 if upper else 1.0))
    a = _run(mdp, x0, free, upper, False, monkeypatch)
    b = _run(mdp, x0, free, upper, True, monkeypatch)
    assert hot and all(hot)  # the kernel ran, on every large level with work
    assert a[0] == b[0] and a[1].tobytes() == b[1].tobytes() and a[2] == b[2] > 0
    if b[0]:
        assert not C._fails(b[3], b[4], b[1], free, upper).any()


@pytest.mark.parametrize("upper", [True, False])
def test_compiled_rounds_give_up_where_the_numpy_rounds_do(upper, hot, monkeypatch) -> None:
    """With one round a level, a level still moving after its round is refused by both
    routes alike, with the same bounds moved up to there."""
    mdp = random_mdp(300, seed=7, locality=6, self_loop_fraction=0.3, max_choices=3)
    free = np.asarray(mdp.target, dtype=bool)
    rng = np.random.default_rng(7)
    x0 = np.where(free, 1.0, rng.random(mdp.n_states) * (0.5 if upper else 1.0))
    a = _run(mdp, x0, free, upper, False, monkeypatch, rounds=1)
    b = _run(mdp, x0, free, upper, True, monkeypatch, rounds=1)
    assert hot and all(hot)
    assert not a[0] and not b[0]
    assert a[1].tobytes() == b[1].tobytes() and a[2] == b[2] > 0


def _retries(p: Fraction, q: Fraction, k: int):
    """A rare event with ties: ``k`` stages to pass, each with two tied choices (the
    same law: pass with ``p``, fail back to stage 0 with ``q``, to the sink with the
    rest) and a worse third (pass with ``p / 2``); past the last stage the goal.  Goal
    ``k``, sink ``k + 1``."""
    from conftest import build_mdp

    goal, sink = k, k + 1
    choices = []
    for s in range(k):
        same = {s + 1: float(p), 0: float(q), sink: float(1 - p - q)}
        if s == 0:
            same = {1: float(p), 0: float(q), sink: float(1 - p - q)}
        worse = {s + 1: float(p / 2), 0: float(q), sink: float(1 - p / 2 - q)}
        choices.append([("a", same), ("b", dict(same)), ("c", worse)])
    choices += [[], []]
    return build_mdp(choices, target=[goal], sink=[sink]), goal, sink


def _exact_max(mdp, goal: int) -> list[Fraction]:
    """Pmax of reaching ``goal`` from every state, in rationals: each deterministic
    policy's chain solved exactly (the states that cannot reach the goal under it at
    0), the best value of each state over every policy (one policy attains them all)."""
    n = mdp.n_states
    m = sp.csr_array(mdp.matrix)
    groups = np.asarray(mdp.row_groups)
    rows_of = {}
    for r in range(m.shape[0]):
        a, z = m.indptr[r], m.indptr[r + 1]
        rows_of[r] = {int(j): Fraction(float(v)) for j, v in zip(m.indices[a:z], m.data[a:z],
                                                                strict=True)}
    live = [s for s in range(n) if s != goal and groups[s + 1] > groups[s]
            and not (groups[s + 1] - groups[s] == 1 and rows_of[int(groups[s])] == {s: 1})]
    best = [Fraction(0)] * n
    best[goal] = Fraction(1)
    for pick in itertools.product(*(range(groups[s], groups[s + 1]) for s in live)):
        row = dict(zip(live, pick, strict=True))
        reach = {goal}
        grew = True
        while grew:
            grew = False
            for s in live:
                if s not in reach and any(t in reach for t in rows_of[row[s]]):
                    reach.add(s)
                    grew = True
        unk = [s for s in live if s in reach]
        idx = {s: i for i, s in enumerate(unk)}
        a = [[Fraction(int(i == j)) for j in range(len(unk))] + [Fraction(0)]
             for i in range(len(unk))]
        for s in unk:
            for t, v in rows_of[row[s]].items():
                if t == goal:
                    a[idx[s]][-1] += v
                elif t in idx:
                    a[idx[s]][idx[t]] -= v
        for c in range(len(unk)):  # Gauss-Jordan elimination in rationals
            piv = next(r for r in range(c, len(unk)) if a[r][c] != 0)
            a[c], a[piv] = a[piv], a[c]
            a[c] = [v / a[c][c] for v in a[c]]
            for r in range(len(unk)):
                if r != c and a[r][c] != 0:
                    f = a[r][c]
                    a[r] = [u - f * w for u, w in zip(a[r], a[c], strict=True)]
        for s in unk:
            best[s] = max(best[s], a[idx[s]][-1])
    return best


@pytest.mark.parametrize("k,p,q", [(4, Fraction(1, 64), Fraction(1, 8)),
                                   (5, Fraction(1, 32), Fraction(1, 4)),
                                   (3, Fraction(1, 1024), Fraction(1, 8))])
def test_a_rare_event_bracket_repaired_compiled_holds_the_exact_value(k, p, q, hot,
                                                                     monkeypatch) -> None:
    """The certificate of a policy with ties and one worse choice on a rare event
    (values down to 1e-9), its upper candidate repaired through the kernel: lower <= the
    exact Pmax <= upper at the initial state, and the same bracket to the bit as with
    the NumPy rounds."""
    mdp, goal, sink = _retries(p, q, k)
    exact = _exact_max(mdp, goal)
    assert 0 < exact[0] < Fraction(1, 10) ** (k + 1)  # a rare event
    policy = np.asarray(mdp.row_groups[:-1], dtype=np.int64).copy()
    policy[k - 1] += 2  # the worse choice at the last stage: its upper candidate fails
    zero = np.zeros(mdp.n_states, dtype=bool)
    zero[sink] = True
    got = {}
    for compiled in (True, False):
        with monkeypatch.context() as mp:
            if not compiled:
                mp.setattr(R, "compiled_rounds", lambda *a: None)
            cert = C.certify(mdp, mdp.target, policy, sense="max", zero=zero)
        assert all(c.passed for c in cert.checks), [c.detail for c in cert.checks]
        got[compiled] = (cert.lower, cert.upper)
        assert "states repaired" in cert.checks[1].detail  # the repair ran
        assert Fraction(cert.lower) <= exact[0] <= Fraction(cert.upper)
    assert got[True] == got[False]
    assert hot and any(hot)  # the kernel repaired


@pytest.mark.parametrize("k,p,q", [(4, Fraction(1, 64), Fraction(7, 8)),
                                   (3, Fraction(1, 1024), Fraction(1, 2))])
def test_a_candidate_below_the_optimum_is_repaired_above_it(k, p, q, hot,
                                                            monkeypatch) -> None:
    """An upper candidate below the exact optimum on every live state (the exact value
    rounded down, halved at one state): the compiled repair closes, the whole check
    passes, each bound is at least the exact Pmax, bit for bit the NumPy repair's."""
    mdp, goal, sink = _retries(p, q, k)
    exact = _exact_max(mdp, goal)
    free = np.zeros(mdp.n_states, dtype=bool)
    free[[goal, sink]] = True
    x0 = np.array([float(v) for v in exact])
    x0[:goal] = np.nextafter(x0[:goal], 0.0)
    x0[1] /= 2
    a = _run(mdp, x0, free, True, False, monkeypatch)
    b = _run(mdp, x0, free, True, True, monkeypatch)
    assert hot and all(hot)
    assert a[0] and b[0] and a[1].tobytes() == b[1].tobytes() and a[2] == b[2] > 0
    assert not C._fails(b[3], b[4], b[1], free, True).any()
    assert all(Fraction(float(b[1][s])) >= exact[s] for s in range(mdp.n_states))


@pytest.mark.parametrize("warm,paid", [(False, True), (True, False)])
def test_no_compiled_rounds_on_a_cold_cache_or_an_unpaid_load(warm, paid,
                                                              monkeypatch) -> None:
    """Without the kernel's cache file, or before any compiled kernel's load is paid,
    the rounds are NumPy's (no compile, no load paid by the repair), with the same
    bounds."""
    monkeypatch.setattr(kernel_loader, "compiled_paid", lambda: paid)
    monkeypatch.setattr(CC, "_ROUNDS_WARM", [warm])
    monkeypatch.setattr(R, "SPARSE_LEVEL", 1)
    calls = []
    real = CC.compiled_rounds

    def counted(*args):
        got = real(*args)
        calls.append(got is not None)
        return got

    monkeypatch.setattr(R, "compiled_rounds", counted)
    mdp = random_mdp(200, seed=3, locality=6, self_loop_fraction=0.3, max_choices=3)
    free = np.asarray(mdp.target, dtype=bool)
    x0 = np.where(free, 1.0, np.random.default_rng(3).random(mdp.n_states) * 0.5)
    got = _run(mdp, x0, free, True, True, monkeypatch)
    assert calls and not any(calls)
    want = _run(mdp, x0, free, True, False, monkeypatch)
    assert got[1].tobytes() == want[1].tobytes() and got[2] == want[2]
