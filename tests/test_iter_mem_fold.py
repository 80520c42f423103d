"""The plain route's solve of both truncation models (mitld_lp.routes.plain.solve_models)
with the lifted bounds held folded through the certificates: the iteration's bounds
bracket the optimum found by brute force over every deterministic policy (each
policy's chain solved with numpy, written here), the LP's values agree with it, and a
folded vector comes back to the bit and holds no reference to the array it replaced."""

from __future__ import annotations

import gc
import itertools
import time
import weakref
from dataclasses import replace

import numpy as np
import pytest

from mitld_lp.problem import Settings
from mitld_lp.routes import plain
from mitld_lp.routes.acceptance import Acceptance
from mitld_lp.routes.plain import _Folding, solve_models
from mitld_lp.solvers.analysis import analyse
from mitld_lp.solvers.graph import Sense
from mitld_lp.testing import random_mdp


def _reach(p: np.ndarray, goal: np.ndarray) -> np.ndarray:
    """Reach probabilities of ``goal`` in the chain ``p`` (dense): 0 where the goal is
    unreachable (graph search), else the linear system on the rest."""
    can = goal.copy()
    while True:
        more = can | ((p[:, can].sum(axis=1) > 0) & ~goal)
        if np.array_equal(more, can):
            break
        can = more
    x = np.where(goal, 1.0, 0.0)
    rest = can & ~goal
    idx = np.flatnonzero(rest)
    if idx.size:
        a = np.eye(idx.size) - p[np.ix_(idx, idx)]
        b = p[np.ix_(idx, np.flatnonzero(goal))].sum(axis=1)
        x[idx] = np.linalg.solve(a, b)
    return x


def _brute_force(mdp, goal: np.ndarray, sense: str) -> np.ndarray:
    """The optimum of reaching ``goal`` in every state, over every deterministic
    memoryless policy (they suffice for reachability), each chain solved densely."""
    dense = mdp.matrix.toarray()
    groups = np.asarray(mdp.row_groups)
    n = groups.size - 1
    best = None
    for pick in itertools.product(*[range(groups[s], groups[s + 1]) for s in range(n)]):
        x = _reach(dense[list(pick)], goal)
        best = x if best is None else (np.maximum(best, x) if sense == "max"
                                       else np.minimum(best, x))
    return best


def _tiny(seed: int, truncated: bool):
    mdp = random_mdp(9, seed=seed, max_choices=2, max_successors=3, target_fraction=0.15,
                     sink_fraction=0.2, self_loop_fraction=0.2)
    if truncated:  # some sinks made truncated: the two models differ
        sink = np.asarray(mdp.sink).copy()
        cut = sink & (np.arange(sink.size) % 2 == 0)
        if cut.any():
            mdp = replace(mdp, sink=sink & ~cut, truncated=cut)
    return mdp


@pytest.mark.parametrize("sense", ["max", "min"])
@pytest.mark.parametrize("seed", range(6))
def test_models_bracket_the_brute_force_optimum(seed: int, sense: str) -> None:
    mdp = _tiny(seed, truncated=seed % 2 == 1)
    first, second = solve_models(mdp, Acceptance(np.asarray(mdp.target), None),
                                 Settings(), time.perf_counter(), sense)
    truncated = np.asarray(mdp.truncated)
    low_goal = np.asarray(mdp.target)
    models = {id(first): first, id(second): second}.values()
    for sol in models:
        goal = low_goal | truncated if sol.which == "upper" else low_goal
        want = _brute_force(mdp, goal, sense)
        it = sol.iteration
        assert it.lower.shape == it.upper.shape == want.shape
        assert np.all(it.lower <= want + 1e-12), (sol.which, it.lower, want)
        assert np.all(want <= it.upper + 1e-12), (sol.which, it.upper, want)
        if sol.lp is not None and sol.lp.values is not None:
            reach = np.flatnonzero(sol.policy_values >= 0)
            np.testing.assert_allclose(sol.lp.values[reach], want[reach], atol=1e-6)
        assert sol.certified


def _quotient(seed: int):
    mdp = random_mdp(400, seed=seed, locality=6, sink_fraction=0.1,
                     self_loop_fraction=0.3)
    q, _ = analyse(mdp, np.asarray(mdp.target), sense=Sense.MAX)
    return mdp, q


@pytest.mark.parametrize("seed", range(4))
def test_fold_comes_back_to_the_bit_and_lets_the_array_go(seed: int) -> None:
    mdp, q = _quotient(seed)
    fold = _Folding.of(q)
    rng = np.random.default_rng(seed)
    assert 0 < q.n_states < mdp.n_states  # states removed: folding pays
    # a lifted vector, with a few entries the lift would not give (patched back)
    x = np.asarray(q.lift(rng.random(q.n_states)), dtype=np.float64).copy()
    odd = rng.choice(x.size, size=5, replace=False)
    x[odd] = -rng.random(5)
    x[odd[0]] = -0.0  # told from 0.0 by its bits
    want = x.copy()
    ref = weakref.ref(x)
    folded = fold.fold(x)
    del x
    gc.collect()
    assert folded.whole is None
    assert ref() is None  # the folded record holds no reference to the lifted array
    got = folded.unfold()
    assert got.dtype == want.dtype
    np.testing.assert_array_equal(got.view(np.uint64), want.view(np.uint64))
    # a vector no quotient values give is kept whole (folding would not be smaller)
    noise = rng.random(mdp.n_states)
    kept = fold.fold(noise)
    assert kept.whole is noise


