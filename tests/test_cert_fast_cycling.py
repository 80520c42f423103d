"""cert-fast (2026-12-02): a minimum's end-component test read by one compiled call
(``certify_kernels.cycling`` through ``certify_compiled.compiled_cycling``, which
``certify_chain.cycling_among`` runs where the kernels' load is paid).

The set is checked against its definition computed here another way: the strongly
connected components of the support graph from its transitive closure (a boolean matrix
squared until it stops growing), a state's own choice read entry by entry in Python;
and against the analysis's ``may_cycle`` on the same model.  The brackets of a model
whose minimum's test runs compiled are held against the exact minimum by brute force in
rational arithmetic (every deterministic policy solved with fractions)."""

from __future__ import annotations

import itertools
from fractions import Fraction
from types import SimpleNamespace

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.solvers import certify as C
from mitld_lp.solvers import certify_chain, certify_compiled
from mitld_lp.solvers.analysis import may_cycle


def _paid(monkeypatch: pytest.MonkeyPatch, compiled: bool) -> None:
    """The certificate's compiled paths on or off, whatever this process loaded."""
    fake = SimpleNamespace(compiled_paid=lambda: compiled,
                           module_cached=lambda *a: False, prepare=lambda: None)
    monkeypatch.setattr(certify_compiled, "kernel_loader", fake)
    monkeypatch.setattr(certify_compiled, "COMPILED_CHECK_MIN_ROWS", 0)
    monkeypatch.setattr(certify_compiled, "CYCLING_MIN_STATES", 0)
    monkeypatch.setattr(certify_chain, "kernel_loader", fake)


def _random_model(seed: int, n: int = 40) -> tuple[sp.csr_array, np.ndarray]:
    """Choices of four kinds: every entry in the state's own column (one or two stored
    entries), the own column first and then another, an empty row, random successors."""
    rng = np.random.default_rng(seed)
    per = rng.integers(0, 4, size=n)
    groups = np.concatenate([[0], np.cumsum(per)]).astype(np.int64)
    data, cols, ptr = [], [], [0]
    for s in range(n):
        for _ in range(int(per[s])):
            kind = rng.random()
            if kind < 0.15:
                succ = [s] * int(rng.integers(1, 3))
            elif kind < 0.3:
                succ = [s, (s + 1 + int(rng.integers(0, n - 1))) % n]
            elif kind < 0.35:
                succ = []
            else:
                succ = sorted(rng.choice(n, size=int(rng.integers(1, 3)),
                                         replace=False).tolist())
            cols += succ
            data += [1.0 / max(len(succ), 1)] * len(succ)
            ptr.append(len(cols))
    m = sp.csr_array((np.array(data), np.array(cols, dtype=np.int32),
                      np.array(ptr, dtype=np.int32)), shape=(int(groups[-1]), n))
    return m, groups


def _by_definition(m: sp.csr_array, groups: np.ndarray, left: np.ndarray) -> np.ndarray:
    """A ``left`` state whose component (mutual reachability in the support graph, by
    the transitive closure) holds another state, or with a choice whose stored entries,
    at least one, are all its own column."""
    n = left.size
    step = np.zeros((n, n), dtype=bool)
    for s in range(n):
        for c in range(groups[s], groups[s + 1]):
            for e in range(m.indptr[c], m.indptr[c + 1]):
                step[s, m.indices[e]] = True
    reach = step | np.eye(n, dtype=bool)
    while True:
        more = (reach.astype(np.int64) @ reach.astype(np.int64)) > 0
        if np.array_equal(more, reach):
            break
        reach = more
    out = np.zeros(n, dtype=bool)
    for s in range(n):
        if not left[s]:
            continue
        shared = int(np.sum(reach[s] & reach[:, s]))
        loops = any(m.indptr[c + 1] > m.indptr[c] and all(
            int(m.indices[e]) == s for e in range(m.indptr[c], m.indptr[c + 1]))
            for c in range(groups[s], groups[s + 1]))
        out[s] = shared > 1 or loops
    return out


@pytest.mark.parametrize("seed", range(12))
def test_compiled_cycling_is_the_definition(seed, monkeypatch) -> None:
    m, groups = _random_model(seed)
    n = groups.size - 1
    left = np.random.default_rng(100 + seed).random(n) < 0.6
    comp = certify_chain.support_layers(SimpleNamespace(matrix=m, row_groups=groups))[0]
    want = _by_definition(m, groups, left)
    owner = np.repeat(np.arange(n), np.diff(groups))
    analysis = SimpleNamespace(matrix=m, state_of=lambda c: owner[c],
                               choice_state=lambda: owner)
    assert np.array_equal(want, left & may_cycle(analysis, comp))
    _paid(monkeypatch, True)
    for kind in (np.int32, np.int64):  # a product's components are int32
        got = certify_compiled.compiled_cycling(m, groups, comp.astype(kind), left)
        assert got is not None and np.array_equal(got, want)
    assert np.array_equal(certify_chain.cycling_among(m, groups, comp, left), want)
    _paid(monkeypatch, False)
    assert certify_compiled.compiled_cycling(m, groups, comp, left) is None
    assert np.array_equal(certify_chain.cycling_among(m, groups, comp, left), want)


def test_few_states_asked_stay_on_numpy(monkeypatch) -> None:
    m, groups = _random_model(1)
    comp = certify_chain.support_layers(SimpleNamespace(matrix=m, row_groups=groups))[0]
    left = np.ones(comp.size, dtype=bool)
    _paid(monkeypatch, True)
    assert certify_compiled.compiled_cycling(m, groups, comp, left) is not None
    monkeypatch.setattr(certify_compiled, "CYCLING_MIN_STATES", int(left.sum()) + 1)
    assert certify_compiled.compiled_cycling(m, groups, comp, left) is None


