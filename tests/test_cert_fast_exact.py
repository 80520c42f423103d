"""cert-fast: the certificate's compiled Bellman check (``certify_kernels.bellman_rows``
through ``certify_compiled.compiled_checks``), its chain's single levels compiled where a
kernel's load is paid, and the repair's pass-by-pass test read without its walk.

Every bracket is held against exact values computed here in rational arithmetic
(``Fraction``): value iteration to its fixed point on acyclic MDPs (exact after as many
steps as the longest path), and on cyclic ones policy iteration solved by Gauss-Jordan
elimination and then confirmed an exact fixed point by one more exact Bellman step (no
end component is left among the unknown states, so the fixed point is unique).  Rare
probabilities go down to 1e-30, both senses.  A candidate nudged one unit in the last
place past the exact value is refused, by the compiled check and by NumPy's."""

from __future__ import annotations

import math
from fractions import Fraction
from types import SimpleNamespace

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.mdp import ABSORB, MDP
from mitld_lp.solvers import certify as C
from mitld_lp.solvers import certify_blocks, certify_chain, certify_compiled, certify_repair
from mitld_lp.solvers.rounding import float_down, float_up, rounding

RARE = (1e-30, 1e-22, 1e-15, 3e-9)


def _model(seed: int, n: int, cyclic: bool) -> tuple[MDP, list[dict[int, Fraction]]]:
    """``n`` unknown states, then the target ``n`` and the sink ``n + 1``.  Each choice
    reaches the sink with probability at least 0.05 (no end component among the
    unknown states), the target often with a rare probability, and other unknown
    states: later ones only (acyclic) or any, itself included (cyclic)."""
    rng = np.random.default_rng(seed)
    target, sink = n, n + 1
    rows: list[list[dict[int, float]]] = []
    for s in range(n):
        choices = []
        for _ in range(int(rng.integers(1, 4))):
            pool = list(range(s + 1, n)) if not cyclic else list(range(n))
            succ = [int(t) for t in rng.choice(pool, size=min(len(pool), int(
                rng.integers(0, 3))), replace=False)] if pool else []
            w = {t: float(rng.uniform(0.2, 1.0)) for t in succ}
            w[sink] = float(rng.uniform(0.05, 0.6))
            tail = float(rng.choice(RARE)) if rng.random() < 0.6 else float(
                rng.uniform(0.05, 0.5))
            total = sum(w.values())
            row = {t: (1.0 - tail) * p / total for t, p in w.items()}
            row[target] = tail
            choices.append(row)
        rows.append(choices)
    rows += [[], []]
    return model_of_rows(rows, target, sink)


def model_of_rows(rows: list[list[dict[int, float]]], target: int, sink: int
           ) -> tuple[MDP, list[dict[int, Fraction]]]:
    """The MDP of ``rows`` (absorbing states one self-loop) and its exact model: each
    stored row in rational arithmetic divided by its exact sum (within a few units of
    roundoff of the floats: inside the certificate's allowance)."""
    n = len(rows)
    stored, groups, acts = [], [0], []
    for s, choices in enumerate(rows):
        for c in choices or [{s: 1.0}]:
            stored.append(c)
            acts.append(ABSORB if not choices else len(acts) % 2)
        groups.append(len(stored))
    data, cols, ptr = [], [], [0]
    for row in stored:
        for t in sorted(row):
            cols.append(t)
            data.append(row[t])
        ptr.append(len(cols))
    matrix = sp.csr_array((np.array(data), np.array(cols), np.array(ptr)),
                          shape=(len(stored), n))
    exact = []
    for r in range(matrix.shape[0]):
        a, z = matrix.indptr[r], matrix.indptr[r + 1]
        row = {int(t): Fraction(float(p)) for t, p in zip(matrix.indices[a:z],
                                                         matrix.data[a:z], strict=True)}
        total = sum(row.values())
        exact.append({t: p / total for t, p in row.items()})
    tgt = np.zeros(n, dtype=bool)
    tgt[target] = True
    snk = np.zeros(n, dtype=bool)
    snk[sink] = True
    mdp = MDP(matrix=matrix, row_groups=np.array(groups, dtype=np.int64),
              choice_actions=np.array(acts, dtype=np.int32), action_names=("a0", "a1"),
              initial=0, target=tgt, sink=snk, truncated=np.zeros(n, dtype=bool),
              states=list(range(n)))
    return mdp, exact


