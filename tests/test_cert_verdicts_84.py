"""cert-84: the Bellman check by state verdicts on both sides
(:func:`mitld_lp.solvers.certify_compiled.compiled_failing`, the repair kernel's
``state_needs`` asked for verdicts), with the rows the convex rule settles skipped (a
state at ``x``'s extreme on the passing side) or read by the rule first (one at the
other extreme).

The verdicts are held against the check's definition evaluated here a row at a time
(the rounded sum in the row's order, the convex rule's extreme compared in exact
rationals), and against the NumPy check and the compiled row check they replace; the
certificate's brackets against exact optima: the brute force of
``test_cert_small_exact`` (every deterministic policy solved in fractions) and a
linear program solved by SciPy's HiGHS on larger random MDPs with end components,
both senses, compiled paths on and off (the same bits)."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.optimize import linprog
from test_cert_fast_exact import model_of_rows
from test_cert_small_exact import exact_optimum, paid_kernels, small_model

from mitld_lp.solvers import certify as C
from mitld_lp.solvers import certify_compiled as CC
from mitld_lp.solvers.rounding import rounding
from mitld_lp.util import kernel_loader

TIES = (0.0, 0.25, 0.5, 0.75, 1.0)


def random_rows(seed: int) -> tuple[C.Rows, np.ndarray, np.ndarray]:
    """``(st, x, free)``: 1-9 states, 1-3 choices a state, 1-3 rows of nature a choice
    or one, 0-4 entries a row (dyadic or random probabilities), ``x`` of tied values
    (0 and 1 among them: states at both extremes) or random ones."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 10))
    robust = bool(rng.random() < 0.3)
    groups = np.concatenate([[0], np.cumsum(rng.integers(1, 4, size=n))]).astype(np.int64)
    per = rng.integers(1, 4, size=int(groups[-1])) if robust else np.ones(int(groups[-1]),
                                                                            int)
    nature = np.concatenate([[0], np.cumsum(per)]).astype(np.int64)
    ptr, cols, vals = [0], [], []
    dyadic = bool(rng.random() < 0.5)
    for _ in range(int(nature[-1])):
        c = np.sort(rng.choice(n, size=min(int(rng.integers(0, 5)), n), replace=False))
        p = rng.integers(1, 5, size=c.size) / 4.0 if dyadic else rng.random(c.size)
        if c.size:
            p = p / p.sum()
        cols += c.tolist()
        vals += p.tolist()
        ptr.append(len(cols))
    m = sp.csr_array((np.asarray(vals, dtype=np.float64), np.asarray(cols, dtype=np.int32),
                      np.asarray(ptr, dtype=np.int32)), shape=(int(nature[-1]), n))
    x = (rng.choice(TIES, size=n) if rng.random() < 0.7 else rng.random(n)).astype(float)
    return C.Rows(m, groups, nature if robust else None), x, rng.random(n) < 0.2


def definition(st: C.Rows, rnd, x: np.ndarray, free: np.ndarray, upper: bool) -> np.ndarray:
    """The check a row at a time: a row passes when its rounded bound (``(sum + slack)
    * high`` above; ``(sum - slack) * low``, at least 0, below; the sum from 0 in the
    entries' order) or the extreme of ``x`` over its stored entries (none: it passes)
    is on the right side of the state's value; a choice when one of its rows does; a
    state (not free) fails when some choice does not pass."""
    m = st.matrix
    out = np.zeros(st.n_states, dtype=bool)
    for s in range(st.n_states):
        if free[s]:
            continue
        own = Fraction(float(x[s]))
        for c in range(int(st.groups[s]), int(st.groups[s + 1])):
            rows = range(c, c + 1) if st.nature is None else range(int(st.nature[c]),
                                                                  int(st.nature[c + 1]))
            passed = False
            for r in rows:
                lo, hi = int(m.indptr[r]), int(m.indptr[r + 1])
                acc = 0.0
                for e in range(lo, hi):
                    acc += float(m.data[e]) * float(x[m.indices[e]])
                k = int(rnd.count[r])
                reached = [Fraction(float(x[m.indices[e]])) for e in range(lo, hi)]
                if upper:
                    bound = Fraction((acc + float(rnd.slack_of[k])) * float(rnd.high_of[k]))
                    passed |= bound <= own or not reached or max(reached) <= own
                else:
                    bound = Fraction(max((acc - float(rnd.slack_of[k]))
                                         * float(rnd.low_of[k]), 0.0))
                    passed |= bound >= own or not reached or min(reached) >= own
            if not passed:
                out[s] = True
    return out


