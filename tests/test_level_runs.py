"""The single states taken a run of levels at a time (topological.SingleLevels.values /
.flow / .solve, the certificate's chain, NumPy and compiled): the block LP's answer
(values, policy, occupancy, status), the interval iteration's bounds and the
certificate (bracket, checks, values) are those of the level-by-level walk to the last
bit, on deadline-like acyclic products and on random MDPs with cycles; the values
against a backward recursion in exact arithmetic (acyclic) and scipy's LP (mixed)."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
import scipy.optimize as opt
from conftest import build_mdp
from test_single_levels import layered_mdp, recursion_values

from mitld_lp.solvers import lp_blocks, topological
from mitld_lp.solvers.analysis import analyse
from mitld_lp.solvers.certify import certify
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.iteration import interval_iteration
from mitld_lp.solvers.lp import solve_lp

numba = pytest.importorskip("numba")

WALKS = ("levels", "numpy", "compiled")


def _walk(monkeypatch: pytest.MonkeyPatch, how: str) -> None:
    """``levels``: level by level (the walk before runs); ``numpy`` / ``compiled``: runs
    of levels, without / with the kernels, whatever the product's size."""
    monkeypatch.setattr(lp_blocks, "RUNS_MIN_LEVELS", 10**9 if how == "levels" else 0)
    big = how != "compiled"
    monkeypatch.setattr(topological, "LEVEL_KERNEL_MIN_ENTRIES", 10**12 if big else 0)
    monkeypatch.setattr(topological, "LEVEL_KERNEL_MIN_LEVELS", 10**12 if big else 0)
    # the gate as if no compiled kernel's load were paid in this process
    monkeypatch.setattr(topological.kernel_loader, "compiled_paid", lambda: False)


def _answers(monkeypatch, mdp, sense: Sense):
    out = {}
    for how in WALKS:
        _walk(monkeypatch, how)
        it = interval_iteration(mdp, mdp.target, sense=sense, gap="max", progress=False)
        # the block LPs themselves between the runs (the bounds' greedy policy,
        # certified, would answer the blocks without them)
        lp = solve_lp(mdp, mdp.target, sense=sense, everywhere=True,
                      bounds=(it.lower, it.upper), greedy=False)
        q, _ = analyse(mdp, mdp.target, sense=sense)
        decided, low = q.qualitative, sense is Sense.MIN
        cert = certify(mdp, mdp.target, lp.policy, sense=str(sense), zero=decided.zero,
                       one=decided.one if low else None,
                       mec_of=None if low else q.mecs.mec_of, layers=q.layers,
                       fallback_lower=it.lower, fallback_upper=it.upper, precision=1e-6)
        assert cert.certified, cert.checks
        out[how] = (it, lp, cert)
    return out


def _same(a, b) -> None:
    it_a, lp_a, cert_a = a
    it_b, lp_b, cert_b = b
    assert (cert_a.lower, cert_a.upper, cert_a.checks) == (cert_b.lower, cert_b.upper,
                                                           cert_b.checks)
    assert np.array_equal(cert_a.values, cert_b.values)
    assert np.array_equal(it_a.lower, it_b.lower) and np.array_equal(it_a.upper, it_b.upper)
    assert lp_a.status is lp_b.status and lp_a.message == lp_b.message
    assert lp_a.value == lp_b.value
    for name in ("values", "policy", "occupancy", "randomized"):
        assert np.array_equal(getattr(lp_a, name), getattr(lp_b, name)), name


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
def test_acyclic_runs_give_the_level_walks_answer_and_the_exact_values(
        monkeypatch: pytest.MonkeyPatch, seed: int, sense: Sense) -> None:
    mdp, exact, goal = layered_mdp(seed, depth=40)
    got = _answers(monkeypatch, mdp, sense)
    _same(got["levels"], got["numpy"])
    _same(got["levels"], got["compiled"])
    want = recursion_values(exact, goal, goal, sense)
    cert = got["compiled"][2]  # the certified bracket holds the exact optimum
    assert Fraction(cert.lower) <= want[0] <= Fraction(cert.upper)
    assert cert.upper - cert.lower <= 1e-6 * cert.lower
    values = got["compiled"][1].values
    for s in range(goal):
        assert abs(Fraction(values[s]) - want[s]) <= Fraction(2.0 ** -48) * want[s], s
    # the policy attains the exact optimum: its chain solved exactly
    policy = got["compiled"][1].policy
    v: dict[int, Fraction] = {goal: Fraction(1), goal + 1: Fraction(0)}
    for s in range(goal - 1, -1, -1):
        row = exact[s][int(policy[s]) - int(mdp.row_groups[s])]
        stay = Fraction(row.get(s, 0.0))
        v[s] = sum((Fraction(p) * v[t] for t, p in row.items() if t != s),
                   Fraction(0)) / (1 - stay)
        assert abs(v[s] - want[s]) <= Fraction(2.0 ** -40) * want[s], s


