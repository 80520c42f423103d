"""The analysis's qualitative sets and end components after the rare-event changes
(one attractor pass in place of de Alfaro's rounds where it shows there is no end
component; the state graph in the matrix's index type; the certificate's rows summed
in place), against fixed points written here in plain Python on random MDPs, and a
rare PRISM model's certified bracket against Storm's exact engine, with the compiled
walks and without."""

from __future__ import annotations

import importlib.util
import sys
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.mdp import MDP
from mitld_lp.solvers import walks as walks_module
from mitld_lp.solvers.analysis import analyse
from mitld_lp.solvers.graph import Sense

needs_storm = pytest.mark.skipif(importlib.util.find_spec("stormpy") is None,
                                 reason="needs stormpy: pip install -e '.[prism]'")


@pytest.fixture
def walks(monkeypatch):
    """``walks(True)``: every graph walk compiled (numba); ``walks(False)``: none."""
    def use(compiled: bool) -> None:
        if compiled:
            pytest.importorskip("numba")
        low = 0 if compiled else sys.maxsize
        monkeypatch.setattr(walks_module, "COMPILED_MIN_ENTRIES", low)
        monkeypatch.setattr(walks_module, "COMPILED_LOADED_MIN_ENTRIES", low)
    return use


# ------------------------------------------------------------------ random MDPs
def random_mdp(seed: int) -> tuple[MDP, list[list[set[int]]], np.ndarray, np.ndarray]:
    """An MDP of 3-25 states, each with 1-3 choices of 1-3 successors (weights 1/k),
    now and then a choice that stays put or one into a small cycle (end components
    among the undecided states, and none).  Returned with its choices as Python sets
    of successors per state, a goal (any states: an accepting component's are not
    absorbing) and an extra set (a truncation's states: absorbing, a self-loop each,
    as a product makes them)."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(3, 26))
    goal = rng.random(n) < 0.15
    goal[int(rng.integers(0, n))] = True
    extra = (rng.random(n) < 0.1) & ~goal
    choices: list[list[set[int]]] = []
    for s in range(n):
        if extra[s]:
            choices.append([{s}])
            continue
        mine = []
        for _ in range(int(rng.integers(1, 4))):
            r = rng.random()
            succ = ({s} if r < 0.12 else {s, (s + 1) % n} if r < 0.25
                    else set(rng.integers(0, n, int(rng.integers(1, 4))).tolist()))
            mine.append(succ)
        choices.append(mine)
    rows = [sorted(c) for mine in choices for c in mine]
    groups = np.cumsum([0] + [len(mine) for mine in choices]).astype(np.int64)
    ptr = np.cumsum([0] + [len(r) for r in rows])
    cols = np.array([t for r in rows for t in r], dtype=np.int32)
    data = np.concatenate([np.full(len(r), 1.0 / len(r)) for r in rows])
    matrix = sp.csr_array((data, cols, ptr.astype(np.int32)), shape=(len(rows), n))
    mdp = MDP(matrix=matrix, row_groups=groups,
              choice_actions=np.zeros(len(rows), dtype=np.int32), action_names=("a",),
              initial=0, target=np.zeros(n, dtype=bool), sink=np.zeros(n, dtype=bool),
              truncated=extra.copy(), states=list(range(n)))
    return mdp, choices, goal, extra


def some_path(choices: list[list[set[int]]], target: set[int]) -> set[int]:
    """The states with a path to ``target`` (a fixed point over sets)."""
    inside = set(target)
    grew = True
    while grew:
        grew = False
        for s, mine in enumerate(choices):
            if s not in inside and any(c & inside for c in mine):
                inside.add(s)
                grew = True
    return inside


def prob1_e(choices: list[list[set[int]]], target: set[int]) -> set[int]:
    """``Prob1E``: nu R. mu Y. target | {s | some choice c: post(c) <= R, post(c) & Y}."""
    big = set(range(len(choices)))
    while True:
        small = set(target)
        grew = True
        while grew:
            grew = False
            for s, mine in enumerate(choices):
                if s not in small and any(c <= big and c & small for c in mine):
                    small.add(s)
                    grew = True
        if small == big:
            return big
        big = small


def prob0_e(choices: list[list[set[int]]], target: set[int]) -> set[int]:
    """``Prob0E``: nu Z. not target & {s | some choice c: post(c) <= Z}."""
    z = set(range(len(choices))) - target
    while True:
        keep = {s for s in z if any(c <= z for c in choices[s])}
        if keep == z:
            return z
        z = keep


def reach_avoiding(choices: list[list[set[int]]], seeds: set[int],
                   avoid: set[int]) -> set[int]:
    """The states with a path to ``seeds`` that visits no ``avoid`` state before."""
    inside = set(seeds)
    grew = True
    while grew:
        grew = False
        for s, mine in enumerate(choices):
            if s not in inside and s not in avoid and any(c & inside for c in mine):
                inside.add(s)
                grew = True
    return inside


def end_components(choices: list[list[set[int]]], states: set[int]) -> list[set[int]]:
    """The maximal end components among ``states`` by the textbook rounds, their
    strongly connected parts by mutual reachability (sets, no library)."""
    alive = set(states)
    allowed = {s: [c for c in choices[s] if c <= alive] for s in alive}
    while True:
        alive = {s for s in alive if allowed[s]}
        allowed = {s: [c for c in allowed[s] if c <= alive] for s in alive}
        succ = {s: set().union(*allowed[s]) if allowed[s] else set() for s in alive}
        reach = {}
        for s in alive:  # the states reachable from s along the allowed choices
            seen, todo = {s}, [s]
            while todo:
                for t in succ[todo.pop()]:
                    if t not in seen:
                        seen.add(t)
                        todo.append(t)
            reach[s] = seen
        part = {s: frozenset(t for t in reach[s] if s in reach[t]) for s in alive}
        new = {s: [c for c in allowed[s] if c <= part[s]] for s in alive}
        if new == allowed and all(new[s] for s in alive):
            return sorted({part[s] for s in alive}, key=min)
        allowed = new


@pytest.mark.parametrize("compiled", [True, False])
def test_qualitative_sets_and_end_components_are_the_fixed_points(walks, compiled) -> None:
    walks(compiled)
    seen_none = seen_some = 0
    for seed in range(60):
        mdp, choices, goal, extra = random_mdp(seed)
        n = mdp.n_states
        for sense in (Sense.MAX, Sense.MIN):
            models = analyse(mdp, goal, extra, sense=sense)
            for target_mask, q in zip((goal, goal | extra), models, strict=True):
                target = set(np.flatnonzero(target_mask).tolist())
                dec = q.qualitative
                if sense is Sense.MAX:
                    zero = set(range(n)) - some_path(choices, target)
                    one = prob1_e(choices, target)
                else:
                    zero = prob0_e(choices, target)
                    one = set(range(n)) - reach_avoiding(choices, zero, target)
                assert set(np.flatnonzero(dec.zero).tolist()) == zero, (seed, sense)
                assert set(np.flatnonzero(dec.one).tolist()) == one, (seed, sense)
                no_path = set(range(n)) - some_path(choices, target)
                assert set(np.flatnonzero(dec.unreachable).tolist()) == no_path
            if sense is Sense.MIN:
                assert models[0].mecs.n_mecs == 0
                continue
            # the end components collapsed: those of the upper model's maybe states less
            # the goal's value-1 states (they leave the quotient, their components whole)
            wide = set(np.flatnonzero(goal | extra).tolist())
            maybe = some_path(choices, wide) - wide \
                - prob1_e(choices, set(np.flatnonzero(goal).tolist()))
            want = end_components(choices, maybe)
            mec_of = np.asarray(models[1].mecs.mec_of)
            got = sorted(({int(s) for s in np.flatnonzero(mec_of == k)}
                          for k in range(models[1].mecs.n_mecs)), key=min)
            assert got == want, (seed, got, want)
            assert models[0].mecs is models[1].mecs
            internal = np.asarray(models[1].mecs.internal)
            for s in range(n):  # a choice is internal iff it stays in its state's MEC
                for i, c in enumerate(choices[s]):
                    stays = bool(mec_of[s] >= 0) and all(mec_of[t] == mec_of[s] for t in c)
                    assert internal[int(mdp.row_groups[s]) + i] == stays, (seed, s, i)
            seen_none += not want
            seen_some += bool(want)
    assert seen_none >= 5 and seen_some >= 5  # both kinds of product were met


def test_the_attractor_pass_decides_no_end_component_alone(walks, monkeypatch) -> None:
    """On the compiled walks, a product whose maybe states hold no end component is
    decided by the attractor pass: de Alfaro's rounds are not run; one with an end
    component still runs them."""
    walks(True)
    from mitld_lp.solvers import analysis_ends
    from mitld_lp.solvers import graph as graph_module

    rounds = []
    real = graph_module.compiled_end_components

    def counted(*args, **kwargs):
        rounds.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(analysis_ends, "compiled_end_components", counted)
    # a ring 0 -> 1 -> 2 -> 0 that leaks to the goal 3 and the sink 4 from every state
    ring = [[{1, 3, 4}], [{2, 4}], [{0, 4}], [{3}], [{4}]]
    mdp = _mdp(ring, goal=3)
    q = analyse(mdp, mdp.target, sense=Sense.MAX)[0]
    assert q.mecs.n_mecs == 0 and rounds == []
    # state 1 may also stay put: {1} is an end component among the maybe states
    ring[1].append({1})
    mdp = _mdp(ring, goal=3)
    q = analyse(mdp, mdp.target, sense=Sense.MAX)[0]
    assert q.mecs.n_mecs == 1 and rounds == [1]
    assert np.flatnonzero(np.asarray(q.mecs.mec_of) >= 0).tolist() == [1]


def _mdp(choices: list[list[set[int]]], goal: int) -> MDP:
    rows = [sorted(c) for mine in choices for c in mine]
    n = len(choices)
    ptr = np.cumsum([0] + [len(r) for r in rows]).astype(np.int32)
    matrix = sp.csr_array((np.concatenate([np.full(len(r), 1.0 / len(r)) for r in rows]),
                           np.array([t for r in rows for t in r], dtype=np.int32), ptr),
                          shape=(len(rows), n))
    target = np.zeros(n, dtype=bool)
    target[goal] = True
    return MDP(matrix=matrix,
               row_groups=np.cumsum([0] + [len(m) for m in choices]).astype(np.int64),
               choice_actions=np.zeros(len(rows), dtype=np.int32), action_names=("a",),
               initial=0, target=target, sink=np.zeros(n, dtype=bool),
               truncated=np.zeros(n, dtype=bool), states=list(range(n)))


# ------------------------------------------------------------------ a rare PRISM model
#: Four stages climbed by two kinds of try, each of which may fall back to the start
#: (retries: cycles, no end component) or fail for good; ``wait`` (stage 1 <-> 2) an
#: end component among the undecided states in the second program.  Pmax ~ 1e-5.
RETRY = """mdp
module m
  s : [0..5] init 0;
  [a] s<4 -> 0.001 : (s'=s+1) + 0.99 : (s'=0) + 0.009 : (s'=5);
  [b] s<4 -> 0.0004 : (s'=s+1) + 0.9956 : (s'=0) + 0.004 : (s'=5);
  [end] s>=4 -> true;
endmodule
label "hit" = s=4;
"""
WAITING = RETRY.replace("  [end]", "  [wait] s=1 -> (s'=2);\n  [wait] s=2 -> (s'=1);\n"
                        "  [end]")


def _model_file(tmp_path: Path, prism: str, objective: str) -> Path:
    (tmp_path / "m.prism").write_text(prism)
    path = tmp_path / f"m_{objective}.toml"
    path.write_text(f'name = "m"\nspec = "F hit"\nobjective = "{objective}"\n\n'
                    '[prism]\nfile = "m.prism"\n')
    return path


@needs_storm
@pytest.mark.parametrize(("prism", "objective"), [(RETRY, "max"), (RETRY, "min"),
                                                  (WAITING, "max")])
def test_a_rare_models_bracket_holds_storms_exact_value(tmp_path, walks, prism,
                                                        objective) -> None:
    from storm_exact import storm_rational

    from mitld_lp import load_model, synthesize

    (tmp_path / "storm.prism").write_text(prism)
    exact = storm_rational(tmp_path / "storm.prism", f'P{objective}=? [F "hit"]')
    assert 0 < exact < Fraction(1, 10**4)  # a rare event, not a graph-decided value
    path = _model_file(tmp_path, prism, objective)
    got = []
    for compiled in (True, False):
        walks(compiled)
        r = synthesize(load_model(path))
        assert r.certified, r.failed_checks
        assert Fraction(r.lower) <= exact <= Fraction(r.upper)
        assert Fraction(r.upper) - Fraction(r.lower) <= exact / 10**6
        got.append((r.lower, r.upper))
    assert got[0] == got[1]  # the compiled walks and NumPy's: the same bits


def test_backward_reachable_on_int64_edges_is_the_closure(walks) -> None:
    """The compiled reach along a list of edges, handed int64 edges (cast to int32 for
    the kernel) and int32 ones, against a fixed point over sets."""
    walks(True)
    from mitld_lp.solvers.graph import backward_reachable

    rng = np.random.default_rng(3)
    for _ in range(20):
        n, m = int(rng.integers(2, 30)), int(rng.integers(0, 60))
        source, succ = rng.integers(0, n, m), rng.integers(0, n, m)
        seeds = rng.random(n) < 0.2
        inside = set(np.flatnonzero(seeds).tolist())
        grew = True
        while grew:
            grew = False
            for a, b in zip(source.tolist(), succ.tolist(), strict=True):
                if b in inside and a not in inside:
                    inside.add(a)
                    grew = True
        for dtype in (np.int64, np.int32):
            got = backward_reachable(n, source.astype(dtype), succ.astype(dtype), seeds)
            assert set(np.flatnonzero(got).tolist()) == inside