def test_held_records_let_the_lifted_bounds_go() -> None:
    from mitld_lp.solvers.iteration import interval_iterations

    mdp, q = _quotient(1)
    (it,) = interval_iterations(mdp, [q])
    refs = [weakref.ref(it.lower), weakref.ref(it.upper)]
    lower, upper = it.lower.copy(), it.upper.copy()
    bare, _, folded = _Folding.of(q).held(it, None)
    del it
    gc.collect()
    assert bare.lower is None and bare.upper is None
    assert all(r() is None for r in refs)
    np.testing.assert_array_equal(folded["lower"].unfold().view(np.uint64),
                                  lower.view(np.uint64))
    np.testing.assert_array_equal(folded["upper"].unfold().view(np.uint64),
                                  upper.view(np.uint64))


def _value_iteration(mdp, goal: np.ndarray, sense: str) -> np.ndarray:
    """The optimum by value iteration from 0 (the least fixed point: the optimum of
    reaching ``goal``), written with numpy's segmented reductions, to a fixpoint."""
    m = mdp.matrix.tocsr()
    starts = np.asarray(mdp.row_groups)[:-1]
    reduce = np.maximum.reduceat if sense == "max" else np.minimum.reduceat
    x = np.where(goal, 1.0, 0.0)
    for _ in range(200_000):
        new = np.where(goal, 1.0, reduce(m @ x, starts))
        if np.array_equal(new, x):
            break
        x = new
    else:
        raise AssertionError("value iteration did not settle")
    return x


@pytest.mark.parametrize("sense", ["max", "min"])
@pytest.mark.parametrize("seed", range(3))
def test_folded_solve_brackets_value_iteration(seed: int, sense: str,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    """A product large enough that the bounds are held folded (checked): the restored
    bounds still bracket value iteration's optimum, in both models."""
    mdp = random_mdp(600, seed=seed, locality=8, sink_fraction=0.15,
                     self_loop_fraction=0.3, target_fraction=0.1)
    sink = np.asarray(mdp.sink).copy()
    cut = sink & (np.arange(sink.size) % 3 == 0)
    mdp = replace(mdp, sink=sink & ~cut, truncated=cut)
    made = []
    held = _Folding.held

    def spy(self, it, lp):
        out = held(self, it, lp)
        made.append(bool(out[2]) and all(f.whole is None for f in out[2].values()))
        return out

    monkeypatch.setattr(_Folding, "held", spy)
    monkeypatch.setattr(plain, "FOLD_FROM_TRANSITIONS", 0)  # held folded whatever the size
    first, second = solve_models(mdp, Acceptance(np.asarray(mdp.target), None),
                                 Settings(), time.perf_counter(), sense)
    assert made and all(made)  # every model's vectors were held folded
    target, truncated = np.asarray(mdp.target), np.asarray(mdp.truncated)
    for sol in (first, second):
        goal = target | truncated if sol.which == "upper" else target
        want = _value_iteration(mdp, goal, sense)
        it = sol.iteration
        assert np.all(it.lower <= want + 1e-9), sol.which
        assert np.all(want <= it.upper + 1e-9), sol.which
        assert sol.certified


def _bits(a: np.ndarray) -> np.ndarray:
    return np.asarray(a, dtype=np.float64).view(np.uint64)


@pytest.mark.parametrize("sense", ["max", "min"])
@pytest.mark.parametrize("truncated", [False, True])
def test_held_whole_or_folded_the_same_answer(sense: str, truncated: bool,
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    """Below FOLD_FROM_TRANSITIONS nothing is folded (no fold is made); from it, the
    vectors are held folded.  Both ways give the same records, policy and certified
    bounds to the bit, and those bracket value iteration's optimum (written in the
    test)."""
    mdp = random_mdp(600, seed=7, locality=8, sink_fraction=0.15,
                     self_loop_fraction=0.3, target_fraction=0.1)
    if truncated:
        sink = np.asarray(mdp.sink).copy()
        cut = sink & (np.arange(sink.size) % 3 == 0)
        mdp = replace(mdp, sink=sink & ~cut, truncated=cut)
    target = np.asarray(mdp.target)
    folds: list[bool] = []
    held = _Folding.held

    def spy(self, it, lp):
        out = held(self, it, lp)
        folds.append(bool(out[2]) and all(f.whole is None for f in out[2].values()))
        return out

    monkeypatch.setattr(_Folding, "held", spy)
    runs = []
    for fold_from in (10**18, 0):
        monkeypatch.setattr(plain, "FOLD_FROM_TRANSITIONS", fold_from)
        runs.append(solve_models(mdp, Acceptance(target, None), Settings(),
                                 time.perf_counter(), sense))
    # held (and so folded) only when folding is on: once a model
    assert len(folds) == (2 if truncated else 1) and all(folds)
    for unfolded, folded in zip(runs[0], runs[1], strict=True):
        assert unfolded.which == folded.which
        np.testing.assert_array_equal(unfolded.policy, folded.policy)
        for a, b in ((unfolded.iteration.lower, folded.iteration.lower),
                     (unfolded.iteration.upper, folded.iteration.upper),
                     (unfolded.policy_values, folded.policy_values)):
            np.testing.assert_array_equal(_bits(a), _bits(b))
        assert _bits(np.array(unfolded.bounds)).tolist() == _bits(
            np.array(folded.bounds)).tolist()
        goal = target | np.asarray(mdp.truncated) if folded.which == "upper" else target
        want = _value_iteration(mdp, goal, sense)
        assert np.all(folded.iteration.lower <= want + 1e-9)
        assert np.all(want <= folded.iteration.upper + 1e-9)
        assert folded.certified and unfolded.certified
