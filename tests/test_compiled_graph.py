"""The compiled graph walks (``mitld_lp.solvers.compiled_graph``) against walks written
differently here (closures, plain fixed points), against the NumPy walks they replace
(the same sets, components, numbering and quotients) and against Storm's prob01."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from dataclasses import fields, is_dataclass, replace
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.mdp import MDP
from mitld_lp.solvers import graph
from mitld_lp.solvers import walks as walks_module
from mitld_lp.solvers.analysis import analyse
from mitld_lp.solvers.graph import Sense
from mitld_lp.util import traversal

numba = pytest.importorskip("numba")
from mitld_lp.solvers import compiled_graph as cg  # noqa: E402  (needs numba)

ROOT = Path(__file__).resolve().parent.parent
needs_storm = pytest.mark.skipif(importlib.util.find_spec("stormpy") is None,
                                 reason="needs stormpy: pip install -e '.[prism]'")


@pytest.fixture
def walks(monkeypatch):
    """``walks(True)``: every walk of ``graph`` compiled; ``walks(False)``: none."""
    def use(compiled: bool) -> None:
        low = 0 if compiled else sys.maxsize
        monkeypatch.setattr(walks_module, "COMPILED_MIN_ENTRIES", low)
        monkeypatch.setattr(walks_module, "COMPILED_LOADED_MIN_ENTRIES", low)
    return use


def random_graph(rng: np.random.Generator, n: int, m: int) -> sp.csr_array:
    g = sp.csr_array((np.ones(m, dtype=bool), (rng.integers(0, n, m), rng.integers(0, n, m))),
                     shape=(n, n))
    g.sum_duplicates()
    return g


def random_mdp(rng: np.random.Generator, n: int) -> MDP:
    """1-3 choices a state, 1-3 successors a choice (weights 1/k), some self-loops;
    the last state the target, the one before it truncated."""
    rows, groups = [], [0]
    for s in range(n):
        for _ in range(int(rng.integers(1, 4))):
            succ = ({s} if rng.random() < 0.15
                    else set(rng.integers(0, n, int(rng.integers(1, 4))).tolist()))
            rows.append(sorted(succ))
        groups.append(len(rows))
    ptr = np.cumsum([0] + [len(r) for r in rows])
    cols = np.array([t for r in rows for t in r], dtype=np.int32)
    data = np.concatenate([np.full(len(r), 1.0 / len(r)) for r in rows])
    matrix = sp.csr_array((data, cols, ptr.astype(np.int32)), shape=(len(rows), n))
    target = np.zeros(n, dtype=bool)
    target[-1] = True
    truncated = np.zeros(n, dtype=bool)
    truncated[-2] = True
    return MDP(matrix=matrix, row_groups=np.array(groups, dtype=np.int64),
               choice_actions=np.zeros(len(rows), dtype=np.int32), action_names=("a",),
               initial=0, target=target, sink=np.zeros(n, dtype=bool),
               truncated=truncated, states=list(range(n)))


def closure(g: sp.csr_array) -> np.ndarray:
    """Reflexive transitive closure (dense Warshall): ``r[i, j]`` iff a path i -> j."""
    r = g.toarray().astype(bool) | np.eye(g.shape[0], dtype=bool)
    for k in range(g.shape[0]):
        r |= r[:, [k]] & r[[k], :]
    return r


def test_components_levels_and_reach_match_a_closure():
    rng = np.random.default_rng(1)
    for _ in range(60):
        n = int(rng.integers(1, 40))
        g = random_graph(rng, n, int(rng.integers(0, 3 * n)))
        seeds = rng.random((n, 2)) < 0.1
        r = closure(g)
        for descending in (False, True):
            k, label, level, reach = cg.components_and_levels(  # int32, as every caller's
                g.indptr.astype(np.int32), g.indices.astype(np.int32), descending, seeds, True)
            assert np.array_equal(label[:, None] == label[None, :], r & r.T)
            assert k == np.unique(label).size
            # longest path to a sink of the condensation, by recursion over the closure
            memo: dict[int, int] = {}

            def depth(c, label=label, r=r, memo=memo):
                if c not in memo:
                    members = np.flatnonzero(label == c)
                    below = {int(label[t]) for t in np.flatnonzero(r[members].any(axis=0))}
                    memo[c] = max((depth(d) + 1 for d in below - {c}), default=0)
                return memo[c]
            assert [depth(c) for c in range(k)] == level.tolist()
            for c in range(k):
                members = np.flatnonzero(label == c)
                assert reach[c].tolist() == (r[members] @ seeds).any(axis=0).tolist()


def test_components_are_numbered_as_the_numpy_walks_number_them():
    from scipy.sparse import csgraph

    rng = np.random.default_rng(2)
    for _ in range(100):
        n = int(rng.integers(1, 60))
        g = random_graph(rng, n, int(rng.integers(0, 3 * n)))
        k, label = cg.strong_components(g.indptr, g.indices, True)
        want = csgraph.connected_components(g, directed=True, connection="strong")
        assert k == want[0] and np.array_equal(label, want[1])
        k, label = cg.strong_components(g.indptr, g.indices, False)
        want = traversal.strong_components(g)  # a small graph: the plain walk
        assert k == want[0] and np.array_equal(label, want[1])


def test_state_graph_is_the_graph_view():
    rng = np.random.default_rng(3)
    mdp = random_mdp(rng, 50)
    ptr, succ = cg.state_graph(mdp.matrix.indptr, mdp.matrix.indices, mdp.row_groups, 50)
    view = graph.graph_view(mdp.matrix, mdp.row_groups)
    assert np.array_equal(ptr, view.indptr) and np.array_equal(succ, view.indices)


def plain_attractor(mdp: MDP, seeds: np.ndarray) -> np.ndarray:
    """The least set holding ``seeds`` and every state all of whose choices have an
    entry in it, by iterating to the fixed point."""
    inside = seeds.copy()
    rows = [set(mdp.matrix.indices[mdp.matrix.indptr[c]:mdp.matrix.indptr[c + 1]].tolist())
            for c in range(mdp.n_choices)]
    grew = True
    while grew:
        grew = False
        for s in np.flatnonzero(~inside):
            choices = range(mdp.row_groups[s], mdp.row_groups[s + 1])
            if all(any(inside[t] for t in rows[c]) for c in choices):
                inside[s] = grew = True
    return inside


def test_attractor_and_reach_match_fixed_points(walks):
    walks(True)
    rng = np.random.default_rng(4)
    for _ in range(30):
        n = int(rng.integers(2, 40))
        mdp = random_mdp(rng, n)
        seeds = rng.random(n) < 0.15
        got = graph.attractor(mdp.matrix, mdp.row_groups, seeds)
        assert np.array_equal(got, plain_attractor(mdp, seeds))
        r = closure(graph.graph_view(mdp.matrix, mdp.row_groups))
        back = cg.backward(mdp.matrix.indptr, mdp.matrix.indices, mdp.row_groups, seeds,
                           np.zeros(mdp.n_choices, dtype=bool), False)
        assert np.array_equal(back, (r & seeds[None, :]).any(axis=1))
        e = graph.edges(mdp)
        along = graph.backward_reachable(n, e.source, e.succ, seeds)
        assert np.array_equal(along, (r & seeds[None, :]).any(axis=1))


def test_end_components_are_those_of_the_numpy_rounds(walks):
    rng = np.random.default_rng(5)
    for _ in range(40):
        n = int(rng.integers(2, 40))
        mdp = random_mdp(rng, n)
        mask = rng.random(n) < 0.8
        walks(False)
        want = graph.maximal_end_components(mdp, mask)
        walks(True)
        got = graph.maximal_end_components(mdp, mask)
        assert got.n_mecs == want.n_mecs
        assert np.array_equal(got.mec_of, want.mec_of)
        assert np.array_equal(got.internal, want.internal)
        # each one closed under its choices and strongly connected by them
        for k in range(got.n_mecs):
            states = got.states_of(k)
            choices = got.choices_of(k, mdp)
            sub = mdp.matrix[choices]
            assert set(sub.indices.tolist()) <= set(states.tolist())
            owner = mdp.choice_state()[choices]
            g = sp.csr_array((np.ones(sub.nnz, dtype=bool),
                              (np.repeat(owner, np.diff(sub.indptr)), sub.indices)),
                             shape=(n, n))
            assert closure(g)[np.ix_(states, states)].all()


def _same(a, b, where="quotient"):
    if isinstance(a, np.ndarray):
        assert a.dtype == b.dtype and np.array_equal(a, b), where
    elif sp.issparse(a):
        for part in ("indptr", "indices", "data"):
            assert np.array_equal(getattr(a, part), getattr(b, part)), where
    elif is_dataclass(a):
        for f in fields(a):
            _same(getattr(a, f.name), getattr(b, f.name), f"{where}.{f.name}")
    elif isinstance(a, tuple):
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _same(x, y, f"{where}[{i}]")
    elif isinstance(a, float) and a != a:
        assert b != b, where
    else:
        assert a == b, where


def _goes_down(owner: np.ndarray, succ: np.ndarray, comp: np.ndarray,
               level: np.ndarray) -> None:
    """Every edge ``owner -> succ`` between two components that have a level (-1: none)
    goes to a lower one."""
    a, b = comp[owner], comp[succ]
    both = (a != b) & (level[a] >= 0) & (level[b] >= 0)
    assert np.all(level[a[both]] > level[b[both]])


def _same_blocks(a, b, q) -> None:
    """Two block orders of the quotient ``q``: the same components (ids may differ),
    sizes and self-loops, and each grouped by a layering of the quotient's graph."""
    pairs = np.unique(np.column_stack([a.component, b.component]), axis=0)
    assert pairs.shape[0] == a.n_components == b.n_components  # one partition
    assert np.array_equal(a.size[pairs[:, 0]], b.size[pairs[:, 1]])
    assert np.array_equal(a.self_loop, b.self_loop)
    owner = np.repeat(np.arange(q.n_states), np.diff(q.row_groups))
    owner = np.repeat(owner, np.diff(q.matrix.indptr))
    for o in (a, b):
        _goes_down(owner, q.matrix.indices, o.component, o.level)
        assert np.all(o.level >= 0)
        for k in range(o.n_levels):
            assert np.all(o.level[o.component[o.states_at(k)]] == k)


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
def test_analysis_compiled_is_the_numpy_analysis(walks, sense):
    """The same quotient, sets and components whether the walks are compiled or not.
    The levels may differ: the compiled walk finds the product's in the same pass and
    they are kept, the NumPy analysis finds the quotient's own (the product-wide walk
    was half its time) and lifts them to the product's components, -1 outside the
    quotient.  So the levels, and the quotient's block order grouped by them, are
    checked to be layerings (every edge between components goes down), -1 only where
    no state of the component is in the quotient."""
    rng = np.random.default_rng(6)
    for _ in range(15):
        mdp = random_mdp(rng, int(rng.integers(3, 60)))
        walks(False)
        want = analyse(mdp, mdp.target, mdp.truncated, sense=sense)
        walks(True)
        got = analyse(mdp, mdp.target, mdp.truncated, sense=sense)
        g = graph.graph_view(sp.csr_array(mdp.matrix), mdp.row_groups)
        owner = np.repeat(np.arange(mdp.n_states), np.diff(g.indptr))
        for q, p in zip(got, want, strict=True):
            _same(replace(q, layers=None, order=None), replace(p, layers=None, order=None))
            _same(q.layers[0], p.layers[0], "layers[0]")
            _same_blocks(q.order, p.order, q)
            comp = np.asarray(q.layers[0])
            inside = np.zeros(int(comp.max()) + 1, dtype=bool)
            inside[comp[np.asarray(q.state_map) >= 0]] = True
            for level in (np.asarray(q.layers[1]), np.asarray(p.layers[1])):
                assert level.dtype == np.asarray(p.layers[1]).dtype
                _goes_down(owner, g.indices, comp, level)
                assert np.all((level >= 0) | ~inside)
            assert np.all(np.asarray(q.layers[1]) >= 0)  # the compiled walk's: all


