"""What the plain route's solve of both truncation models (``routes.plain.solve_models``,
the sensed route's too) releases: the heap's freed pages handed back once before the
analysis for a product at or above ``TRIM_FROM_TRANSITIONS`` (every route that solves
through it, the sensed information states included), and a minimum's end-component map
(an index a state, which its certificate never reads) not held through the
certificates.  With the release on, the answers bracket the optimum computed here in
exact rational arithmetic (value iteration over every deterministic policy's chain,
each chain solved with Fractions by Gaussian elimination, written here)."""

from __future__ import annotations

import gc
import itertools
import time
import weakref
from dataclasses import replace
from fractions import Fraction

import numpy as np
import pytest

from mitld_lp.problem import Settings
from mitld_lp.routes import plain
from mitld_lp.routes.acceptance import Acceptance
from mitld_lp.testing import random_mdp


def _solve_exact(rows: list[dict[int, Fraction]], goal: list[bool]) -> list[Fraction]:
    """Reach probabilities of ``goal`` in the chain ``rows`` (sparse, in Fractions): 0
    where the goal is unreachable (a graph search), else the linear system on the rest
    by Gaussian elimination."""
    n = len(rows)
    can = list(goal)
    changed = True
    while changed:
        changed = False
        for s in range(n):
            if not can[s] and any(can[t] for t in rows[s]):
                can[s] = changed = True
    rest = [s for s in range(n) if can[s] and not goal[s]]
    at = {s: i for i, s in enumerate(rest)}
    m = len(rest)
    a = [[Fraction(0)] * (m + 1) for _ in range(m)]
    for i, s in enumerate(rest):
        a[i][i] += 1
        for t, p in rows[s].items():
            if goal[t]:
                a[i][m] += p
            elif t in at:
                a[i][at[t]] -= p
    for c in range(m):  # Gauss-Jordan, exact
        pivot = next(r for r in range(c, m) if a[r][c] != 0)
        a[c], a[pivot] = a[pivot], a[c]
        lead = a[c][c]
        a[c] = [v / lead for v in a[c]]
        for r in range(m):
            if r != c and a[r][c] != 0:
                f = a[r][c]
                a[r] = [v - f * w for v, w in zip(a[r], a[c], strict=True)]
    x = [Fraction(1) if goal[s] else Fraction(0) for s in range(n)]
    for i, s in enumerate(rest):
        x[s] = a[i][m]
    return x


def _optimum(mdp, goal: np.ndarray, sense: str) -> list[Fraction]:
    """The optimum of reaching ``goal`` from every state over every deterministic
    memoryless policy (they suffice for reachability), in Fractions from the floats'
    exact values, each
    row divided by its sum (the floats sum to 1 only within their rounding, which the
    certificate's allowance covers: compared within :data:`SLACK`)."""
    m = mdp.matrix.tocsr()
    groups = np.asarray(mdp.row_groups)
    n = groups.size - 1
    rows = []
    for c in range(m.shape[0]):
        row = {int(t): Fraction(float(p)) for t, p in
               zip(m.indices[m.indptr[c]:m.indptr[c + 1]],
                   m.data[m.indptr[c]:m.indptr[c + 1]], strict=True)}
        total = sum(row.values())  # a distribution: the floats' rounding taken out
        rows.append({t: p / total for t, p in row.items()})
    pick = max if sense == "max" else min
    best: list[Fraction] | None = None
    for choice in itertools.product(*[range(groups[s], groups[s + 1]) for s in range(n)]):
        x = _solve_exact([rows[c] for c in choice], [bool(g) for g in goal])
        best = x if best is None else [pick(a, b) for a, b in zip(best, x, strict=True)]
    assert best is not None
    return best


#: Far above a row's rounding (about 1e-16 a row here), far below any gap between a
#: wrong bound and the optimum.
SLACK = Fraction(1, 10**12)


def _tiny(seed: int):
    mdp = random_mdp(8, seed=seed, max_choices=2, max_successors=3, target_fraction=0.15,
                     sink_fraction=0.2, self_loop_fraction=0.2)
    sink = np.asarray(mdp.sink).copy()
    cut = sink & (np.arange(sink.size) % 2 == 0)  # some sinks truncated: two models
    if cut.any():
        mdp = replace(mdp, sink=sink & ~cut, truncated=cut)
    return mdp


@pytest.mark.parametrize("sense", ["max", "min"])
@pytest.mark.parametrize("seed", range(4))
def test_released_solve_brackets_the_exact_optimum(monkeypatch, seed: int,
                                                   sense: str) -> None:
    trims: list[int] = []
    monkeypatch.setattr(plain, "TRIM_FROM_TRANSITIONS", 0)  # every product is "large"
    monkeypatch.setattr(plain, "release_free_memory", lambda: trims.append(1) or True)
    mdp = _tiny(seed)
    first, second = plain.solve_models(mdp, Acceptance(np.asarray(mdp.target), None),
                                       Settings(), time.perf_counter(), sense)
    assert trims == [1]  # the builder's holes handed back once, before the analysis
    target, truncated = np.asarray(mdp.target), np.asarray(mdp.truncated)
    init = int(mdp.initial)
    for sol in {id(first): first, id(second): second}.values():
        goal = target | truncated if sol.which == "upper" else target
        want = _optimum(mdp, goal, sense)[init]
        lo, hi = sol.bounds
        side = 0 if sense == "max" else 1  # the side that bounds the policy's value
        assert sol.certified
        assert Fraction(lo) <= want + SLACK, (sol.which, lo, want)
        assert Fraction(hi) >= want - SLACK, (sol.which, hi, want)
        assert not np.isnan(sol.bounds[side])


def test_below_the_threshold_nothing_is_trimmed(monkeypatch) -> None:
    trims: list[int] = []
    monkeypatch.setattr(plain, "release_free_memory", lambda: trims.append(1) or True)
    mdp = _tiny(0)
    assert mdp.n_transitions < plain.TRIM_FROM_TRANSITIONS
    plain.solve_models(mdp, Acceptance(np.asarray(mdp.target), None), Settings(),
                       time.perf_counter(), "max")
    assert trims == []


@pytest.mark.parametrize("sense, released", [("min", True), ("max", False)])
def test_minimum_end_component_map_is_not_held_through_certificates(
        monkeypatch, sense: str, released: bool) -> None:
    import mitld_lp.solvers.certify as certify_module

    refs: list[weakref.ref] = []
    real_analyse = __import__("mitld_lp.solvers.analysis", fromlist=["analyse"]).analyse

    def analyse(*args, **kwargs):
        quotients = real_analyse(*args, **kwargs)
        refs.extend(weakref.ref(q.mecs.mec_of) for q in quotients)
        return quotients

    alive_at_certificate: list[bool] = []
    real_certify = certify_module.certify

    def certify(*args, **kwargs):
        gc.collect()
        alive_at_certificate.append(any(r() is not None for r in refs))
        return real_certify(*args, **kwargs)

    monkeypatch.setattr("mitld_lp.solvers.analysis.analyse", analyse)
    monkeypatch.setattr(certify_module, "certify", certify)
    mdp = _tiny(2)
    plain.solve_models(mdp, Acceptance(np.asarray(mdp.target), None), Settings(),
                       time.perf_counter(), sense)
    assert alive_at_certificate  # the certificates ran
    assert refs
    # a minimum's map is gone by its certificates; a maximum's is read by them
    assert all(alive is not released for alive in alive_at_certificate)