def _routes(st, rnd, x, free, upper, monkeypatch):
    """The verdicts by the state kernel, by the compiled row check and by NumPy."""
    monkeypatch.setattr(CC, "COMPILED_CHECK_MIN_ROWS", 0)
    monkeypatch.setattr(kernel_loader, "compiled_paid", lambda: True)
    states = CC.compiled_failing(st, rnd, x, free, upper=upper)
    with monkeypatch.context() as mp:
        mp.setattr(C, "compiled_failing", lambda *a, **k: None)
        rows = C._fails(st, rnd, x, free, upper)
        mp.setattr(kernel_loader, "compiled_paid", lambda: False)
        numpy = C._fails(st, rnd, x, free, upper)
    return states, rows, numpy


@pytest.mark.parametrize("upper", [True, False])
def test_state_verdicts_are_the_checks_on_both_sides(upper, monkeypatch) -> None:
    far = near = 0  # states at x's extremes that the kernel asks about, seen
    for seed in range(400):
        st, x, free = random_rows(seed)
        rnd = rounding(st.matrix)
        want = definition(st, rnd, x, free, upper)
        states, rows, numpy = _routes(st, rnd, x, free, upper, monkeypatch)
        assert states is not None
        np.testing.assert_array_equal(states, want, err_msg=f"seed {seed}")
        np.testing.assert_array_equal(rows, want, err_msg=f"seed {seed}")
        np.testing.assert_array_equal(numpy, want, err_msg=f"seed {seed}")
        # some states alone (:func:`certify._fails_among`): theirs, the others passing
        among = np.flatnonzero(np.arange(st.n_states) % 2 == 1)
        part = CC.compiled_failing(st, rnd, x, free, among, upper)
        only = np.zeros(st.n_states, dtype=bool)
        only[among] = want[among]
        np.testing.assert_array_equal(part, only, err_msg=f"seed {seed}")
        hi, lo = float(x.max()), float(x.min())
        asked = ~free
        near += int(np.sum(asked & (x == (hi if upper else lo))))
        far_at = asked & (x == (lo if upper else hi)) & (hi > lo)
        far += int(np.sum(far_at & want)) + int(np.sum(far_at & ~want))
    assert near > 50 and far > 50, (near, far)  # both shortcuts were met


def test_a_state_at_the_far_extreme_fails_where_a_successor_is_off_it(monkeypatch) -> None:
    """Worked by hand: four states, a choice each; state 0 to states 1 and 2 in
    halves, states 1 and 2 to state 1, state 3 to state 0; ``x = (1, 1, 0.5, 0)``.
    Below (``E(x) >= x[s]``): state 0 (at 1, x's largest) has the sum 0.75 and the
    least successor 0.5, both under 1: it fails; state 1 passes by the rule (its one
    successor at 1); state 2 by its sum (1, rounded down, at least 0.5); state 3 (at 0,
    x's least) passes unread.  Above (``E(x) <= x[s]``): states 0 and 1 (at 1) pass
    unread; state 2 (at 0.5) reads state 1 at 1 and state 3 (at 0) state 0 at 1: both
    fail, by the sum and by the rule."""
    m = sp.csr_array((np.array([0.5, 0.5, 1.0, 1.0, 1.0]),
                      np.array([1, 2, 1, 1, 0], dtype=np.int32),
                      np.array([0, 2, 3, 4, 5], dtype=np.int32)), shape=(4, 4))
    st = C.Rows(m, np.arange(5, dtype=np.int64))
    x = np.array([1.0, 1.0, 0.5, 0.0])
    rnd = rounding(m)
    free = np.zeros(4, dtype=bool)
    states, rows, numpy = _routes(st, rnd, x, free, False, monkeypatch)
    np.testing.assert_array_equal(states, [True, False, False, False])
    np.testing.assert_array_equal(rows, states)
    np.testing.assert_array_equal(numpy, states)
    states, rows, numpy = _routes(st, rnd, x, free, True, monkeypatch)
    np.testing.assert_array_equal(states, [False, False, True, True])
    np.testing.assert_array_equal(rows, states)
    np.testing.assert_array_equal(numpy, states)


@pytest.mark.parametrize("seed", range(8))
def test_brackets_hold_the_brute_force_optimum_with_state_verdicts(seed, monkeypatch) -> None:
    """``test_cert_small_exact``'s brute force, with the verdict kernel counted: it
    gives the verdicts of a minimum's check too now."""
    mdp, exact = small_model(seed, 5)
    target = np.asarray(mdp.target)
    asked = []
    real = CC.compiled_failing

    def spy(*a, **k):
        got = real(*a, **k)
        asked.append((k.get("upper", a[5] if len(a) > 5 else True), got is not None))
        return got

    monkeypatch.setattr(C, "compiled_failing", spy)
    for upper in (True, False):
        v, policy = exact_optimum(mdp, exact, 5, upper)
        sets = {"zero": np.array([p == 0 for p in v]),
                "one": None if upper else np.array([p == 1 for p in v])}
        bits = set()
        for compiled in (True, False):
            paid_kernels(monkeypatch, compiled)
            cert = C.certify(mdp, target, policy, sense="max" if upper else "min", **sets)
            held = Fraction(cert.lower) <= v[0] <= Fraction(cert.upper)
            assert held and cert.certified, (upper, v[0], [c.detail for c in cert.checks])
            bits.add((cert.lower.hex(), cert.upper.hex(), np.asarray(cert.values).tobytes()))
        assert len(bits) == 1  # the compiled paths' bits are NumPy's
    assert (False, True) in asked and (True, True) in asked  # both sides by the kernel