@needs_storm
@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
def test_qualitative_sets_are_storms_prob01(walks, tmp_path, sense):
    import stormpy
    import stormpy.analysis

    from mitld_lp.solvers import write_drn

    walks(True)
    rng = np.random.default_rng(7)
    prop = stormpy.parse_properties(f'P{sense.value}=? [F "target"]')[0]
    for i in range(6):
        mdp = random_mdp(rng, 30)
        q = analyse(mdp, mdp.target, sense=sense)[0]
        path = write_drn(mdp, mdp.target, tmp_path / f"m{i}.drn", valuations=False)
        model = stormpy.build_model_from_drn(str(path))
        assert model.nr_states == mdp.n_states
        zero, one = stormpy.analysis.compute_prob01_states(model, prop)
        assert [zero.get(s) for s in range(30)] == q.qualitative.zero.tolist()
        assert [one.get(s) for s in range(30)] == q.qualitative.one.tolist()


def test_a_small_solve_loads_no_numba():
    probe = ("import sys, json\nfrom mitld_lp import load_model, synthesize\n"
             "synthesize(load_model('models/bus_grid.toml'))\n"
             "print(json.dumps('numba' in sys.modules))")
    run = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                         cwd=ROOT, timeout=120, check=True)
    assert json.loads(run.stdout.strip().splitlines()[-1]) is False
