"""The deadline walks (issue 45): the component levels found by SciPy's searches
(graph.searched_levels) and the batched NumPy walks of the single-state levels
(level_batches.bounds / flow), each against a plain state-by-state computation written
here, and a small PRISM deadline model solved end to end against Storm's exact engine."""

from __future__ import annotations

import sys
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import build_mdp

from mitld_lp.solvers import analysis_gates, graph, level_search
from mitld_lp.solvers.analysis import analyse
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.topological import SingleLevels

sys.path.insert(0, str(Path(__file__).resolve().parent))
from storm_exact import storm_rational  # noqa: E402

# ----------------------------------------------------------------------- plain references


def _plain_components(n: int, succ: list[list[int]]) -> list[int]:
    """Kosaraju's two passes, iterative: a label per node (any numbering)."""
    seen, order = [False] * n, []
    for root in range(n):
        if seen[root]:
            continue
        seen[root] = True
        stack = [(root, 0)]
        while stack:
            v, i = stack.pop()
            if i < len(succ[v]):
                stack.append((v, i + 1))
                w = succ[v][i]
                if not seen[w]:
                    seen[w] = True
                    stack.append((w, 0))
            else:
                order.append(v)
    pred: list[list[int]] = [[] for _ in range(n)]
    for v in range(n):
        for w in succ[v]:
            pred[w].append(v)
    label = [-1] * n
    for c, root in enumerate(reversed(order)):
        if label[root] >= 0:
            continue
        label[root] = c
        todo = [root]
        while todo:
            v = todo.pop()
            for w in pred[v]:
                if label[w] < 0:
                    label[w] = c
                    todo.append(w)
    return label


def _plain_levels(n: int, succ: list[list[int]], label: list[int],
                  seeds: np.ndarray) -> tuple[dict[int, int], dict[int, list[bool]]]:
    """Each component's longest path to a sink of the component graph, and whether it
    reaches each seed set, by memoised recursion (made iterative) over the components."""
    members: dict[int, list[int]] = {}
    for v in range(n):
        members.setdefault(label[v], []).append(v)
    out = {c: {label[w] for v in vs for w in succ[v]} - {c} for c, vs in members.items()}
    level: dict[int, int] = {}
    reach: dict[int, list[bool]] = {}
    for start in members:
        stack = [start]
        while stack:
            c = stack[-1]
            if c in level:
                stack.pop()
                continue
            todo = [d for d in out[c] if d not in level]
            if todo:
                stack.extend(todo)
                continue
            stack.pop()
            level[c] = 1 + max((level[d] for d in out[c]), default=-1)
            mine = [bool(seeds[members[c], j].any()) for j in range(seeds.shape[1])]
            reach[c] = [mine[j] or any(reach[d][j] for d in out[c])
                        for j in range(seeds.shape[1])]
    return level, reach


def _random_graph(seed: int, n: int) -> sp.csr_array:
    """Mostly downhill (a deep graph of thin levels, as a deadline makes) with a few
    uphill edges that close cycles, on shuffled node ids."""
    rng = np.random.default_rng(seed)
    m = 3 * n
    a = rng.integers(0, n, m)
    b = np.clip(a - rng.integers(1, 12, m), 0, n - 1)
    up = rng.random(m) < 0.03
    b[up] = np.minimum(a[up] + rng.integers(1, 4, int(up.sum())), n - 1)
    perm = rng.permutation(n)
    g = sp.csr_array((np.ones(m, dtype=bool), (perm[a], perm[b])), shape=(n, n))
    g.sum_duplicates()
    return g


@pytest.fixture(params=["searched", "walked"])
def how(request, monkeypatch):
    """The levels found by the search (any graph counts as large and thin) or walked
    level by level (no graph counts as thin)."""
    if request.param == "searched":
        monkeypatch.setattr(graph, "SMALL", 0)
        monkeypatch.setattr(graph, "PROBE_LEVELS", 1)
        monkeypatch.setattr(level_search, "LEVEL_CALL_SECONDS", 1.0)
    else:
        monkeypatch.setattr(level_search, "LEVEL_CALL_SECONDS", 0.0)
    return request.param, _searches(monkeypatch)


def _searches(monkeypatch) -> list[bool]:
    """Per call of the search from :func:`graph.levels`, whether it answered."""
    inner, used = graph.searched_levels, []
    monkeypatch.setattr(graph, "searched_levels",
                        lambda *a: used.append((got := inner(*a)) is not None) or got)
    return used


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_levels_match_a_plain_longest_path_and_reach(seed: int, how) -> None:
    mode, used = how
    n = 1500
    g = _random_graph(seed, n)
    seeds = np.random.default_rng(seed + 10).random((n, 2)) < np.array([0.002, 0.03])
    found = graph.levels(g, seeds)
    assert used == ([True] if mode == "searched" else [])
    succ = [g.indices[g.indptr[v]:g.indptr[v + 1]].tolist() for v in range(n)]
    label = _plain_components(n, succ)
    # the same partition into components, whatever the numbering
    pairs = set(zip(label, found.component.tolist(), strict=True))
    assert len(pairs) == len(set(label)) == len(set(found.component.tolist()))
    level, reach = _plain_levels(n, succ, label, seeds)
    assert max(level.values()) > 50  # deep: the case the search is for
    for v in range(n):
        c = int(found.component[v])
        assert found.level[c] == level[label[v]], v
        assert found.reach[c].tolist() == reach[label[v]], v


