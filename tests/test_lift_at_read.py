"""The plain route's solve of both truncation models (mitld_lp.routes.plain.solve_models)
with the records' bounds and values held on the quotient and lifted at read
(mitld_lp.solvers.result.Lifted): the iteration's bounds bracket the optimum found by
brute force over every deterministic policy (each policy's chain solved with numpy,
written here), the LP's values agree with it, a held vector lifts to what the
quotient's values give by a loop over the states written here, and the held records
give the eager ones (lifted when made) to the bit, on both sides of the trim
threshold."""

from __future__ import annotations

import itertools
import time
from dataclasses import replace

import numpy as np
import pytest

from mitld_lp.problem import Settings
from mitld_lp.routes import plain
from mitld_lp.routes.acceptance import Acceptance
from mitld_lp.routes.plain import solve_models
from mitld_lp.solvers import result as records
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


def _lift_by_loop(reduced, state_map, one, forced: bool) -> np.ndarray:
    """The lift written as a loop over the states: a kept state reads its reduced
    state's value, a removed one 1 on ``one`` else 0; ``forced``: ``one`` is 1."""
    out = np.empty(state_map.size)
    for s, r in enumerate(state_map.tolist()):
        if forced and one[s]:
            out[s] = 1.0
        elif r < 0:
            out[s] = 1.0 if one[s] else 0.0
        else:
            out[s] = reduced[r]
    return out


@pytest.mark.parametrize("forced", [False, True])
@pytest.mark.parametrize("seed", range(4))
def test_held_vector_lifts_as_the_loop_and_reads_on_the_quotient(seed: int,
                                                                  forced: bool) -> None:
    mdp, q = _quotient(seed)
    assert 0 < q.n_states < mdp.n_states  # states removed: the lift gathers
    rng = np.random.default_rng(seed)
    one = np.asarray(q.qualitative.one).copy()
    if forced:  # a kept state of value 1 too: its entry lifts to 1, not its value
        one[np.flatnonzero(q.state_map >= 0)[0]] = True
    base = np.zeros((q.n_states, 3))
    base[:, 1] = rng.random(q.n_states)
    v = records.Lifted.of(base[:, 1], q.state_map, one, forced=forced)
    assert v.reduced.base is None  # a copy: the 3-column array is not held
    want = _lift_by_loop(base[:, 1], q.state_map, one, forced)
    got = v.lift()
    assert not got.flags.writeable
    np.testing.assert_array_equal(_bits(got), _bits(want))
    assert [v.at(s) for s in range(mdp.n_states)] == want.tolist()
    on = v.on(q.state_map)
    if forced:  # a kept state forced: the reduced values are not what it reads
        assert on is None
    else:  # every member of a reduced state reads its value
        kept = np.flatnonzero(q.state_map >= 0)
        np.testing.assert_array_equal(_bits(on[q.state_map[kept]]), _bits(want[kept]))
    assert v.on(q.state_map.copy()) is None  # another map: not read on the quotient
    # read where gathered (the certificate's guess and fallback): the loop's entries
    mask = rng.random(mdp.n_states) < 0.3
    idx = np.flatnonzero(~mask)[::3]
    for index in (mask, idx, slice(5, 77, 2), np.zeros(0, dtype=np.int64)):
        np.testing.assert_array_equal(_bits(v[index]), _bits(want[index]))