def _step(mdp: MDP, exact: list[dict[int, Fraction]], v: list[Fraction], upper: bool
          ) -> tuple[list[Fraction], list[int]]:
    """One exact Bellman step (the target stays 1, the sink 0) and its greedy rows."""
    groups = np.asarray(mdp.row_groups)
    target, sink = np.asarray(mdp.target), np.asarray(mdp.sink)
    out, best = [], []
    pick = max if upper else min
    for s in range(mdp.n_states):
        if target[s] or sink[s]:
            out.append(Fraction(int(target[s])))
            best.append(-1)
            continue
        vals = {r: sum(p * v[t] for t, p in exact[r].items())
                for r in range(groups[s], groups[s + 1])}
        r = pick(vals, key=lambda k: (vals[k], -k))
        out.append(vals[r])
        best.append(r)
    return out, best


def _solve_policy(mdp: MDP, exact: list[dict[int, Fraction]], policy: list[int]
                  ) -> list[Fraction]:
    """The policy's exact values: ``v = P v`` with the target 1 and the sink 0, by
    Gauss-Jordan elimination in fractions (every state transient but the absorbing)."""
    n = mdp.n_states
    target, sink = np.asarray(mdp.target), np.asarray(mdp.sink)
    a = [[Fraction(int(i == j)) for j in range(n)] + [Fraction(int(target[i]))]
         for i in range(n)]
    for s in range(n):
        if target[s] or sink[s]:
            continue
        for t, p in exact[policy[s]].items():
            a[s][t] -= p
    for c in range(n):
        piv = next(r for r in range(c, n) if a[r][c] != 0)
        a[c], a[piv] = a[piv], a[c]
        f = a[c][c]
        a[c] = [x / f for x in a[c]]
        for r in range(n):
            if r != c and a[r][c] != 0:
                g = a[r][c]
                a[r] = [x - g * y for x, y in zip(a[r], a[c], strict=True)]
    return [a[s][n] for s in range(n)]


def exact_optimum(mdp: MDP, exact: list[dict[int, Fraction]], upper: bool,
                  cyclic: bool) -> tuple[list[Fraction], list[int]]:
    """The exact optimum (``upper``: the maximum) and an optimal policy's rows."""
    n = mdp.n_states
    if not cyclic:  # value iteration from 0: exact after n steps on a DAG
        v = [Fraction(int(t)) for t in np.asarray(mdp.target)]
        for _ in range(n + 1):
            v, best = _step(mdp, exact, v, upper)
        again, _ = _step(mdp, exact, v, upper)
        assert again == v  # a fixed point, exactly
        return v, best
    _, best = _step(mdp, exact, [Fraction(0)] * n, upper)
    for _ in range(4 * n + 8):  # policy iteration, exact
        v = _solve_policy(mdp, exact, best)
        again, greedy = _step(mdp, exact, v, upper)
        if again == v:  # a fixed point of the Bellman operator: the optimum
            return v, best
        best = [g if (again[s] != v[s]) else b for s, (g, b) in
                enumerate(zip(greedy, best, strict=True))]
    raise AssertionError("policy iteration did not settle")


CASES = [(seed, cyclic) for seed in range(6) for cyclic in (False, True)]


def _paid(monkeypatch: pytest.MonkeyPatch, compiled: bool) -> None:
    """The compiled check (and the chain's compiled single levels) on or off,
    whatever this process loaded before."""
    fake = SimpleNamespace(compiled_paid=lambda: compiled, module_cached=lambda *a: compiled)
    monkeypatch.setattr(certify_compiled, "kernel_loader", fake)
    monkeypatch.setattr(certify_compiled, "COMPILED_CHECK_MIN_ROWS", 0)
    monkeypatch.setattr(certify_chain, "kernel_loader", fake)
    monkeypatch.setattr(certify_chain, "CHAIN_KERNEL_MIN_LEVELS", 0)
    # the chain's blocks' cache look-up (kept once a process), asked afresh of the fake
    monkeypatch.setattr(certify_blocks, "_BLOCKS_WARM", [])


