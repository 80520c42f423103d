"""analysis-gates: the analysis's attractors run compiled on a warm cache from 100,000
entries (:mod:`mitld_lp.solvers.analysis_gates`), the components staying on SciPy's walk.

* the compiled attractor (and its spared choices) and the analysis's sets with the
  attractor compiled against fixed points written here in plain Python over dicts of
  successor sets, on random MDPs with end components, both senses;
* every array of both quotients the same with the gate forced on and off (and the
  compiled kernel called only when on);
* the gate's decision against the rule written here, and its refusals: the loader off,
  a cold cache, numba missing (in this process, and the loader switched off in a fresh
  one).
"""

from __future__ import annotations

import os
import subprocess
import sys
from dataclasses import fields, is_dataclass
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

import mitld_lp.solvers
from mitld_lp.mdp import MDP
from mitld_lp.solvers import analysis_gates, graph
from mitld_lp.solvers import walks as walks_module
from mitld_lp.solvers.analysis import analyse
from mitld_lp.solvers.graph import Sense
from mitld_lp.testing import random_mdp
from mitld_lp.util import kernel_loader

numba = pytest.importorskip("numba")
from mitld_lp.solvers import compiled_graph  # noqa: E402  (needs numba)


@pytest.fixture
def gate(monkeypatch: pytest.MonkeyPatch):
    """``gate(True)``: the attractors and the quotient's levels compiled whatever their
    size, every other walk on NumPy (the mix of a mid-sized product: ``compiled_walks``
    says no); ``gate(False)``: all on NumPy.  Returns the list of the compiled
    attractor's and levels' kernel calls (their names)."""
    calls: list[str] = []

    def counted(name: str):
        inner = getattr(compiled_graph, name)

        def call(*args, **kwargs):
            calls.append(name)
            return inner(*args, **kwargs)
        return call

    for name in ("backward", "state_levels"):
        monkeypatch.setattr(compiled_graph, name, counted(name))
    monkeypatch.setattr(walks_module, "COMPILED_MIN_ENTRIES", sys.maxsize)
    monkeypatch.setattr(walks_module, "COMPILED_LOADED_MIN_ENTRIES", sys.maxsize)

    def use(on: bool) -> list[str]:
        calls.clear()
        for name in ("WARM_MIN_ENTRIES", "PAID_MIN_ENTRIES", "LEVELS_MIN_ENTRIES"):
            monkeypatch.setattr(analysis_gates, name, 0 if on else sys.maxsize)
        monkeypatch.setattr(analysis_gates, "_WARM", {analysis_gates.ATTRACTOR: on,
                                                      analysis_gates.LEVELS: on})
        return calls
    return use


def successors(mdp: MDP) -> dict[int, list[set[int]]]:
    """Each state's choices as sets of successors of positive probability."""
    m = sp.csr_array(mdp.matrix)
    g = np.asarray(mdp.row_groups)
    out: dict[int, list[set[int]]] = {}
    for s in range(mdp.n_states):
        out[s] = [{int(t) for t, p in zip(m.indices[m.indptr[c]:m.indptr[c + 1]],
                                          m.data[m.indptr[c]:m.indptr[c + 1]], strict=True)
                   if p > 0} for c in range(int(g[s]), int(g[s + 1]))]
    return out


def plain_attractor(succ: dict[int, list[set[int]]], seeds: set[int]) -> set[int]:
    """The least set holding ``seeds`` and every state with a choice all of whose
    choices have a successor in it (a round at a time, until nothing joins)."""
    inside = set(seeds)
    while True:
        joined = {s for s, cs in succ.items() if s not in inside and cs
                  and all(c & inside for c in cs)}
        if not joined:
            return inside
        inside |= joined


def plain_reach(succ: dict[int, list[set[int]]], seeds: set[int], through: set[int],
                ) -> set[int]:
    """The states of ``through`` with a path inside ``through`` to a seed, and the
    seeds."""
    inside = set(seeds)
    while True:
        joined = {s for s in through - inside if any(c & inside for c in succ[s])}
        if not joined:
            return inside
        inside |= joined