def test_a_component_graph_off_tarjans_order_is_walked(monkeypatch) -> None:
    # the search relies on edges running from higher ids to lower: where they do not,
    # it declines and the level-by-level walk answers
    preds = sp.csr_array((np.ones(2), ([0, 1], [1, 2])), shape=(3, 3))  # 1->0, 2->1 ok
    assert graph.searched_levels(preds, np.array([0]), np.arange(3),
                                 np.zeros((3, 0), dtype=bool))[0].tolist() == [0, 1, 2]
    wrong = sp.csr_array((np.ones(2), ([1, 2], [0, 1])), shape=(3, 3))  # 0->1: uphill
    assert graph.searched_levels(wrong, np.array([2]), np.arange(3),
                                 np.zeros((3, 0), dtype=bool)) is None


# ------------------------------------------------------------- the single-state walks


def _deadline_mdp(seed: int, depth: int = 40, width: int = 6, ties: bool = False):
    """A deadline-like MDP: ``depth`` layers of ``width`` states, each choice staying put,
    moving to the next layers, or to the goal / the dead end.  ``ties``: some choices
    never reach the goal, and a third of the states repeat a choice (an exact tie)."""
    rng = np.random.default_rng(seed)
    n = depth * width
    goal, dead = n, n + 1
    states = []
    for s in range(n):
        layer = s // width
        mine = []
        for a in range(int(rng.integers(1, 4))):
            ahead = [(layer + int(rng.integers(1, 3))) * width + int(j)
                     for j in rng.choice(width, 2, replace=False)]
            nxt = [goal, dead] + [t if t < n else dead for t in ahead]
            w = rng.integers(1, 9, size=len(nxt) + 1).astype(float)
            w[0] = w[0] if rng.random() < 0.5 else 0.0
            if ties:
                w[1] = w[1] if rng.random() < 0.6 else 0.0
            p = w / w.sum()
            row = {s: float(p[0])} if p[0] > 0 else {}
            for t, q in zip(nxt, p[1:], strict=True):
                row[t] = row.get(t, 0.0) + float(q)
            row[dead] += 1.0 - sum(row.values())
            mine.append((f"a{a}", row))
        if ties and rng.random() < 0.35:  # the same distribution again
            mine.append((f"a{len(mine)}", dict(mine[0][1])))
        states.append(mine)
    states += [[], []]
    return build_mdp(states, target=[goal], sink=[dead])


def _plain_order(sl: SingleLevels) -> list[list[int]]:
    """The single states' positions in ``sl`` (level by level)."""
    at = sl.level_state
    return [list(range(int(at[k]), int(at[k + 1]))) for k in range(at.size - 1)]