@pytest.mark.parametrize("compiled", [True, False])
@pytest.mark.parametrize(("seed", "cyclic"), CASES)
def test_brackets_hold_the_exact_optimum_both_senses(seed, cyclic, compiled,
                                                     monkeypatch) -> None:
    _paid(monkeypatch, compiled)
    mdp, exact = _model(seed, 7, cyclic)
    target = np.asarray(mdp.target)
    for upper in (True, False):
        v, best = exact_optimum(mdp, exact, upper, cyclic)
        policy = np.array(best, dtype=np.int64)
        zero = np.array([p == 0 for p in v])
        sense = "max" if upper else "min"
        cert = C.certify(mdp, target, policy, sense=sense, zero=zero,
                         one=None if upper else np.array([p == 1 for p in v]))
        assert Fraction(cert.lower) <= v[0] <= Fraction(cert.upper), (sense, v[0])
        assert cert.certified, [c.detail for c in cert.checks]
        # tight: within the certificate's relative precision of the exact value
        assert Fraction(cert.upper) - Fraction(cert.lower) <= v[0] * Fraction(1, 10**6)


@pytest.mark.parametrize("compiled", [True, False])
@pytest.mark.parametrize(("seed", "cyclic"), CASES)
def test_a_candidate_one_ulp_past_the_exact_optimum_is_refused(seed, cyclic, compiled,
                                                               monkeypatch) -> None:
    _paid(monkeypatch, compiled)
    mdp, exact = _model(seed, 7, cyclic)
    target = np.asarray(mdp.target)
    rnd = rounding(sp.csr_array(mdp.matrix))
    st = C.Rows(sp.csr_array(mdp.matrix), np.asarray(mdp.row_groups, dtype=np.int64))
    layers = C.support_layers(mdp)
    for upper in (True, False):
        v, best = exact_optimum(mdp, exact, upper, cyclic)
        zero = np.array([p == 0 for p in v])
        ch = C.chain(mdp, target, np.array(best, dtype=np.int64), rnd, layers)
        side = (C.optimum_upper(mdp, ch, rnd, zero=zero, layers=layers) if upper else
                C.optimum_lower(mdp, ch, rnd, zero=zero, layers=layers))
        assert side.check.passed
        free = target.copy() if upper else target | zero
        good = np.array(side.vector)
        assert not C._fails(st, rnd, good, free, upper).any()  # the checked vector
        for s in np.flatnonzero(~free & ~np.asarray(mdp.sink)):
            if v[s] == 0:
                continue
            bad = good.copy()
            # one unit in the last place past the exact value: below it for an upper
            # bound, above it for a lower one; accepting it would prove a false bound
            bad[s] = (math.nextafter(float_down(v[s]), -math.inf) if upper else
                      math.nextafter(float_up(v[s]), math.inf))
            assert C._fails(st, rnd, bad, free, upper).any(), (s, upper)
            among = np.zeros(mdp.n_states, dtype=bool)
            among[s] = True
            assert C._fails_among(st, rnd, bad, free, upper, among)[s], (s, upper)


def _rows_of(seed: int, nature: bool) -> tuple[C.Rows, np.ndarray]:
    """A random matrix of choices (some a robust game's: several of nature's rows),
    stored zeros and an empty row among them, and each row's state."""
    rng = np.random.default_rng(seed)
    n = 40
    per_state = rng.integers(1, 4, size=n)
    groups = np.concatenate([[0], np.cumsum(per_state)]).astype(np.int64)
    n_choices = int(groups[-1])
    per_choice = rng.integers(1, 3, size=n_choices) if nature else np.ones(
        n_choices, dtype=np.int64)
    nat = np.concatenate([[0], np.cumsum(per_choice)]).astype(np.int64)
    n_rows = int(nat[-1])
    data, cols, ptr = [], [], [0]
    for r in range(n_rows):
        k = int(rng.integers(0, 5)) if r != 3 else 0
        succ = rng.choice(n, size=k, replace=False)
        p = rng.dirichlet(np.ones(k)) if k else np.zeros(0)
        p[rng.random(k) < 0.1] = 0.0  # stored zeros
        cols += succ.tolist()
        data += p.tolist()
        ptr.append(len(cols))
    m = sp.csr_array((np.array(data), np.array(cols, dtype=np.int32),
                      np.array(ptr, dtype=np.int32)), shape=(n_rows, n))
    return C.Rows(m, groups, nat if nature else None), rng.random(n)