def lp_model(seed: int, n: int):
    """``n`` unknown states, the target ``n`` and the sink ``n + 1``; each state 1-3
    choices, some staying among the unknown states (self-loops and splits: end
    components), the others to a few states, the sink and the target."""
    rng = np.random.default_rng(1000 + seed)
    target, sink = n, n + 1
    rows = []
    for s in range(n):
        choices = []
        for _ in range(int(rng.integers(1, 4))):
            if rng.random() < 0.3:
                succ = [s] if rng.random() < 0.4 else [int(t) for t in rng.choice(
                    n, size=2, replace=False)]
                w = rng.uniform(0.1, 1.0, size=len(succ))
                choices.append(dict(zip(succ, (w / w.sum()).tolist(), strict=True)))
                continue
            succ = [int(t) for t in rng.choice(n, size=int(rng.integers(0, 3)),
                                               replace=False)] + [target, sink]
            w = rng.uniform(0.05, 1.0, size=len(succ))
            row: dict[int, float] = {}
            for t, p in zip(succ, (w / w.sum()).tolist(), strict=True):
                row[t] = row.get(t, 0.0) + p
            choices.append(row)
        rows.append(choices)
    rows += [[], []]
    return model_of_rows(rows, target, sink)[0]


def lp_optimum(mdp, upper: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The optimum by HiGHS: the states at 0 by the graph (no path to the target
    above; a policy that avoids it for ever below, the greatest set with a choice
    staying in it), the rest the least (above) or greatest (below) solution of the
    Bellman inequalities with the target at 1.  Returns the values, the zero set and a
    policy (each unknown state's choice best for the LP's values)."""
    m = sp.csr_array(mdp.matrix).toarray()
    groups = np.asarray(mdp.row_groups)
    n = mdp.n_states
    target = np.asarray(mdp.target, dtype=bool)
    owner = np.repeat(np.arange(n), np.diff(groups))
    if upper:
        reach = target.copy()
        while True:
            more = reach | np.bincount(owner, weights=(m[:, reach].sum(axis=1) > 0),
                                       minlength=n).astype(bool)
            if np.array_equal(more, reach):
                break
            reach = more
        zero = ~reach
    else:
        zero = ~target & (np.diff(groups) > 0)
        while True:
            stays = (m[:, ~zero].sum(axis=1) == 0)
            keep = zero & np.bincount(owner, weights=stays, minlength=n).astype(bool)
            if np.array_equal(keep, zero):
                break
            zero = keep
    fixed = target | zero | (np.diff(groups) == 0)
    a_ub, b_ub = [], []
    for c in range(m.shape[0]):
        s = owner[c]
        if fixed[s]:
            continue
        row = m[c].copy()
        row[s] -= 1.0  # P_c v - v_s <= 0 above, >= 0 below
        a_ub.append(row if upper else -row)
        b_ub.append(0.0)
    bounds = [(1.0, 1.0) if target[s] else (0.0, 0.0) if (zero[s] or fixed[s]) else
              (0.0, 1.0) for s in range(n)]
    got = linprog(np.ones(n) if upper else -np.ones(n), A_ub=np.array(a_ub),
                  b_ub=np.array(b_ub), bounds=bounds, method="highs")
    assert got.status == 0
    v = got.x
    policy = np.full(n, -1, dtype=np.int64)
    for s in np.flatnonzero(~fixed):
        vals = m[groups[s]:groups[s + 1]] @ v
        policy[s] = groups[s] + int(np.argmax(vals) if upper else np.argmin(vals))
    return v, zero, policy


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("upper", [True, False])
def test_brackets_hold_the_lp_optimum(seed, upper, monkeypatch) -> None:
    mdp = lp_model(seed, 30)
    v, zero, policy = lp_optimum(mdp, upper)
    target = np.asarray(mdp.target)
    got = []
    for compiled in (True, False):
        paid_kernels(monkeypatch, compiled)
        cert = C.certify(mdp, target, policy, sense="max" if upper else "min", zero=zero)
        # HiGHS solves to about 1e-9: the bracket holds its optimum within that
        assert cert.lower <= v[0] + 1e-9 and v[0] - 1e-9 <= cert.upper, (cert, v[0])
        assert 0.0 <= cert.lower <= cert.upper <= 1.0
        got.append((cert.lower.hex(), cert.upper.hex(), cert.certified))
    assert got[0] == got[1]