def _scipy_value(mdp, sense: Sense) -> float:
    """The optimum at the initial state by scipy's LP on the raw MDP, ``v = 1`` on the
    target: for a maximum the least ``v`` with ``v(s) >= P(c) v`` for every choice,
    ``0`` where no choice leads to the target; for a minimum the greatest ``v`` with
    ``v(s) <= P(c) v``, ``0`` where some policy avoids the target for ever (the
    greatest set closed under some choice, found here by removal)."""
    n = mdp.n_states
    p = mdp.matrix.toarray() > 0
    starts = mdp.row_groups[:-1]
    a = mdp.matrix.toarray()
    owner = mdp.choice_state()
    a[np.arange(a.shape[0]), owner] -= 1.0  # P(c) v - v(s)
    target = np.asarray(mdp.target, dtype=bool)
    if sense is Sense.MAX:  # zero: cannot reach the target
        zero = ~target
        while True:
            hits = np.logical_or.reduceat((p & ~zero[None, :]).any(axis=1), starts)
            if not (zero & hits).any():
                break
            zero &= ~hits
    else:  # zero: some choice keeps the play inside, for ever
        zero = ~target
        while True:
            stays = np.logical_or.reduceat(~(p & ~zero[None, :]).any(axis=1), starts)
            if np.array_equal(zero & stays, zero):
                break
            zero &= stays
    bounds = [(1.0, 1.0) if target[s] else (0.0, 0.0) if zero[s] else (0.0, 1.0)
              for s in range(n)]
    rows = ~target[owner]
    sign = 1.0 if sense is Sense.MAX else -1.0  # max: (P(c) - e_s) v <= 0, min: >= 0
    res = opt.linprog(sign * np.ones(n), A_ub=sign * a[rows],
                      b_ub=np.zeros(int(rows.sum())), bounds=bounds, method="highs")
    assert res.status == 0, res.message
    return float(res.x[mdp.initial])


def _mixed(seed: int, depth: int = 40, width: int = 3):
    """A deadline-like product (:func:`test_single_levels._layered`) in which every
    fifth layer's states may also step back to the layer above (cycles over two
    layers, with choices): runs of single-state levels between block LPs.  The first
    state of every seventh layer has only exactly tied choices: to a state of value
    1/2, to the goal with probability 1/2 (the larger one-step target probability),
    and that again (the later index)."""
    rng = np.random.default_rng(seed)
    mdp, _, goal = layered_mdp(seed, depth, width)
    half = goal + 2
    rows = []
    for s in range(goal):
        mine = []
        layer = s // width
        if layer % 7 == 3 and s % width == 0:
            coin = {goal: 0.5, goal + 1: 0.5}
            rows.append([("via", {half: 1.0}), ("coin", coin), ("again", dict(coin))])
            continue
        for c in range(int(mdp.row_groups[s]), int(mdp.row_groups[s + 1])):
            row = mdp.matrix[[c]].toarray()[0]
            succ = {int(t): float(row[t]) for t in np.flatnonzero(row)}
            mine.append((f"a{c - int(mdp.row_groups[s])}", succ))
        if layer % 5 == 4 and layer > 0:
            back = (layer - 1) * width + int(rng.integers(width))
            w = rng.integers(1, 6, size=2).astype(float)
            mine.append(("back", {back: float(w[0] / w.sum()), goal + 1: float(w[1] / w.sum())}
                         if rng.random() < 0.5 else {back: 1.0}))
        rows.append(mine)
    rows += [[], [], [("coin", {goal: 0.5, goal + 1: 0.5})]]
    return build_mdp(rows, target=[goal], sink=[goal + 1])


@pytest.mark.parametrize("seed", range(2))
@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
def test_mixed_runs_give_the_level_walks_answer_and_scipys_value(
        monkeypatch: pytest.MonkeyPatch, seed: int, sense: Sense) -> None:
    mdp = _mixed(seed, depth=30)
    got = _answers(monkeypatch, mdp, sense)
    words = got["levels"][1].message.split()  # "clarabel: 6 block LPs and ..."
    assert int(words[1]) > 0 and int(words[5]) > 20, got["levels"][1].message
    _same(got["levels"], got["numpy"])
    _same(got["levels"], got["compiled"])
    policy = got["compiled"][1].policy
    tied = np.arange(3 * 3, 30 * 3, 7 * 3)  # the first state of layers 3, 10, 17, 24
    # the maximum takes the coin (the larger target step), the minimum the move
    assert np.all(policy[tied] == mdp.row_groups[tied] + (1 if sense is Sense.MAX else 0))
    want = _scipy_value(mdp, sense)
    assert got["compiled"][1].value == pytest.approx(want, abs=1e-7)
    # the default, where the bounds' greedy policy may answer a block between the runs
    it = interval_iteration(mdp, mdp.target, sense=sense, gap="max", progress=False)
    default = solve_lp(mdp, mdp.target, sense=sense, everywhere=True,
                       bounds=(it.lower, it.upper))
    assert default.value == pytest.approx(want, abs=1e-7)