def _plain_rows(q, sl: SingleLevels, i: int):
    """Single state ``i`` of ``sl``: per choice, (choice, self-loop, [(col, p)]) read from
    the quotient's matrix (the self-loop left out of the entries)."""
    s = int(sl.states[i])
    out = []
    for c in range(int(q.row_groups[s]), int(q.row_groups[s + 1])):
        lo, hi = q.matrix.indptr[c], q.matrix.indptr[c + 1]
        cols, vals = q.matrix.indices[lo:hi].tolist(), q.matrix.data[lo:hi].tolist()
        stay = sum(v for col, v in zip(cols, vals, strict=True) if col == s)
        out.append((c, stay, [(col, v) for col, v in zip(cols, vals, strict=True)
                              if col != s]))
    return s, out


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
def test_batched_bounds_walk_is_the_plain_loop_to_the_bit(seed: int, sense: Sense) -> None:
    mdp = _deadline_mdp(seed)
    q, _ = analyse(mdp, mdp.target, sense=sense)
    sl = SingleLevels(q, q.order, compiled=False)
    assert sl.positive and len(sl.runs) > 30
    k = 2
    rewards = np.column_stack([q.to_target, 0.5 * q.to_target])
    got = np.zeros((q.n_states, k))
    sl.solve(0, q.order.n_levels, rewards, got)
    want = np.zeros((q.n_states, k))
    pick = max if sense is Sense.MAX else min
    for level in _plain_order(sl):
        for i in level:
            s, rows = _plain_rows(q, sl, i)
            for j in range(k):
                scores = []
                for c, stay, entries in rows:
                    acc = 0.0
                    for col, v in entries:
                        acc += v * want[col, j]
                    scores.append(min(max((rewards[c, j] + acc) / (1.0 - stay), 0.0), 1.0))
                want[s, j] = pick(scores)
    assert got.tobytes() == want.tobytes()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_batched_flow_walk_is_the_plain_loop_to_the_bit(seed: int) -> None:
    mdp = _deadline_mdp(seed)
    q, _ = analyse(mdp, mdp.target)
    sl = SingleLevels(q, q.order, compiled=False)
    rng = np.random.default_rng(seed)
    # a randomised policy: each state's choices' weights sum to 1
    weights = rng.random(q.matrix.shape[0])
    groups = q.row_groups
    weights /= np.repeat(np.add.reduceat(weights, groups[:-1]), np.diff(groups))
    self_loop = np.asarray(q.order.self_loop)
    x0 = rng.random(q.n_states)
    got = x0.copy()
    sl.flow(0, q.order.n_levels, self_loop, weights, got)
    want = x0.copy()
    for level in reversed(_plain_order(sl)):
        rows = [_plain_rows(q, sl, i) for i in level]
        for s, choices in rows:
            kept = 0.0
            for c, _, _ in choices:
                kept += weights[c] * self_loop[c]
            want[s] /= 1.0 - kept
        for s, choices in rows:
            for c, _, entries in choices:
                for col, v in entries:
                    want[col] += v * (weights[c] * want[s])
    assert got.tobytes() == want.tobytes()


# ------------------------------------------------------- a PRISM deadline model end to end

DEADLINE = """mdp
const int D = 60;
module m
  t : [0..D] init 0;
  x : [0..12] init 0;
  [fast] t<D & x<12 -> 0.35 : (x'=x+1)&(t'=t+1) + 0.05 : (x'=0)&(t'=t+1) + 0.6 : (t'=t+1);
  [safe] t<D & x<12 -> 0.2 : (x'=x+1)&(t'=t+1) + 0.8 : (t'=t+1);
  [skip] t<D-1 & x<11 -> 0.1 : (x'=x+2)&(t'=min(t+2,D)) + 0.9 : (t'=min(t+2,D));
  [stop] t=D | x=12 -> true;
endmodule
label "goal" = x=12;
"""


def _posed(tmp_path: Path, program: str, reached: str, objective: str, prop: str):
    """The PRISM ``program`` as a model file whose task is to reach ``reached`` (the
    ``objective``), and Storm's exact value of ``prop`` on it."""
    prism = tmp_path / "deadline.prism"
    prism.write_text(program)
    model = tmp_path / "deadline.toml"
    model.write_text(f'name = "deadline"\nspec = "F reached"\nobjective = "{objective}"\n\n'
                     f'[prism]\nfile = "{prism}"\n\n[labels]\nreached = "{reached}"\n')
    return model, storm_rational(prism, prop)


@pytest.mark.parametrize("objective, prop", [("max", "Pmax=? [F \"goal\"]"),
                                             ("min", "Pmin=? [F \"goal\"]")])
def test_prism_deadline_bracket_holds_storms_exact_value(tmp_path, monkeypatch,
                                                         objective: str, prop: str) -> None:
    walked_and_searched(tmp_path, monkeypatch, DEADLINE, "x=12", objective, prop)


def walked_and_searched(tmp_path: Path, monkeypatch, program: str, reached: str,
                        objective: str, prop: str) -> None:
    """The PRISM ``program`` solved end to end with its levels walked, then searched
    (every graph counts as large and thin): each bracket certified and holding Storm's
    exact value of ``prop`` (no tolerance), the two the same bits."""
    from mitld_lp import load_model, synthesize

    model, exact = _posed(tmp_path, program, reached, objective, prop)
    brackets, used = [], _searches(monkeypatch)
    for searched in (False, True):
        if searched:  # every graph large and thin: the levels searched
            monkeypatch.setattr(graph, "SMALL", 0)
            # by NumPy's walk, not the compiled one a paid load takes from 1,000 entries
            monkeypatch.setattr(analysis_gates, "LEVELS_MIN_ENTRIES", sys.maxsize)
            monkeypatch.setattr(graph, "PROBE_LEVELS", 1)
            monkeypatch.setattr(level_search, "LEVEL_CALL_SECONDS", 1.0)
        r = synthesize(load_model(model))
        assert bool(used) == searched and all(used)
        assert r.certified, r.failed_checks
        assert Fraction(r.lower) <= exact <= Fraction(r.upper)
        assert r.upper - r.lower < 1e-6
        brackets.append((r.lower, r.upper))
    assert 0.01 < float(exact) < 0.99  # not decided by the graph alone
    assert brackets[0] == brackets[1]  # the same bits either way
