"""The analysis's sets against a brute force written here, on random MDPs: general ones
and products acyclic apart from self-loops (a deadline's clock counts time), in both
senses, with and without a second (truncated) target.

Each quotient of :func:`~mitld_lp.solvers.analysis.analyse` is checked against plain
Python fixed points over sets of successors (no code of the package):

* ``prob0``: a maximum's ``Prob0A`` (no path to the target), a minimum's ``Prob0E``
  (the greatest set of non-target states each with a choice that stays in it);
* ``qualitative.one``: a maximum's ``Prob1E`` (the nested fixed point
  ``nu Y. mu X. T | {s: some choice inside Y that hits X}``), a minimum's ``Prob1A``
  (no path through non-target states into ``Prob0E``);
* the maximal end components of a maximum's maybe states (de Alfaro's rounds, each
  round's components from SciPy's ``connected_components``), as a partition with
  their internal choices, numbered by their least state, as the analysis documents;
* ``layers[0]``: the product's strongly connected components (the partition SciPy's
  ``connected_components`` finds), and the block order a valid layering of the
  quotient's own graph (every edge between two blocks goes down a level; each of the
  quotient's components, as SciPy finds them, inside one block).

:func:`~mitld_lp.solvers.analysis.end_components` on an acyclic product (its shortcut:
each maybe state with a choice that stays put is an end component alone) against the
general search of the package, which the shortcut replaces there.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from mitld_lp.mdp import MDP
from mitld_lp.solvers.analysis import analyse, end_components
from mitld_lp.solvers.graph import Sense, maximal_end_components, state_components
from mitld_lp.testing import random_mdp


def _acyclic(seed: int, n: int | None = None) -> MDP:
    """States 0..n-1; each choice moves to lower-numbered states, or stays put (alone,
    or with its own column among others: a loop, yet no end component); 0 and 1 are
    absorbing (target, sink), and about a tenth of the others."""
    rng = np.random.default_rng(7100 + seed)
    n = int(rng.integers(4, 60)) if n is None else n
    rows: list[list[int]] = []
    groups = [0]
    for s in range(n):
        absorbing = s < 2 or rng.random() < 0.1
        for _ in range(1 if absorbing else int(rng.integers(1, 4))):
            kind = rng.random()
            if absorbing or kind < 0.2:
                row = [s]
            else:
                k = int(rng.integers(1, min(s, 3) + 1))
                row = sorted(int(t) for t in rng.choice(s, k, replace=False))
                if kind < 0.35:
                    row = sorted([*row, s])
            rows.append(row)
        groups.append(len(rows))
    ptr = np.concatenate([[0], np.cumsum([len(r) for r in rows])])
    cols = np.concatenate(rows)
    data = np.concatenate([np.full(len(r), 1.0 / len(r)) for r in rows])
    m = sp.csr_array((data, cols.astype(np.int32), ptr.astype(np.int32)),
                     shape=(len(rows), n))
    target = np.zeros(n, dtype=bool)
    target[0] = True
    no = np.zeros(n, dtype=bool)
    return MDP(matrix=m, row_groups=np.asarray(groups, dtype=np.int64),
               choice_actions=np.zeros(len(rows), dtype=np.int32), action_names=(),
               initial=n - 1, target=target, sink=no, truncated=no, states=range(n))


def _choices(mdp: MDP) -> list[list[set[int]]]:
    m = sp.csr_array(mdp.matrix)
    g = np.asarray(mdp.row_groups)
    return [[{int(t) for t, p in zip(m.indices[m.indptr[c]:m.indptr[c + 1]],
                                     m.data[m.indptr[c]:m.indptr[c + 1]], strict=True)
                  if p > 0}
             for c in range(g[s], g[s + 1])] for s in range(mdp.n_states)]


def _reach(ch: list[list[set[int]]], seeds: set[int], through: set[int]) -> set[int]:
    """The seeds and the ``through`` states with a path through such states to one."""
    inside = set(seeds)
    grew = True
    while grew:
        grew = False
        for s in through - inside:
            if any(c & inside for c in ch[s]):
                inside.add(s)
                grew = True
    return inside


def _prob0e(ch: list[list[set[int]]], target: set[int]) -> set[int]:
    y = set(range(len(ch))) - target
    while True:
        keep = {s for s in y if any(c <= y for c in ch[s])}
        if keep == y:
            return y
        y = keep


def _prob1e(ch: list[list[set[int]]], target: set[int]) -> set[int]:
    y = set(range(len(ch)))
    while True:
        x = set(target)
        grew = True
        while grew:
            grew = False
            for s in y - x:
                if any(c <= y and c & x for c in ch[s]):
                    x.add(s)
                    grew = True
        if x == y:
            return y
        y = x


def _prob1a(ch: list[list[set[int]]], target: set[int]) -> set[int]:
    n = len(ch)
    bad = _reach(ch, _prob0e(ch, target), set(range(n)) - target)
    return set(range(n)) - bad


def _mecs(mdp: MDP, ch: list[list[set[int]]], states: set[int]
          ) -> tuple[list[frozenset[int]], set[int]]:
    """De Alfaro's rounds on ``states``: the end components and their choices."""
    g = np.asarray(mdp.row_groups)
    alive = set(states)
    allowed = {c for s in alive for c in range(g[s], g[s + 1])}
    while True:
        allowed = {c for c in allowed
                   if (s := int(np.searchsorted(g, c, side="right") - 1)) in alive
                   and ch[s][c - g[s]] <= alive}
        owners = {int(np.searchsorted(g, c, side="right") - 1) for c in allowed}
        n = mdp.n_states
        rows, cols = [], []
        for c in allowed:
            s = int(np.searchsorted(g, c, side="right") - 1)
            for t in ch[s][c - g[s]]:
                rows.append(s)
                cols.append(t)
        graph = sp.csr_array((np.ones(len(rows)), (rows, cols)), shape=(n, n))
        _, label = connected_components(graph, directed=True, connection="strong")
        leave = {c for c in allowed
                 if any(label[t] != label[int(np.searchsorted(g, c, side="right") - 1)]
                        for t in ch[int(np.searchsorted(g, c, side="right") - 1)][
                            c - g[int(np.searchsorted(g, c, side="right") - 1)]])}
        if not leave and owners == alive:
            parts: dict[int, set[int]] = {}
            for s in alive:
                parts.setdefault(int(label[s]), set()).add(s)
            return [frozenset(p) for p in parts.values()], allowed
        allowed -= leave
        alive = owners