def plain_sets(mdp: MDP, goal: set[int], sense: Sense) -> tuple[set[int], set[int]]:
    """``(prob0, one)`` of reaching ``goal``: a maximum's ``Prob0A`` and ``Prob1E``, a
    minimum's ``Prob0E`` and ``Prob1A``, as the graph decides them."""
    succ = successors(mdp)
    states = set(succ)
    if sense is Sense.MAX:
        prob0 = states - plain_reach(succ, goal, states)
        y = set(states)
        while True:  # nu Y. mu X. goal | {s: a choice inside Y hitting X}
            x = set(goal)
            while True:
                more = {s for s in y - x if any(c and c <= y and c & x for c in succ[s])}
                if not more:
                    break
                x |= more
            if x == y:
                return prob0, y
            y = x
    prob0 = states - plain_attractor(succ, goal)  # Prob0E: some policy avoids the goal
    bad = plain_reach(succ, prob0, states - goal)  # a path outside the goal into Prob0E
    return prob0, states - bad


def _mdp(seed: int, n: int) -> MDP:
    return random_mdp(n, seed=seed, max_choices=3, max_successors=3, target_fraction=0.06,
                      sink_fraction=0.04, self_loop_fraction=0.15,
                      locality=None if seed % 2 else 6)


CASES = [(seed, n) for seed in range(8) for n in (30, 150)]


@pytest.mark.parametrize(("seed", "n"), CASES)
def test_the_compiled_attractor_is_the_plain_fixed_point(seed: int, n: int, gate) -> None:
    mdp = _mdp(seed, n)
    m = sp.csr_array(mdp.matrix)
    rng = np.random.default_rng(seed)
    seeds = rng.random(n) < 0.1
    hit0 = rng.random(mdp.n_choices) < 0.05
    calls = gate(True)
    inside, hit = graph.attractor_spared(m, mdp.row_groups, seeds, hit0)
    assert calls
    succ = successors(mdp)
    # the choices given as hit count as hitting the set: a choice of them is "into" it
    marked = {s: [c | ({-1} if hit0[int(mdp.row_groups[s]) + i] else set())
                  for i, c in enumerate(cs)] for s, cs in succ.items()}
    expect = plain_attractor(marked, set(np.flatnonzero(seeds).tolist()) | {-1}) - {-1}
    assert set(np.flatnonzero(inside).tolist()) == expect
    # hit: those given and every choice with a successor in the set
    want = np.array([bool(hit0[c]) or bool(cs & expect)
                     for s in range(n) for c, cs in zip(
                         range(int(mdp.row_groups[s]), int(mdp.row_groups[s + 1])),
                         succ[s], strict=True)])
    assert np.array_equal(hit, want)


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize(("seed", "n"), CASES)
def test_the_analysis_sets_with_the_attractor_compiled(seed: int, n: int, sense: Sense,
                                                        gate) -> None:
    mdp = _mdp(seed, n)
    goal = np.asarray(mdp.target)
    want0, want1 = plain_sets(mdp, set(np.flatnonzero(goal).tolist()), sense)
    for on in (True, False):
        calls = gate(on)
        q, _ = analyse(mdp, goal, sense=sense)
        assert set(np.flatnonzero(q.prob0).tolist()) == want0, on
        assert set(np.flatnonzero(q.qualitative.one).tolist()) == want1, on
        if not on:
            assert not calls


def _arrays(x, path: str = "q") -> dict[str, object]:
    """Every array (dtype and bytes) and plain value of a quotient, walked."""
    out: dict[str, object] = {}
    if isinstance(x, np.ndarray):
        out[path] = (x.dtype.str, x.shape, x.tobytes())
    elif sp.issparse(x):
        for name in ("data", "indices", "indptr"):
            out.update(_arrays(getattr(x, name), f"{path}.{name}"))
    elif is_dataclass(x):
        for f in fields(x):
            out.update(_arrays(getattr(x, f.name), f"{path}.{f.name}"))
    elif isinstance(x, dict):
        for k in sorted(x, key=str):
            out.update(_arrays(x[k], f"{path}[{k}]"))
    elif isinstance(x, (tuple, list)):
        for i, v in enumerate(x):
            out.update(_arrays(v, f"{path}[{i}]"))
    elif isinstance(x, (int, float, str, bool)) or x is None:
        out[path] = repr(x)
    else:  # a record of its own (the attractor strategy): its arrays
        for k, v in sorted(vars(x).items()) if hasattr(x, "__dict__") else ():
            out.update(_arrays(v, f"{path}.{k}"))
        for k in getattr(type(x), "__slots__", ()):
            out.update(_arrays(getattr(x, k), f"{path}.{k}"))
    return out


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize("seed", range(6))
def test_both_quotients_are_the_same_with_the_gate_forced_either_way(seed: int, sense: Sense,
                                                                     gate) -> None:
    mdp = _mdp(100 + seed, 200)
    goal = np.asarray(mdp.target)
    extra = np.zeros(mdp.n_states, dtype=bool)
    extra[np.random.default_rng(seed).choice(mdp.n_states, 8, replace=False)] = True
    extra &= ~goal
    got = {}
    for on in (True, False):
        calls = gate(on)
        got[on] = [_arrays(q) for q in analyse(mdp, goal, extra, sense=sense)]
        assert ("backward" in calls) is on
        assert on or not calls
        LEVELS_CALLED.extend(c for c in calls if c == "state_levels")
    assert got[True] == got[False]