def test_records_hold_no_product_vector() -> None:
    from mitld_lp.solvers.iteration import interval_iterations

    mdp, q = _quotient(1)
    (it,) = interval_iterations(mdp, [q])
    for v in (it.held_lower, it.held_upper):
        assert isinstance(v, records.Lifted)
        assert v.reduced.shape == (q.n_states,) and v.state_map is q.state_map
        # its own contiguous copy, not a column of the pass's bounds: a strided vector
        # is another type to the compiled kernels that read it (a compile in a solve)
        assert v.reduced.flags.c_contiguous and v.reduced.base is None
    a, b = it.lower, it.lower
    assert a is not b  # lifted at each read, not kept
    np.testing.assert_array_equal(_bits(a), _bits(b))
    assert it.value_lower == a[mdp.initial] and it.value_upper == it.upper[mdp.initial]


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
def test_held_solve_brackets_value_iteration(seed: int, sense: str,
                                             monkeypatch: pytest.MonkeyPatch) -> None:
    """The records held on the quotient (checked), with the trim and the certificate's
    large-product route on: the lifted bounds still bracket value iteration's optimum,
    in both models."""
    mdp = random_mdp(600, seed=seed, locality=8, sink_fraction=0.15,
                     self_loop_fraction=0.3, target_fraction=0.1)
    sink = np.asarray(mdp.sink).copy()
    cut = sink & (np.arange(sink.size) % 3 == 0)
    mdp = replace(mdp, sink=sink & ~cut, truncated=cut)
    monkeypatch.setattr(plain, "TRIM_FROM_TRANSITIONS", 0)  # the large product's route
    first, second = solve_models(mdp, Acceptance(np.asarray(mdp.target), None),
                                 Settings(), time.perf_counter(), sense)
    target, truncated = np.asarray(mdp.target), np.asarray(mdp.truncated)
    for sol in (first, second):
        it = sol.iteration
        assert isinstance(it.held_lower, records.Lifted)
        assert isinstance(sol.lp.held_values, records.Lifted)
        goal = target | truncated if sol.which == "upper" else target
        want = _value_iteration(mdp, goal, sense)
        assert np.all(it.lower <= want + 1e-9), sol.which
        assert np.all(want <= it.upper + 1e-9), sol.which
        # the certificate's bounds hold the optimum (either sense: a bound on the
        # policy's value lies on the optimum's far side); a side not asked for is nan
        lo, hi = sol.bounds
        start = int(mdp.initial)
        assert not (np.isnan(lo) and np.isnan(hi))
        assert np.isnan(lo) or lo <= want[start] + 1e-12, (sol.which, lo, want[start])
        assert np.isnan(hi) or want[start] <= hi + 1e-12, (sol.which, hi, want[start])
        assert sol.certified


def _bits(a: np.ndarray) -> np.ndarray:
    return np.asarray(a, dtype=np.float64).view(np.uint64)


@pytest.mark.parametrize("trim_from", [10**18, 0])
@pytest.mark.parametrize("sense", ["max", "min"])
@pytest.mark.parametrize("truncated", [False, True])
def test_held_or_eager_the_same_answer(sense: str, truncated: bool, trim_from: int,
                                       monkeypatch: pytest.MonkeyPatch) -> None:
    """The records held on the quotient, lifted at read, and the eager ones (lifted
    when made: ``LIFT_AT_READ`` off), below and from the trim threshold: the same
    records, policy and certified bounds to the bit, bracketing value iteration's
    optimum (written in the test)."""
    mdp = random_mdp(600, seed=7, locality=8, sink_fraction=0.15,
                     self_loop_fraction=0.3, target_fraction=0.1)
    if truncated:
        sink = np.asarray(mdp.sink).copy()
        cut = sink & (np.arange(sink.size) % 3 == 0)
        mdp = replace(mdp, sink=sink & ~cut, truncated=cut)
    target = np.asarray(mdp.target)
    monkeypatch.setattr(plain, "TRIM_FROM_TRANSITIONS", trim_from)
    runs = []
    for at_read in (False, True):
        monkeypatch.setattr(records, "LIFT_AT_READ", at_read)
        runs.append(solve_models(mdp, Acceptance(target, None), Settings(),
                                 time.perf_counter(), sense))
    assert len({id(m) for m in runs[0]}) == (2 if truncated else 1)
    for eager, lazy in zip(runs[0], runs[1], strict=True):
        assert isinstance(eager.iteration.held_lower, np.ndarray)
        assert isinstance(lazy.iteration.held_lower, records.Lifted)
        assert lazy.which == eager.which
        np.testing.assert_array_equal(lazy.policy, eager.policy)
        np.testing.assert_array_equal(lazy.lp.policy, eager.lp.policy)
        for a, b in ((eager.iteration.lower, lazy.iteration.lower),
                     (eager.iteration.upper, lazy.iteration.upper),
                     (eager.lp.values, lazy.lp.values),
                     (eager.policy_values, lazy.policy_values)):
            np.testing.assert_array_equal(_bits(a), _bits(b))
        numbers = [(m.value, *m.bounds, *m.bracket, m.lp.value, m.lp.dual_objective,
                    m.iteration.value_lower, m.iteration.value_upper)
                   for m in (eager, lazy)]
        assert _bits(np.array(numbers[0])).tolist() == _bits(np.array(numbers[1])).tolist()
        goal = target | np.asarray(mdp.truncated) if lazy.which == "upper" else target
        want = _value_iteration(mdp, goal, sense)
        assert np.all(lazy.iteration.lower <= want + 1e-9)
        assert np.all(want <= lazy.iteration.upper + 1e-9)
        assert lazy.certified and eager.certified