def _partition(labels: np.ndarray, among: np.ndarray | None = None) -> set[frozenset[int]]:
    idx = np.arange(labels.size) if among is None else np.flatnonzero(among)
    parts: dict[int, set[int]] = {}
    for s in idx:
        parts.setdefault(int(labels[s]), set()).add(int(s))
    return {frozenset(p) for p in parts.values()}


def _scc(mdp: MDP) -> np.ndarray:
    m = sp.csr_array(mdp.matrix)
    owner = np.repeat(np.arange(mdp.n_states), np.diff(np.asarray(mdp.row_groups)))
    rows = owner[np.repeat(np.arange(m.shape[0]), np.diff(m.indptr))]
    graph = sp.csr_array((np.ones(m.nnz), (rows, m.indices)),
                         shape=(mdp.n_states, mdp.n_states))
    return connected_components(graph, directed=True, connection="strong")[1]


def _cases() -> list[tuple[str, int]]:
    return ([("acyclic", s) for s in range(40)] + [("random", s) for s in range(25)]
            + [("large acyclic", s) for s in range(2)] + [("large", s) for s in range(2)])


def _make(kind: str, seed: int) -> MDP:
    if kind == "acyclic":
        return _acyclic(seed)
    if kind == "large acyclic":  # past SMALL: SciPy's walks, the reversed state graph
        return _acyclic(seed, 9000)
    n = 9000 if kind == "large" else int(np.random.default_rng(seed).integers(5, 70))
    return random_mdp(n, seed=4400 + seed, self_loop_fraction=0.25, target_fraction=0.1,
                      sink_fraction=0.1)


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize("with_extra", [False, True, "open"])
@pytest.mark.parametrize(("kind", "seed"), _cases())
def test_sets_against_fixed_points(kind: str, seed: int, sense: Sense,
                                   with_extra: bool | str) -> None:
    """``open``: a goal of states that move on (not absorbing, so paths run through
    them: a minimum's value-1 states are then searched through the maybe states only)."""
    mdp = _make(kind, seed)
    ch = _choices(mdp)
    n = mdp.n_states
    goal = np.asarray(mdp.target, dtype=bool)
    extra = np.zeros(n, dtype=bool)
    if with_extra == "open":
        goal = np.random.default_rng(seed).random(n) < 0.2
        goal[mdp.initial] = False
    elif with_extra:  # truncated states are absorbing, as a product's are
        g = np.asarray(mdp.row_groups)
        alone = [s for s in range(n) if g[s + 1] - g[s] == 1 and ch[s] == [{s}]]
        extra[[s for s in alone if np.random.default_rng(seed + s).random() < 0.5]] = True
        extra &= ~goal
    low, high = analyse(mdp, goal, extra, sense=sense)
    scc = _scc(mdp)
    for q, tmask in ((low, goal), (high, goal | extra)):
        target = set(np.flatnonzero(tmask).tolist())
        if sense is Sense.MAX:
            zero = set(range(n)) - _reach(ch, target, set(range(n)))
            one = _prob1e(ch, target)
        else:
            zero = _prob0e(ch, target)
            one = _prob1a(ch, target)
        assert set(np.flatnonzero(q.prob0).tolist()) == zero
        assert set(np.flatnonzero(q.qualitative.zero).tolist()) == zero
        assert set(np.flatnonzero(q.qualitative.one).tolist()) == one
        # the product's components, as SciPy finds them
        assert _partition(np.asarray(q.layers[0])) == _partition(scc)
        # the block order: a layering of the quotient's own graph
        qm = sp.csr_array(q.matrix)
        k = q.row_groups.shape[0] - 1
        if k:
            owner = np.repeat(np.arange(k), np.diff(q.row_groups))
            src = owner[np.repeat(np.arange(qm.shape[0]), np.diff(qm.indptr))]
            graph = sp.csr_array((np.ones(qm.nnz), (src, qm.indices)), shape=(k, k))
            _, qlab = connected_components(graph, directed=True, connection="strong")
            comp = np.asarray(q.order.component)
            # a block is a union of the quotient's components (a product component
            # whose paths ran through removed states stays one block)
            assert all(len({int(comp[s]) for s in part}) == 1
                       for part in _partition(qlab))
            lv = np.asarray(q.order.level)[comp]
            cross = comp[src] != comp[qm.indices]
            assert np.all(lv[src][cross] > lv[qm.indices][cross])
    if sense is Sense.MAX:  # the end components of the upper model's maybe states
        wide = set(np.flatnonzero(goal | extra).tolist())
        maybe = _reach(ch, wide, set(range(n))) - wide
        want, _ = _mecs(mdp, ch, maybe)
        got = _partition(np.asarray(high.mecs.mec_of), np.asarray(high.mecs.mec_of) >= 0)
        # those left in the quotient (the value-1 ones leave it): some of them, whole
        assert got <= set(want)