LEVELS_CALLED: list[str] = []


def test_the_quotients_levels_were_compiled_in_some_case_above() -> None:
    """(after the cases above, in this file's order): the forced gate reached the
    quotient's levels, so their equality above covers the compiled levels too."""
    if not LEVELS_CALLED:
        for seed in range(6):
            for sense in (Sense.MAX, Sense.MIN):
                mdp = _mdp(100 + seed, 200)
                with pytest.MonkeyPatch.context() as mp:
                    mp.setattr(walks_module, "COMPILED_MIN_ENTRIES", sys.maxsize)
                    mp.setattr(walks_module, "COMPILED_LOADED_MIN_ENTRIES", sys.maxsize)
                    mp.setattr(analysis_gates, "PAID_MIN_ENTRIES", 0)
                    mp.setattr(analysis_gates, "LEVELS_MIN_ENTRIES", 0)
                    mp.setattr(analysis_gates, "WARM_MIN_ENTRIES", 0)
                    mp.setattr(analysis_gates, "_WARM", {analysis_gates.ATTRACTOR: True,
                                                         analysis_gates.LEVELS: True})
                    seen: list[int] = []
                    inner = compiled_graph.state_levels
                    mp.setattr(compiled_graph, "state_levels",
                               lambda *a, _i=inner, _s=seen: _s.append(1) or _i(*a))
                    analyse(mdp, np.asarray(mdp.target), sense=sense)
                LEVELS_CALLED.extend("state_levels" for _ in seen)
    assert LEVELS_CALLED


def expected(entries: int, paid: bool, warm: bool, levels: bool) -> bool:
    """The rule: compiled from 4 million entries, from 150,000 once a kernel's load is
    paid; where the kernel is warm in the loader's cache, an attractor from 100,000
    entries, an attractor from 20,000 once a load is paid and the quotient's levels from
    1,000."""
    if entries >= 4_000_000 or (paid and entries >= 150_000):
        return True
    if not warm or entries < (1_000 if levels else 20_000):
        return False
    return paid or (not levels and entries >= 100_000)


@pytest.mark.parametrize("entries", [0, 999, 1_000, 19_999, 20_000, 99_999, 100_000,
                                     149_999, 150_000, 3_999_999, 4_000_000])
