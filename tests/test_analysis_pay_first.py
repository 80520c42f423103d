"""fixed-82: the analysis pays the kernel loader's load at its start where the
certificate of the same product would pay it anyway
(:func:`mitld_lp.solvers.analysis_gates.pay_if_warm`), so that its walks run compiled.

* the gate's decision against the rule written here (paid already; a cold kernel of
  the analysis's; else the certificate's own rule, asked with the product's entries);
* ``analyse`` asks it once, with the product's stored entries, before any walk;
* the analysis with every walk compiled from the first (the load paid at the start)
  against every walk on NumPy (nothing paid): the same bytes in every array of both
  quotients, and the qualitative sets equal to fixed points written here in plain
  Python over lists of successor sets, on random MDPs with end components, both senses.
"""

from __future__ import annotations

import sys

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.solvers import analysis, analysis_gates, certify_compiled
from mitld_lp.solvers import walks as walks_module
from mitld_lp.solvers.analysis import analyse
from mitld_lp.solvers.graph import Sense
from mitld_lp.testing import random_mdp
from mitld_lp.util import kernel_loader

pytest.importorskip("numba")


@pytest.mark.parametrize("paid", [True, False])
@pytest.mark.parametrize("cold", [None, 0, 1, 2])
@pytest.mark.parametrize("certificate_pays", [True, False])
def test_the_gate_follows_the_rule(paid: bool, cold: int | None, certificate_pays: bool,
                                   monkeypatch: pytest.MonkeyPatch) -> None:
    asked: list[int] = []
    monkeypatch.setattr(kernel_loader, "compiled_paid", lambda: paid)
    monkeypatch.setattr(analysis_gates, "_WARM", {
        k: i != cold for i, k in enumerate(analysis_gates.ANALYSIS_KERNELS)})
    monkeypatch.setattr(certify_compiled, "load_if_warm",
                        lambda entries: asked.append(entries) or certificate_pays)
    got = analysis_gates.pay_if_warm(223_456)
    if paid:
        assert got and not asked
    elif cold is not None:
        assert not got and not asked  # a cold kernel: nothing paid, nothing asked
    else:
        assert got is certificate_pays and asked == [223_456]


@pytest.mark.parametrize("entries", [0, 1_000, 149_999])
def test_a_small_product_asks_nothing(entries: int, monkeypatch: pytest.MonkeyPatch) -> None:
    # below the certificate's 150,000 entries nothing is paid, and no kernel's warmth is
    # looked up (that reads and hashes cache files: the bundled case must not import
    # hashlib for it)
    looked: list[str] = []
    monkeypatch.setattr(kernel_loader, "compiled_paid", lambda: False)
    monkeypatch.setattr(analysis_gates, "warm", lambda k: looked.append(k) or True)
    monkeypatch.setattr(certify_compiled, "load_if_warm", lambda n: pytest.fail("asked"))
    assert analysis_gates.pay_if_warm(entries) is False
    assert looked == []


def test_the_analysis_kernels_include_the_attractor_and_the_levels() -> None:
    assert analysis_gates.ATTRACTOR in analysis_gates.ANALYSIS_KERNELS
    assert analysis_gates.LEVELS in analysis_gates.ANALYSIS_KERNELS


def _mdp(seed: int, n: int):
    return random_mdp(n, seed=seed, max_choices=3, max_successors=3, target_fraction=0.06,
                      sink_fraction=0.04, self_loop_fraction=0.2,
                      locality=None if seed % 2 else 5)


def test_analyse_asks_the_gate_first_with_the_products_entries(
        monkeypatch: pytest.MonkeyPatch) -> None:
    mdp = _mdp(3, 120)
    order: list[object] = []
    monkeypatch.setattr(analysis, "pay_if_warm", lambda entries: order.append(entries))
    inner = analysis.components_reaching
    monkeypatch.setattr(analysis, "components_reaching",
                        lambda *a, **k: order.append("walk") or inner(*a, **k))
    analyse(mdp, np.asarray(mdp.target))
    assert order[0] == sp.csr_array(mdp.matrix).nnz and order.count(order[0]) == 1
    assert "walk" in order[1:]