@pytest.mark.parametrize(("kind", "seed"), _cases())
def test_end_components_against_rounds(kind: str, seed: int) -> None:
    """The analysis's end components of the maybe states (acyclic: the shortcut)
    against de Alfaro's rounds written here, numbered by their least state."""
    mdp = _make(kind, seed)
    ch = _choices(mdp)
    m = sp.csr_array(mdp.matrix)
    goal = np.asarray(mdp.target, dtype=bool)
    found = state_components(m, mdp.row_groups, goal[:, None])
    maybe = found.reach[found.component][:, 0] & ~goal
    got = end_components(mdp, found.component, maybe)
    want, inside = _mecs(mdp, ch, set(np.flatnonzero(maybe).tolist()))
    mec_of = np.asarray(got.mec_of)
    assert got.n_mecs == len(want)
    assert _partition(mec_of, mec_of >= 0) == set(want)
    assert set(np.flatnonzero(got.internal).tolist()) == inside
    least = [min(np.flatnonzero(mec_of == i)) for i in range(got.n_mecs)]
    assert least == sorted(least)
    plain = maximal_end_components(mdp, maybe)  # the package's general search
    assert np.array_equal(np.asarray(plain.internal), np.asarray(got.internal))
    assert _partition(np.asarray(plain.mec_of), np.asarray(plain.mec_of) >= 0) == set(want)


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize("with_extra", [False, True, "open"])
@pytest.mark.parametrize(("kind", "seed"), [("large acyclic", 0), ("large", 0),
                                             ("acyclic", 3), ("random", 3)])