def test_a_component_number_out_of_range_is_left_to_numpy(monkeypatch) -> None:
    m, groups = _random_model(0)
    comp = np.zeros(groups.size - 1, dtype=np.int64)
    comp[3] = -1
    _paid(monkeypatch, True)
    assert certify_compiled.compiled_cycling(m, groups, comp,
                                             np.ones(comp.size, dtype=bool)) is None
    comp[3] = comp.size  # a component number no state count allows
    assert certify_compiled.compiled_cycling(m, groups, comp.astype(np.int32),
                                             np.ones(comp.size, dtype=bool)) is None


def _exact_min(rows: list[list[dict[int, Fraction]]], target: int) -> list[Fraction]:
    """Pmin of reaching ``target`` from each state: every deterministic policy's chain
    solved exactly (Gauss-Jordan on the states that reach the target, 0 elsewhere), the
    least state by state (a minimum has an optimal deterministic memoryless policy)."""
    n = len(rows)
    best = [Fraction(2)] * n
    for pick in itertools.product(*(range(len(r)) for r in rows)):
        succ = [rows[s][pick[s]] for s in range(n)]
        reach = {target}
        grown = True
        while grown:
            grown = False
            for s in range(n):
                if s not in reach and any(j in reach for j in succ[s]):
                    reach.add(s)
                    grown = True
        unknown = [s for s in range(n) if s in reach and s != target]
        at = {s: i for i, s in enumerate(unknown)}
        k = len(unknown)
        a = [[Fraction(int(i == j)) for j in range(k)] + [Fraction(0)] for i in range(k)]
        for s in unknown:
            for j, p in succ[s].items():
                if j == target:
                    a[at[s]][k] += p
                elif j in at:
                    a[at[s]][at[j]] -= p
        for col in range(k):
            piv = next(r for r in range(col, k) if a[r][col] != 0)
            a[col], a[piv] = a[piv], a[col]
            f = a[col][col]
            a[col] = [v / f for v in a[col]]
            for r in range(k):
                if r != col and a[r][col] != 0:
                    g = a[r][col]
                    a[r] = [v - g * w for v, w in zip(a[r], a[col], strict=True)]
        value = [Fraction(1) if s == target else Fraction(0) for s in range(n)]
        for s in unknown:
            value[s] = a[at[s]][k]
        best = [min(b, v) for b, v in zip(best, value, strict=True)]
    return best


@pytest.mark.parametrize("compiled", [True, False])
@pytest.mark.parametrize("seed", range(6))
def test_a_minimums_bracket_holds_the_exact_minimum(seed, compiled, monkeypatch) -> None:
    """A minimum whose states leave with rare probabilities: its lower bound's
    end-component test asks the compiled set where ``compiled``; the bracket holds the
    exact minimum either way, with the same bits."""
    rng = np.random.default_rng(seed)
    n, target, sink = 6, 6, 7
    rows: list[list[dict[int, Fraction]]] = []
    for s in range(n):
        choices = []
        for _ in range(int(rng.integers(1, 3))):
            rare = Fraction(int(rng.integers(1, 9)), 10**12)
            j = int(rng.integers(0, n))
            if rng.random() < 0.5:
                choices.append({target: rare, j: 1 - rare} if j != s else
                               {target: rare, sink: 1 - rare})
            else:
                half = Fraction(int(rng.integers(1, 4)), 4)
                choices.append({target: half, sink: 1 - half})
        rows.append(choices)
    rows += [[{target: Fraction(1)}], [{sink: Fraction(1)}]]
    want = _exact_min(rows, target)
    data, cols, ptr, groups = [], [], [0], [0]
    for choices in rows:
        for ch in choices:
            for j in sorted(ch):
                cols.append(j)
                data.append(float(ch[j]))
            ptr.append(len(cols))
        groups.append(len(ptr) - 1)
    m = sp.csr_array((np.array(data), np.array(cols, dtype=np.int32),
                      np.array(ptr, dtype=np.int32)), shape=(len(ptr) - 1, n + 2))
    groups_a = np.array(groups, dtype=np.int64)
    tgt = np.zeros(n + 2, dtype=bool)
    tgt[target] = True
    zero = np.array([want[s] == 0 for s in range(n)] + [False, True])
    one = np.array([want[s] == 1 for s in range(n)] + [True, False])
    # the minimising policy: at each state a choice whose exact value is the minimum
    policy = np.full(n + 2, -1, dtype=np.int64)
    for s in range(n):
        for i, ch in enumerate(rows[s]):
            if sum((p * want[j] for j, p in ch.items()), Fraction(0)) == want[s]:
                policy[s] = groups[s] + i
                break
    _paid(monkeypatch, compiled)
    got = []
    for initial in range(n):
        mdp = certify_chain.RowModel(m, groups_a, initial)
        cert = C.certify(mdp, tgt, policy, sense="min", zero=zero, one=one)
        assert Fraction(cert.lower) <= want[initial] <= Fraction(cert.upper)
        got.append((cert.lower.hex(), cert.upper.hex(), cert.certified))
    _paid(monkeypatch, not compiled)
    for initial in range(n):
        mdp = certify_chain.RowModel(m, groups_a, initial)
        cert = C.certify(mdp, tgt, policy, sense="min", zero=zero, one=one)
        assert (cert.lower.hex(), cert.upper.hex(), cert.certified) == got[initial]
