"""A minimum's staying strategy on its prob-0 states, recorded by the analysis from the
attractor that found them (:mod:`mitld_lp.solvers.analysis_staying`) and played by the
lift (:func:`~mitld_lp.solvers.quotient.lift_policy`) without its search through the rows.

Checked against routes written here:

* :func:`first_unhit` against a plain loop over each state's choices;
* the analysis's record against ``Prob0E`` found as a greatest fixpoint (the states, not
  targets, with a choice whose whole support stays in the set, shrunk until stable: the
  dual of the attractor the analysis walks) and, per state of several choices, its first
  choice whose support lies in that set, read from Python sets of successors;
* the lifted policy with the record against the same policy with the record dropped
  (the lift's own search), the NumPy and the compiled routes, to the integer;
* the lift takes the record: with the search made to fail, the policy is still made.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.mdp import ABSORB, MDP
from mitld_lp.solvers import analysis, compiled_graph, graph, lift_kernels, quotient
from mitld_lp.solvers.analysis import analyse
from mitld_lp.solvers.analysis_staying import (
    STAYING_STRATEGY,
    first_unhit,
    recorded_staying,
)
from mitld_lp.solvers.graph import Sense


def _mdp(rng: np.random.Generator, n: int, zeros: bool = False
         ) -> tuple[MDP, np.ndarray, np.ndarray]:
    """``n`` states: absorbing goal, sink and truncated states (an ``ABSORB`` self-loop
    each), the others 1-4 choices of 1-3 successors near them, some a choice that only
    loops; ``zeros``: some entries stored as an explicit zero (no edge)."""
    kind = rng.choice(4, n, p=[0.88, 0.04, 0.05, 0.03])  # plain, goal, sink, truncated
    kind[0] = 0
    # per state its choices, each an action and a list of (successor, probability)
    states: list[list[tuple[int, list[tuple[int, float]]]]] = []
    for s in range(n):
        if kind[s]:
            states.append([(ABSORB, [(s, 1.0)])])
            continue
        mine = []
        for a in range(int(rng.integers(1, 5))):
            k = int(rng.integers(1, 4))
            ts = [s] if rng.random() < 0.15 else \
                sorted({int((s + d) % n) for d in rng.integers(-5, 9, k)})
            row = [(t, 1.0 / len(ts)) for t in ts]
            if zeros and rng.random() < 0.2:  # a stored zero toward a further state
                row.append((int((s + 11) % n), 0.0))
            mine.append((a, row))
        states.append(mine)
    flat = [ch for mine in states for ch in mine]
    c = len(flat)
    rows = [r for r, (_, row) in enumerate(flat) for _ in row]
    cols = [t for _, row in flat for t, _ in row]
    vals = [p for _, row in flat for _, p in row]
    actions = [a for a, _ in flat]
    groups = np.concatenate([[0], np.cumsum([len(mine) for mine in states])])
    matrix = sp.csr_array((vals, (rows, cols)), shape=(c, n))  # sums duplicates
    matrix.indices = matrix.indices.astype(np.int32)
    matrix.indptr = matrix.indptr.astype(np.int32)
    goal, extra = kind == 1, kind == 3
    mdp = MDP(matrix=matrix, row_groups=np.array(groups, dtype=np.int64),
              choice_actions=np.array(actions, dtype=np.int32),
              action_names=("a", "b", "c", "d"), initial=0, target=goal | extra,
              sink=kind == 2, truncated=extra, states=range(n))
    return mdp, goal, extra


def _support(mdp: MDP) -> list[set[int]]:
    """Each choice's successors of positive probability, as Python sets."""
    m = mdp.matrix.tocoo()
    out: list[set[int]] = [set() for _ in range(m.shape[0])]
    for r, t, v in zip(m.row.tolist(), m.col.tolist(), m.data.tolist(), strict=True):
        if v > 0:
            out[r].add(t)
    return out


def _prob0e(mdp: MDP, target: np.ndarray, post: list[set[int]]) -> set[int]:
    """``Prob0E`` as a greatest fixpoint: start from every non-target state, keep those
    with a choice whose whole support stays in the set, until nothing leaves."""
    groups = mdp.row_groups.tolist()
    z = {s for s in range(mdp.n_states) if not target[s]}
    while True:
        keep = {s for s in z if any(post[c] <= z for c in range(groups[s], groups[s + 1]))}
        if keep == z:
            return z
        z = keep


def _expected(mdp: MDP, zero: set[int], post: list[set[int]]) -> tuple[list[int], list[int]]:
    """The states of ``zero`` whose first choice leaves ``zero``, and each one's first
    choice whose support stays in ``zero``."""
    groups = mdp.row_groups.tolist()
    states, choices = [], []
    for s in sorted(zero):
        stay = [c for c in range(groups[s], groups[s + 1]) if post[c] <= zero]
        if stay and stay[0] != groups[s]:
            states.append(s)
            choices.append(stay[0])
    return states, choices


def test_first_unhit_against_a_loop() -> None:
    rng = np.random.default_rng(86)
    for _ in range(30):
        n = int(rng.integers(1, 40))
        counts = rng.integers(0, 5, n)
        groups = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        hit = rng.random(int(groups[-1])) < 0.6
        zero = rng.random(n) < 0.5
        for s in range(n):  # every state of zero with a choice keeps one unhit
            if zero[s] and counts[s] and hit[groups[s]:groups[s + 1]].all():
                hit[groups[s + 1] - 1] = False
        got = first_unhit(groups, zero, hit)
        want_s, want_c = [], []
        for s in range(n):
            unhit = [c for c in range(groups[s], groups[s + 1]) if not hit[c]]
            if zero[s] and unhit and unhit[0] != groups[s]:
                want_s.append(s)
                want_c.append(unhit[0])
        assert got.states.tolist() == want_s
        assert got.choices.tolist() == want_c
        assert got.states.dtype == np.int32 and got.choices.dtype == np.int32