def test_quotients_as_the_searches_replaced(kind: str, seed: int, sense: Sense,
                                            with_extra: bool | str,
                                            monkeypatch: pytest.MonkeyPatch) -> None:
    """Every array of both quotients the same to the bit as with the searches the
    analysis replaced, still in the package: the reach from the condensation
    (``state_components``, no reversed graph handed on, so a minimum's Prob1A searched
    through the maybe states) and the end components searched (``_searched``, every
    component a state of its own)."""
    import dataclasses

    from mitld_lp.solvers import analysis, analysis_ends

    mdp = _make(kind, seed)
    n = mdp.n_states
    goal = np.asarray(mdp.target, dtype=bool)
    extra = np.zeros(n, dtype=bool)
    if with_extra == "open":
        goal = np.random.default_rng(seed).random(n) < 0.2
        goal[mdp.initial] = False
    elif with_extra:
        g = np.asarray(mdp.row_groups)
        ch = _choices(mdp)
        extra[[s for s in range(n) if g[s + 1] - g[s] == 1 and ch[s] == [{s}]
               and s % 2]] = True
        extra &= ~goal
    new = analyse(mdp, goal, extra, sense=sense)

    def old_reach(m: sp.csr_array, groups: np.ndarray, seeds: np.ndarray):  # type: ignore[no-untyped-def]
        found = state_components(m, groups, seeds)
        return found, found.reach[found.component], None

    monkeypatch.setattr(analysis, "components_reaching", old_reach)
    monkeypatch.setattr(analysis_ends, "_self_loops_only",
                        lambda mdp, maybe: analysis_ends._searched(mdp, np.arange(mdp.n_states),
                                                                   maybe))
    old = analyse(mdp, goal, extra, sense=sense)

    def arrays(x: object, at: str = "") -> dict[str, object]:
        if isinstance(x, np.ndarray):
            return {at: (x.dtype.str, x.shape, x.tobytes())}
        if sp.issparse(x):
            x = sp.csr_array(x)
            return {f"{at}.{k}": arrays(getattr(x, k))[""] for k in ("data", "indices", "indptr")}
        if dataclasses.is_dataclass(x):
            return {k: v for f in dataclasses.fields(x)
                    for k, v in arrays(getattr(x, f.name), f"{at}.{f.name}").items()}
        if isinstance(x, (tuple, list)):
            return {k: v for i, y in enumerate(x) for k, v in arrays(y, f"{at}[{i}]").items()}
        if isinstance(x, dict):
            return {k: v for key, y in x.items() for k, v in arrays(y, f"{at}{{{key}}}").items()}
        if hasattr(x, "__slots__") and not isinstance(x, (int, float, str)):
            return {k: v for name in x.__slots__
                    for k, v in arrays(getattr(x, name), f"{at}.{name}").items()}
        return {at: repr(x)}

    for a, b in zip(new, old, strict=True):
        got, want = arrays(a), arrays(b)
        assert got.keys() == want.keys()
        assert [k for k in got if got[k] != want[k]] == []