@pytest.mark.parametrize("seed", [0, 1])
def test_the_repair_reaches_every_state_a_moved_bound_is_read_by(seed: int) -> None:
    """The upper bound on the maximum from a poor policy (each state's worst choice):
    its values fail the Bellman check wherever a better choice exists, the repair moves
    them level by level (the states reading a moved one found from the matrix's
    columns), and the repaired vector passes with the first slack and lies above the
    exact optimum (the backward recursion) at the initial state."""
    from mitld_lp.solvers import certify as C

    mdp, exact, goal = layered_mdp(seed, depth=40)
    want = recursion_values(exact, goal, goal, Sense.MAX)
    worst = recursion_values(exact, goal, goal, Sense.MIN)
    policy = np.full(mdp.n_states, -1, dtype=np.int64)
    for s in range(goal):  # the minimum's choice: the chain of the worst policy
        scores = []
        for row in exact[s]:
            stay = Fraction(row.get(s, 0.0))
            scores.append(sum((Fraction(p) * (worst[t] if t < goal else int(t == goal))
                               for t, p in row.items() if t != s), Fraction(0)) / (1 - stay))
        policy[s] = int(mdp.row_groups[s]) + scores.index(min(scores))
    zero = np.zeros(mdp.n_states, dtype=bool)
    zero[goal + 1] = True
    cert = C.certify(mdp, mdp.target, policy, sense="max", zero=zero, sides=("upper",))
    (check,) = cert.checks
    assert check.passed and "slack x1," in check.detail, check.detail
    moved = int(check.detail.split(" states repaired")[0].rsplit(" ", 1)[1])
    assert moved > goal // 4  # the repair did the work, over many levels
    assert Fraction(cert.upper) >= want[0]
    assert float(want[0]) == pytest.approx(cert.upper, rel=1e-9)


def test_the_minimums_end_component_check_finds_a_cycle_of_two_states() -> None:
    """States 0 and 1 can pass the play to each other for ever (an end component of two
    states, no self-loop): Pmin = 0 there.  Told that only the sink avoids the target,
    the certificate's search (among the states of cyclic components and those with a
    choice that stays put) finds it and falls back to the bound 0; told the truth, the
    bound holds."""
    from mitld_lp.solvers import certify as C

    goal, sink = 2, 3
    mdp = build_mdp([[("a", {1: 1.0}), ("b", {goal: 0.5, sink: 0.5})],
                     [("a", {0: 1.0}), ("b", {goal: 1.0})], [], []],
                    target=[goal], sink=[sink])
    policy = np.array([0, 2, -1, -1])  # each state's first choice: the cycle
    zero = np.zeros(4, dtype=bool)
    zero[sink] = True
    cert = C.certify(mdp, mdp.target, policy, sense="min", zero=zero)
    assert cert.lower == 0.0 and not cert.certified
    assert any("1 end components outside the zero set (state 0)" in c.detail
               for c in cert.checks)
    zero[:2] = True
    cert = C.certify(mdp, mdp.target, policy, sense="min", zero=zero)
    assert cert.certified and cert.lower == 0.0 == cert.upper


@pytest.mark.parametrize(("seed", "sense"), [(4, Sense.MAX), (5, Sense.MAX),
                                            (5, Sense.MIN)])
def test_runs_leave_the_states_known_to_be_zero_to_their_choice(
        monkeypatch: pytest.MonkeyPatch, seed: int, sense: Sense) -> None:
    """The lower model of a truncated product keeps the states that can reach only a
    truncated state (here: the sinks) with value 0 (``Quotient.zero``): the runs skip
    them as the level walk does, to the last bit, and the value is scipy's."""
    from mitld_lp.testing import random_mdp

    mdp = random_mdp(400, seed=seed, target_fraction=0.05, sink_fraction=0.03,
                     self_loop_fraction=0.02, max_choices=3, max_successors=3, locality=6)
    got = {}
    for how in WALKS:
        _walk(monkeypatch, how)
        low, _ = analyse(mdp, mdp.target, np.asarray(mdp.sink), sense=sense)
        assert low.zero.any()
        got[how] = solve_lp(mdp, low.target, quotient=low, sense=sense, everywhere=True)
    for how in ("numpy", "compiled"):
        assert got[how].message == got["levels"].message
        for name in ("values", "policy", "occupancy", "randomized"):
            assert np.array_equal(getattr(got[how], name), getattr(got["levels"], name))
    assert got["compiled"].value == pytest.approx(_scipy_value(mdp, sense), abs=1e-7)