@pytest.mark.parametrize("paid", [True, False])
@pytest.mark.parametrize("warm", [True, False])
@pytest.mark.parametrize("levels", [True, False])
def test_the_gates_follow_the_rule(entries: int, paid: bool, warm: bool, levels: bool,
                                   monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(kernel_loader, "compiled_paid", lambda: paid)
    monkeypatch.setattr(analysis_gates, "_WARM", {analysis_gates.ATTRACTOR: warm,
                                                  analysis_gates.LEVELS: warm})
    got = (analysis_gates.level_walks if levels else analysis_gates.attractor_walks)(entries)
    assert (got is not None) is expected(entries, paid, warm, levels)
    assert got is None or got is compiled_graph


def test_each_gate_asks_for_its_own_kernel(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(kernel_loader, "compiled_paid", lambda: True)
    monkeypatch.setattr(analysis_gates, "_WARM", {})
    monkeypatch.setattr(kernel_loader, "cached", lambda f, q: q == "_backward")
    assert analysis_gates.attractor_walks(50_000) is compiled_graph
    assert analysis_gates.level_walks(50_000) is None
    monkeypatch.setattr(analysis_gates, "_WARM", {})
    monkeypatch.setattr(kernel_loader, "cached", lambda f, q: q == "state_levels")
    assert analysis_gates.attractor_walks(50_000) is None
    assert analysis_gates.level_walks(50_000) is compiled_graph


@pytest.mark.parametrize("why", ["off", "cold", "no numba"])
def test_the_gates_refuse_unless_the_loader_links_the_cached_kernel(
        why: str, monkeypatch: pytest.MonkeyPatch) -> None:
    paid = [False]
    monkeypatch.setattr(kernel_loader, "compiled_paid", lambda: paid[0])
    monkeypatch.setattr(analysis_gates, "_WARM", {})
    if why == "off":
        monkeypatch.setattr(kernel_loader, "ENABLED", False)
    elif why == "cold":
        monkeypatch.setattr(kernel_loader, "cached", lambda f, q: False)
    else:
        monkeypatch.setitem(sys.modules, "mitld_lp.solvers.compiled_graph", None)
        monkeypatch.delattr(mitld_lp.solvers, "compiled_graph", raising=False)
    assert analysis_gates.warm(analysis_gates.ATTRACTOR) is False
    assert analysis_gates.warm(analysis_gates.LEVELS) is False
    assert analysis_gates.attractor_walks(1_000_000) is None
    paid[0] = True  # a load paid by another kernel: still no walk of these compiled
    assert analysis_gates.attractor_walks(100_000) is None
    assert analysis_gates.level_walks(100_000) is None
    # the same lookups with the loader on, numba there and the kernels' files cached
    paid[0] = False
    monkeypatch.setattr(analysis_gates, "_WARM", {})
    monkeypatch.setattr(kernel_loader, "ENABLED", True)
    monkeypatch.setattr(kernel_loader, "cached", lambda f, q: q in ("_backward", "state_levels"))
    monkeypatch.setitem(sys.modules, "mitld_lp.solvers.compiled_graph", compiled_graph)
    assert analysis_gates.warm(analysis_gates.ATTRACTOR) is True
    assert analysis_gates.attractor_walks(1_000_000) is compiled_graph
    paid[0] = True
    assert analysis_gates.level_walks(100_000) is compiled_graph


def test_the_loader_switched_off_keeps_numpys_attractor_in_a_fresh_process() -> None:
    code = ("import sys; from mitld_lp.solvers import analysis_gates as g; "
            "from mitld_lp.util import kernel_loader as k; "
            "print(g.warm(), g.warm(g.LEVELS), g.attractor_walks(1_000_000) is None, "
            "k.compiled_paid(), 'numba' in sys.modules)")
    root = str(Path(__file__).resolve().parent.parent)
    env = dict(os.environ, MITLD_LP_KERNEL_LOADER="0",
               PYTHONPATH=os.pathsep.join([root, os.environ.get("PYTHONPATH", "")]))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env=env, check=True, timeout=120)
    assert out.stdout.split() == ["False", "False", "True", "False", "False"]


def plain_levels(succ: list[set[int]], comp: np.ndarray) -> dict[int, int]:
    """Each component's level by memoised recursion over the condensation: 0 without a
    successor component, else one more than its highest successor's."""
    out_of: dict[int, set[int]] = {}
    for s, ts in enumerate(succ):
        out_of.setdefault(int(comp[s]), set()).update(
            int(comp[t]) for t in ts if comp[t] != comp[s])
    memo: dict[int, int] = {}

    def level(c: int) -> int:
        if c not in memo:
            memo[c] = 1 + max((level(d) for d in out_of[c]), default=-1)
        return memo[c]

    limit = sys.getrecursionlimit()  # raised for this recursion only: other tests in the
    sys.setrecursionlimit(max(limit, 10 * len(out_of) + 1000))  # worker rely on the default
    try:
        return {c: level(c) for c in out_of}
    finally:
        sys.setrecursionlimit(limit)


@pytest.mark.parametrize(("seed", "n"), [(0, 60), (1, 400), (2, 3000), (3, 9000)])
def test_the_compiled_quotient_levels_are_scipys_and_the_plain_levels(seed: int, n: int,
                                                                        gate) -> None:
    """On state graphs below and above the plain walk's size (SciPy's search numbers
    the components of the latter): the compiled levels against SciPy's components (the
    partition) and levels by recursion written here, and the same numbers as the NumPy
    walk's."""
    from scipy.sparse.csgraph import connected_components

    mdp = _mdp(200 + seed, n)
    m = sp.csr_array(mdp.matrix)
    gate(True)
    got = graph.state_levels(m, mdp.row_groups, walks=compiled_graph)
    gate(False)
    numpy = graph.state_levels(m, mdp.row_groups)
    assert np.array_equal(got.component, numpy.component)
    assert np.array_equal(got.level, numpy.level)
    succ = [set().union(*cs) for cs in successors(mdp).values()]
    rows = [s for s, ts in enumerate(succ) for _ in ts]
    cols = [t for ts in succ for t in ts]
    g = sp.csr_array((np.ones(len(rows)), (rows, cols)), shape=(n, n))
    k, label = connected_components(g, directed=True, connection="strong")
    # the same partition: a one-to-one map between the labels
    pairs = set(zip(got.component.tolist(), label.tolist(), strict=True))
    assert len(pairs) == k == len({a for a, _ in pairs}) == got.level.size
    want = plain_levels(succ, got.component)
    assert [want[c] for c in range(got.level.size)] == got.level.tolist()


@pytest.mark.parametrize("entries", [0, 149_999, 150_000, 3_999_999, 4_000_000, 10**8])
@pytest.mark.parametrize("per_state", [1, 2.3, 7.9, 8, 20.6])
@pytest.mark.parametrize("paid", [True, False])
def test_the_products_components_are_compiled_from_4_million_entries_or_dense(
        entries: int, per_state: float, paid: bool, monkeypatch: pytest.MonkeyPatch) -> None:
    """From 4 million entries; from 150,000 once a load is paid where a state has at
    least 8 entries; else SciPy's walk."""
    monkeypatch.setattr(kernel_loader, "compiled_paid", lambda: paid)
    states = int(entries / per_state)
    got = analysis_gates.component_walks(entries, states)
    want = entries >= 4_000_000 or (paid and entries >= 150_000 and entries >= 8 * states)
    assert (got is not None) is want


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize("seed", range(4))
def test_the_quotients_are_the_same_with_the_components_on_scipy_or_compiled(
        seed: int, sense: Sense, monkeypatch: pytest.MonkeyPatch) -> None:
    """A product past the plain walk's size (SciPy's search), its load paid: every walk
    compiled, every walk but the product's components compiled (this gate), and every
    walk on NumPy give the same quotients; the product's components are SciPy's
    partition."""
    from scipy.sparse.csgraph import connected_components

    mdp = _mdp(300 + seed, 6000)
    goal = np.asarray(mdp.target)
    extra = np.zeros(mdp.n_states, dtype=bool)
    extra[np.random.default_rng(seed).choice(mdp.n_states, 40, replace=False)] = True
    extra &= ~goal
    monkeypatch.setattr(kernel_loader, "compiled_paid", lambda: True)
    monkeypatch.setattr(analysis_gates, "_WARM", {analysis_gates.ATTRACTOR: True,
                                                  analysis_gates.LEVELS: True})
    calls: list[str] = []
    for name in ("state_levels", "backward"):
        inner = getattr(compiled_graph, name)
        monkeypatch.setattr(compiled_graph, name,
                            lambda *a, _i=inner, _n=name: calls.append(_n) or _i(*a))
    got = {}
    for mode, low, loaded in (("all", 0, 0), ("gate", sys.maxsize, 0),
                              ("numpy", sys.maxsize, sys.maxsize)):
        monkeypatch.setattr(walks_module, "COMPILED_MIN_ENTRIES", low)
        monkeypatch.setattr(walks_module, "COMPILED_LOADED_MIN_ENTRIES", loaded)
        for name in ("WARM_MIN_ENTRIES", "PAID_MIN_ENTRIES", "LEVELS_MIN_ENTRIES"):
            monkeypatch.setattr(analysis_gates, name, loaded)
        calls.clear()
        qs = analyse(mdp, goal, extra, sense=sense)
        got[mode] = [_arrays(q) for q in qs]
        assert ("backward" in calls) is (mode != "numpy"), mode
        if mode == "all":
            assert "state_levels" in calls  # the product's components compiled
        comp = np.asarray(qs[0].layers[0])
    assert got["all"] == got["gate"] == got["numpy"]
    m = sp.csr_array(mdp.matrix)
    g = graph.graph_view(m, mdp.row_groups)
    k, label = connected_components(g, directed=True, connection="strong")
    pairs = set(zip(comp.tolist(), label.tolist(), strict=True))
    assert len(pairs) == k == len({a for a, _ in pairs})
