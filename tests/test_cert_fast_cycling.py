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

from fractions import Fraction
from types import SimpleNamespace

import numpy as np
import pytest
import scipy.sparse as sp
from test_cert_fast_exact import model_of_rows
from test_cert_small_exact import exact_optimum

from mitld_lp.solvers import certify as C
from mitld_lp.solvers import certify_blocks, certify_chain, certify_compiled
from mitld_lp.solvers.analysis import may_cycle


def _paid(monkeypatch: pytest.MonkeyPatch, compiled: bool) -> None:
    """The certificate's compiled paths on or off, whatever this process loaded."""
    fake = SimpleNamespace(compiled_paid=lambda: compiled,
                           module_cached=lambda *a: False, prepare=lambda: None)
    monkeypatch.setattr(certify_compiled, "kernel_loader", fake)
    monkeypatch.setattr(certify_compiled, "COMPILED_CHECK_MIN_ROWS", 0)
    monkeypatch.setattr(certify_compiled, "CYCLING_MIN_STATES", 0)
    monkeypatch.setattr(certify_chain, "kernel_loader", fake)
    monkeypatch.setattr(certify_blocks, "_BLOCKS_WARM", [])  # asked afresh of the fake


def _random_model(seed: int, n: int = 40) -> tuple[sp.csr_array, np.ndarray]:
    """Choices of four kinds: every entry in the state's own column (one or two stored
    entries), the own column first and then another, an empty row, random successors."""
    rng = np.random.default_rng(seed)

    def successors(s: int) -> list[int]:
        kind = rng.random()
        if kind < 0.15:
            return [s] * int(rng.integers(1, 3))
        if kind < 0.3:
            return [s, (s + 1 + int(rng.integers(0, n - 1))) % n]
        if kind < 0.35:
            return []
        return sorted(rng.choice(n, size=int(rng.integers(1, 3)), replace=False).tolist())

    rows = [[successors(s) for _ in range(int(rng.integers(0, 4)))] for s in range(n)]
    groups = np.cumsum([0] + [len(r) for r in rows]).astype(np.int64)
    flat = [succ for r in rows for succ in r]
    m = sp.csr_array((np.concatenate([[1.0 / max(len(f), 1)] * len(f) for f in flat] + [[]]),
                      np.array([c for f in flat for c in f], dtype=np.int32),
                      np.cumsum([0] + [len(f) for f in flat]).astype(np.int32)),
                     shape=(len(flat), n))
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


@pytest.mark.parametrize("seed", range(8))
def test_a_minimums_bracket_holds_the_exact_minimum(seed, monkeypatch) -> None:
    """Minima whose states stay put or leave with rare probabilities (end components
    among the states asked about): the lower bound's end-component test asks the
    compiled set, then the NumPy one; the bracket holds the exact minimum (every
    deterministic policy solved in fractions) either way, with the same bits."""
    rng = np.random.default_rng(seed)
    n, target, sink = 6, 6, 7
    rows: list[list[dict[int, float]]] = []
    for s in range(n):
        choices = []
        for _ in range(int(rng.integers(1, 3))):
            kind = rng.random()
            if kind < 0.3:  # stays put
                choices.append({s: 1.0})
            elif kind < 0.7:  # a rare escape to the target, else a random state
                rare = float(rng.integers(1, 9)) * 1e-12
                j = int(rng.integers(0, n))
                choices.append({target: rare, (j if j != s else sink): 1.0 - rare})
            else:
                half = float(rng.integers(1, 4)) / 4
                choices.append({target: half, sink: 1.0 - half})
        rows.append(choices)
    rows += [[], []]
    mdp, exact = model_of_rows(rows, target, sink)
    want, policy = exact_optimum(mdp, exact, n, False)
    zero = np.array([p == 0 for p in want])
    one = np.array([p == 1 for p in want])
    got = []
    for compiled in (True, False):
        _paid(monkeypatch, compiled)
        cert = C.certify(mdp, np.asarray(mdp.target), policy, sense="min", zero=zero,
                         one=one)
        assert Fraction(cert.lower) <= want[int(mdp.initial)] <= Fraction(cert.upper)
        assert cert.certified, [c.detail for c in cert.checks]
        got.append((cert.lower.hex(), cert.upper.hex(), np.asarray(cert.values).tobytes()))
    assert got[0] == got[1]