def _successors(mdp) -> list[list[set[int]]]:
    m = sp.csr_array(mdp.matrix)
    g = np.asarray(mdp.row_groups)
    return [[{int(m.indices[k]) for k in range(m.indptr[c], m.indptr[c + 1])
              if m.data[k] > 0} for c in range(g[s], g[s + 1])]
            for s in range(mdp.n_states)]


def _fixed_sets(mdp, goal: set[int], sense: Sense) -> tuple[set[int], set[int]]:
    """(prob0, one): a maximum's Prob0A and Prob1E, a minimum's Prob0E and Prob1A, by
    iterating each defining equation over all states until it stops changing."""
    succ = _successors(mdp)
    every = set(range(len(succ)))

    def some_path(into: set[int], inside: set[int]) -> set[int]:
        got = set(into)
        changed = True
        while changed:
            changed = False
            for s in inside - got:
                if any(c & got for c in succ[s]):
                    got.add(s)
                    changed = True
        return got

    if sense is Sense.MAX:
        prob0 = every - some_path(goal, every)
        y = every
        while True:  # greatest Y: a choice staying in Y that reaches the goal within Y
            x = set(goal)
            changed = True
            while changed:
                changed = False
                for s in y - x:
                    if any(c and c <= y and c & x for c in succ[s]):
                        x.add(s)
                        changed = True
            if x == y:
                return prob0, y
            y = x
    forced = set(goal)  # every choice hits the set: the complement is Prob0E
    changed = True
    while changed:
        changed = False
        for s in every - forced:
            if succ[s] and all(c & forced for c in succ[s]):
                forced.add(s)
                changed = True
    prob0 = every - forced
    return prob0, every - some_path(prob0, every - goal)


def _quotient_bytes(q) -> list[tuple[str, bytes]]:
    out = []
    for name in ("prob0", "state_map"):
        if hasattr(q, name):
            x = np.asarray(getattr(q, name))
            out.append((name + x.dtype.str, x.tobytes()))
    m = sp.csr_array(q.matrix) if hasattr(q, "matrix") else None
    if m is not None:
        out += [(k, np.asarray(getattr(m, k)).tobytes()) for k in ("data", "indices",
                                                                   "indptr")]
    out += [("mecs." + k, np.asarray(getattr(q.mecs, k)).tobytes())
            for k in ("mec_of", "internal")]
    one = np.asarray(q.qualitative.one)
    out.append(("one", one.tobytes()))
    return out


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize("seed", range(8))
def test_walks_compiled_from_the_start_give_the_numpy_analysis(
        seed: int, sense: Sense, monkeypatch: pytest.MonkeyPatch) -> None:
    mdp = _mdp(200 + seed, 160)
    goal = np.asarray(mdp.target)
    want0, want1 = _fixed_sets(mdp, set(np.flatnonzero(goal).tolist()), sense)
    got = {}
    for paid in (True, False):
        with monkeypatch.context() as mp:
            mp.setattr(analysis, "pay_if_warm", lambda entries, p=paid: p)
            mp.setattr(kernel_loader, "compiled_paid", lambda p=paid: p)
            # paid: every walk compiled whatever its size; else every walk on NumPy
            for name in ("COMPILED_MIN_ENTRIES", "COMPILED_LOADED_MIN_ENTRIES"):
                mp.setattr(walks_module, name, 0 if paid else sys.maxsize)
            for name in ("WARM_MIN_ENTRIES", "PAID_MIN_ENTRIES"):
                mp.setattr(analysis_gates, name, 0 if paid else sys.maxsize)
            mp.setattr(analysis_gates, "DENSE_ENTRIES", 0 if paid else sys.maxsize)
            q, _ = analyse(mdp, goal, sense=sense)
        assert set(np.flatnonzero(q.prob0).tolist()) == want0, paid
        assert set(np.flatnonzero(q.qualitative.one).tolist()) == want1, paid
        got[paid] = _quotient_bytes(q)
    assert got[True] == got[False]