@pytest.mark.parametrize("nature", [False, True])
@pytest.mark.parametrize("seed", range(8))
def test_compiled_check_gives_numpys_verdict_on_every_row(seed, nature,
                                                          monkeypatch) -> None:
    st, x = _rows_of(seed, nature)
    rng = np.random.default_rng(100 + seed)
    x[rng.random(x.size) < 0.2] = x.max()  # at the extremes: NumPy's shortcuts
    x[rng.random(x.size) < 0.2] = x.min()
    free = rng.random(x.size) < 0.1
    rnd = rounding(st.matrix)
    for upper in (True, False):
        for y in (x, x * (1 + 1e-13), np.where(rng.random(x.size) < 0.5, 0.0, x)):
            want = C.numpy_checks(st, rnd, y, free, upper)
            _paid(monkeypatch, True)
            got = certify_compiled.compiled_checks(st, rnd, y, free, upper)
            assert got is not None and np.array_equal(got, want)
            states = np.flatnonzero(rng.random(x.size) < 0.5)
            part = certify_compiled.compiled_checks(st, rnd, y, free, upper, states)
            rows, _, _ = st.rows_of(states)
            assert np.array_equal(part, want[rows])
            _paid(monkeypatch, False)
            assert certify_compiled.compiled_checks(st, rnd, y, free, upper) is None


@pytest.mark.parametrize("seed", range(6))
def test_downward_without_the_walk_is_the_walks(seed) -> None:
    st, _ = _rows_of(seed, nature=seed % 2 == 1)
    rng = np.random.default_rng(seed)
    for _ in range(5):
        level_of = rng.integers(0, 6, size=st.n_states)
        live = np.sort(rng.choice(st.n_states, size=25, replace=False))
        lv = level_of[live]
        order = np.argsort(lv, kind="stable")
        live, lv = live[order], lv[order]
        walk = certify_repair._Walk(st, live, lv)
        assert certify_repair._downward(st, live, lv, level_of) == walk.downward
    # a chain of levels read only downward: 0 <- 1 <- 2 ... (each row reads lower ones)
    n = 12
    m = sp.csr_array((np.ones(n - 1), np.arange(n - 1), np.concatenate([[0], np.arange(
        n)])), shape=(n, n))
    chain_rows = C.Rows(m, np.arange(n + 1, dtype=np.int64))
    live = np.arange(n)
    assert certify_repair._downward(chain_rows, live, live, live)
    assert not certify_repair._downward(chain_rows, live, np.zeros(n, dtype=np.int64),
                                        np.zeros(n, dtype=np.int64))


@pytest.mark.parametrize("nature", [False, True])
@pytest.mark.parametrize("seed", range(8))
def test_compiled_needs_are_numpys_to_the_bit(seed, nature, monkeypatch) -> None:
    st, x = _rows_of(seed, nature)
    rng = np.random.default_rng(200 + seed)
    rnd = rounding(st.matrix)
    states = np.flatnonzero(rng.random(x.size) < 0.6)
    for upper in (True, False):
        _paid(monkeypatch, False)
        want = certify_repair._needed(st, rnd, x, states, upper)
        _paid(monkeypatch, True)
        got = certify_compiled.compiled_needs(st, rnd, x, states, upper)
        assert got is not None
        assert np.array_equal(got.view(np.int64), want.view(np.int64))  # the bits
        assert np.array_equal(certify_repair._needed(st, rnd, x, states, upper).view(
            np.int64), want.view(np.int64))


@pytest.mark.parametrize("nature", [False, True])
@pytest.mark.parametrize("seed", range(4))
def test_readers_by_column_lists_each_entrys_state_in_row_order(seed, nature) -> None:
    st, _ = _rows_of(seed, nature)
    col_ptr, col_state = certify_repair.readers_by_column(st)
    m = st.matrix
    row_state = st.row_state()
    for j in range(st.n_states):  # brute force: every row holding column j, in order
        want = [int(row_state[r]) for r in range(m.shape[0])
                for c in m.indices[m.indptr[r]:m.indptr[r + 1]] if c == j]
        assert col_state[col_ptr[j]:col_ptr[j + 1]].tolist() == want


@pytest.mark.parametrize("seed", range(6))
def test_reversed_from_state_pointers_reaches_what_a_plain_search_does(seed) -> None:
    from mitld_lp.solvers.reach import Reversed

    rng = np.random.default_rng(300 + seed)
    n = 30
    counts = rng.integers(0, 4, size=n)
    succ = rng.integers(0, n, size=int(counts.sum()))
    starts = np.concatenate([[0], np.cumsum(counts)])
    edges = Reversed(n, None, succ, starts=starts)
    for _ in range(4):
        seeds = rng.random(n) < 0.15
        reach = seeds.copy()  # brute force: grow the set until no edge adds a state
        grew = True
        while grew:
            grew = False
            for s in range(n):
                if not reach[s] and reach[succ[starts[s]:starts[s + 1]]].any():
                    reach[s] = grew = True
        assert np.array_equal(edges.reaching(seeds), reach)
