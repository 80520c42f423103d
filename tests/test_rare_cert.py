"""The certificate's graph walks after the rare-cert changes: ``graph.Reversed`` (now
``solvers/reach.py``) reverses its edges by SciPy's compiled CSR->CSC transpose, a
counting sort, instead of a stable argsort.  Against an independent reversal (NumPy's
stable argsort of the heads, written here) on random edge lists, sorted and unsorted
sources, int32 and int64, the arrays byte for byte; its searches against a fixed point
over Python sets; and a rare PRISM model's certified bracket against Storm's exact
engine, the same bits with SciPy's routine and without it, with the compiled walks and
without."""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
import test_rare_solve as rare

from mitld_lp.solvers import graph, reach

needs_storm = rare.needs_storm
walks = rare.walks  # the fixture: ``walks(True)`` every graph walk compiled, else none


def _argsorted(n: int, source: np.ndarray, succ: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The edges ``source -> succ`` grouped by head, each head's sources in the edges'
    order (NumPy's stable argsort), and each head's start: the reversal Reversed held
    before, in its index type."""
    m = succ.size
    index = np.int32 if n + m < np.iinfo(np.int32).max else np.int64
    order = np.argsort(succ, kind="stable")
    starts = np.zeros(n + 1, dtype=index)
    for h in succ.tolist():  # heads counted one by one, not by bincount
        starts[h + 1] += 1
    return np.asarray(source[order], dtype=index), np.cumsum(starts).astype(index)


def _closure(source: np.ndarray, succ: np.ndarray, seeds: np.ndarray) -> set[int]:
    """The states with a path to a seed: a search over Python dicts of predecessors."""
    preds: dict[int, list[int]] = {}
    for a, b in zip(source.tolist(), succ.tolist(), strict=True):
        preds.setdefault(b, []).append(a)
    todo = np.flatnonzero(seeds).tolist()
    seen = set(todo)
    while todo:
        for a in preds.get(todo.pop(), []):
            if a not in seen:
                seen.add(a)
                todo.append(a)
    return seen


@pytest.mark.parametrize("dtype", [np.int32, np.int64])
@pytest.mark.parametrize("sorted_sources", [True, False])
@pytest.mark.parametrize("scipy_routine", [True, False])
def test_reversed_is_the_stable_argsort_byte_for_byte(monkeypatch, dtype, sorted_sources,
                                                      scipy_routine) -> None:
    if not scipy_routine:  # a SciPy without the compiled transpose: the argsort
        monkeypatch.setattr(reach, "sparsetools", None)
    rng = np.random.default_rng(11)
    for trial in range(60):
        n = int(rng.integers(1, 40))
        m = int(rng.integers(0, 150)) if trial else 0
        source = rng.integers(0, n, m).astype(dtype)
        succ = rng.integers(0, n, m).astype(dtype)
        if sorted_sources:
            source = np.sort(source)
        # repeated edges and self-loops now and then (a chain's rows have both)
        if m > 2:
            succ[1], source[1] = succ[0], source[0]
            if sorted_sources:
                succ[2] = source[2]
        got = graph.Reversed(n, source, succ)
        want_indices, want_ptr = _argsorted(n, source, succ)
        assert got.indices.dtype == want_indices.dtype
        assert got.indices[:m].tobytes() == want_indices.tobytes()
        assert got.indptr[:n + 1].tobytes() == want_ptr.tobytes()
        for _ in range(3):  # several searches from one reversal
            seeds = rng.random(n) < 0.2
            found = got.reaching(seeds)
            assert set(np.flatnonzero(found).tolist()) == _closure(source, succ, seeds)


def test_reversed_keeps_the_edges_it_is_handed() -> None:
    """The reversal reads its sources and heads, never writes them (the certificate's
    chain keeps its edges for the values after the two searches)."""
    rng = np.random.default_rng(5)
    for sort in (True, False):
        source = rng.integers(0, 30, 200).astype(np.int32)
        if sort:
            source.sort()
        succ = rng.integers(0, 30, 200).astype(np.int32)
        kept = source.copy(), succ.copy()
        graph.Reversed(30, source, succ)
        assert np.array_equal(source, kept[0]) and np.array_equal(succ, kept[1])


# ------------------------------------------------------------------ a rare PRISM model
#: Two stations each climb three stages by bold or careful tries; a try may fall back
#: to its station's start (cycles among the undecided states) or fail everything for
#: good.  "hit": both at the top: Pmax about 1e-6, Pmin about 6e-7.
STATIONS = """mdp
module m
  x : [0..3] init 0;
  y : [0..3] init 0;
  f : bool init false;
  [bx] !f & x<3 -> 0.001 : (x'=x+1) + 0.99 : (x'=0) + 0.009 : (f'=true);
  [cx] !f & x<3 -> 0.0004 : (x'=x+1) + 0.9956 : (x'=0) + 0.004 : (f'=true);
  [by] !f & y<3 -> 0.0012 : (y'=y+1) + 0.9878 : (y'=0) + 0.011 : (f'=true);
  [cy] !f & y<3 -> 0.0005 : (y'=y+1) + 0.9945 : (y'=0) + 0.005 : (f'=true);
  [end] f | (x=3 & y=3) -> true;
endmodule
label "hit" = x=3 & y=3 & !f;
"""


@needs_storm
@pytest.mark.parametrize("objective", ["max", "min"])
def test_a_rare_models_bracket_holds_storms_exact_value(tmp_path: Path, walks, monkeypatch,
                                                        objective: str) -> None:
    from storm_exact import storm_rational

    from mitld_lp import load_model, synthesize

    path = rare._model_file(tmp_path, STATIONS, objective)
    exact = storm_rational(tmp_path / "m.prism", f'P{objective}=? [F "hit"]')
    assert 0 < exact < Fraction(1, 10**5)  # a rare event, not a graph-decided value
    got = []
    for compiled in (True, False):
        walks(compiled)
        for routine in (reach.sparsetools, None):  # SciPy's transpose, then the argsort
            monkeypatch.setattr(reach, "sparsetools", routine)
            r = synthesize(load_model(path))
            assert r.certified, r.failed_checks
            assert Fraction(r.lower) <= exact <= Fraction(r.upper)
            got.append((r.lower.hex(), r.upper.hex()))
    assert len(set(got)) == 1, got  # the same bits every way