def test_first_unhit_refuses_a_state_with_every_choice_hit() -> None:
    groups = np.array([0, 2, 3], dtype=np.int64)
    with pytest.raises(ValueError):
        first_unhit(groups, np.array([True, False]), np.array([True, True, False]))


def _walks_compiled(monkeypatch: pytest.MonkeyPatch) -> None:
    """The attractors walked by the compiled walk whatever the size (two attractors then
    each give their hit choices)."""
    walks = SimpleNamespace(backward=compiled_graph.backward)
    monkeypatch.setattr(analysis, "attractor_walks", lambda entries: walks)
    monkeypatch.setattr(graph, "attractor_walks", lambda entries: walks)


@pytest.mark.parametrize("compiled", [False, True])
@pytest.mark.parametrize("seed", range(8))
def test_record_is_prob0e_first_staying(monkeypatch: pytest.MonkeyPatch, seed: int,
                                        compiled: bool) -> None:
    if compiled:
        _walks_compiled(monkeypatch)
    rng = np.random.default_rng(1000 + seed)
    mdp, goal, extra = _mdp(rng, int(rng.integers(30, 120)), zeros=seed % 2 == 1)
    post = _support(mdp)
    quotients = analyse(mdp, goal, extra=extra, sense=Sense.MIN)
    targets = [goal, goal | extra]
    for q, target in zip(quotients, targets, strict=True):
        zero = _prob0e(mdp, target, post)
        assert set(np.flatnonzero(q.prob0).tolist()) == zero
        played = recorded_staying(q.shared, q.prob0)
        assert played is not None
        states, choices = _expected(mdp, zero, post)
        assert played.states.tolist() == states
        assert played.choices.tolist() == choices


def _lifts(mdp: MDP, q, chosen: np.ndarray) -> np.ndarray:
    return quotient.lift_policy(mdp, q, chosen)


@pytest.mark.parametrize("route", ["numpy", "compiled"])
@pytest.mark.parametrize("seed", range(8))
def test_lift_with_record_equals_search(monkeypatch: pytest.MonkeyPatch, seed: int,
                                        route: str) -> None:
    _walks_compiled(monkeypatch)
    if route == "compiled":
        monkeypatch.setattr(quotient, "_lift_states_compiled", lambda *args: True)
        monkeypatch.setattr(lift_kernels, "lift_states_kernel",
                            lift_kernels.lift_states_kernel.py_func)
    else:
        monkeypatch.setattr(quotient, "_lift_states_compiled", lambda *args: False)
    rng = np.random.default_rng(2000 + seed)
    mdp, goal, extra = _mdp(rng, int(rng.integers(30, 120)), zeros=seed % 2 == 0)
    post = _support(mdp)
    for q in analyse(mdp, goal, extra=extra, sense=Sense.MIN):
        assert STAYING_STRATEGY in q.shared
        chosen = np.array([int(q.row_groups[r]) + int(rng.integers(0, max(1, int(
            q.row_groups[r + 1] - q.row_groups[r])))) for r in range(q.row_groups.size - 1)],
            dtype=np.int64)
        with_record = _lifts(mdp, q, chosen)
        kept = dict(q.shared)
        q.shared.pop(STAYING_STRATEGY)
        searched = _lifts(mdp, q, chosen)
        q.shared.update(kept)
        np.testing.assert_array_equal(with_record, searched)
        # every removed prob-0 state's choice stays among them (or is its only one);
        # a state kept for the other target plays the quotient's choice
        zero = set(np.flatnonzero(q.prob0).tolist())
        for s in np.flatnonzero(q.prob0 & (q.state_map < 0)).tolist():
            c = int(with_record[s])
            if c >= 0:
                assert post[c] <= zero or mdp.row_groups[s + 1] - mdp.row_groups[s] == 1


@pytest.mark.parametrize("route", ["numpy", "compiled"])
def test_lift_takes_the_record(monkeypatch: pytest.MonkeyPatch, route: str) -> None:
    rng = np.random.default_rng(77)
    mdp, goal, extra = _mdp(rng, 90)
    q = analyse(mdp, goal | extra, sense=Sense.MIN)[0]
    played = recorded_staying(q.shared, q.prob0)
    assert played is not None and played.states.size  # a prob-0 state of several choices
    want = quotient.lift_policy(mdp, q, np.zeros(q.row_groups.size - 1, dtype=np.int64)
                                + q.row_groups[:-1])

    def fail(*args, **kwargs):
        raise AssertionError("searched although recorded")

    monkeypatch.setattr(quotient, "staying_choices", fail)
    if route == "compiled":
        monkeypatch.setattr(quotient, "_lift_states_compiled", lambda *args: True)
        kernel = lift_kernels.lift_states_kernel.py_func

        def no_search(groups, indptr, indices, data, zero, search, *rest):
            assert not search
            return kernel(groups, indptr, indices, data, zero, search, *rest)

        monkeypatch.setattr(lift_kernels, "lift_states_kernel", no_search)
    else:
        monkeypatch.setattr(quotient, "_lift_states_compiled", lambda *args: False)
    got = quotient.lift_policy(mdp, q, q.row_groups[:-1].astype(np.int64))
    np.testing.assert_array_equal(got, want)
