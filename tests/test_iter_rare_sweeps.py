"""The compiled sweeps of the interval iteration (mitld_lp.solvers.kernels) against
routes written here: a Gauss--Seidel Bellman sweep in plain Python floats (the same
operations in the same order: the same bits), and the exact optimum of small MDPs by
enumerating their policies and solving each chain in fractions.  The MDPs' probabilities
are dyadic, so the floats the solver reads are the fractions exactly; one MDP's value is
a rare event (about 1e-6)."""

from __future__ import annotations

import itertools
from fractions import Fraction

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.mdp import MDP
from mitld_lp.solvers import Status, interval_iteration, kernels
from mitld_lp.solvers.graph import Sense
from mitld_lp.testing.exact import chain_values

pytestmark = pytest.mark.skipif(kernels.compiled_kernel() is None,
                                reason="numba is not installed")

FLOOR = kernels.FLOOR


# ------------------------------------------------- one block: the sweep bit for bit
def _random_block(seed: int) -> tuple[sp.csr_array, np.ndarray, np.ndarray]:
    """A block of 7-12 states with 1-3 choices each (self-loops among the entries, one
    column each at most per row), its exit rewards for a lower and an upper column (the
    same per choice: one model), each choice's row plus its exit summing to at most 1."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(7, 13))
    rows, cols, vals, groups, exits = [], [], [], [0], []
    for _s in range(n):
        for _ in range(int(rng.integers(1, 4))):
            r = len(exits)
            targets = rng.choice(n, size=int(rng.integers(1, 4)), replace=False)
            w = rng.random(targets.size + 2)
            w /= w.sum()
            for t, p in zip(targets, w[:-2], strict=True):
                rows.append(r), cols.append(int(t)), vals.append(float(p))
            exits.append(float(w[-2]))  # w[-1]: leaves to value 0
        groups.append(len(exits))
    inner = sp.csr_array((vals, (rows, cols)), shape=(len(exits), n))
    e = np.array(exits)
    return inner, np.array(groups, dtype=np.int64), np.column_stack([e, e])


def _python_sweep(inner: sp.csr_array, groups: np.ndarray, exits: np.ndarray,
                  x: list[list[float]], tol: float, precision: float | None,
                  minimise: bool) -> tuple[list[float], float]:
    """One Gauss--Seidel sweep of ``x`` (lists of [lower, upper], in place) from the
    last state to the first, each choice's self-loop solved, a lower bound only raised
    and an upper one only lowered; each bound's change and the largest gap over its
    threshold after the sweep."""
    n = len(x)
    change = [0.0, 0.0]
    for s in range(n - 1, -1, -1):
        best = [float("inf") if minimise else float("-inf")] * 2
        for c in range(int(groups[s]), int(groups[s + 1])):
            acc = [float(exits[c, 0]), float(exits[c, 1])]
            loop = 0.0
            for e in range(int(inner.indptr[c]), int(inner.indptr[c + 1])):
                t, w = int(inner.indices[e]), float(inner.data[e])
                if t == s:
                    loop = w
                    continue
                acc = [acc[0] + w * x[t][0], acc[1] + w * x[t][1]]
            leave = 1.0 - loop
            if leave != 1.0:
                acc = [a / leave for a in acc] if leave > 0.0 else [0.0, 0.0]
            best = [min(b, a) if minimise else max(b, a) for b, a in zip(best, acc, strict=True)]
        old = list(x[s])
        x[s][0] = max(x[s][0], min(max(best[0], 0.0), 1.0))
        x[s][1] = min(x[s][1], min(max(best[1], 0.0), 1.0))
        change = [max(change[j], abs(x[s][j] - old[j])) for j in range(2)]
    over = 0.0
    for lo, hi in x:
        th = tol if precision is None else min(tol, max(precision * lo, FLOOR))
        over = max(over, (hi - lo) / th)
    return change, over


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("minimise", [False, True])
@pytest.mark.parametrize("precision", [None, 1e-6])
def test_watched_sweeps_equal_a_python_gauss_seidel_to_the_bit(
        seed: int, minimise: bool, precision: float | None) -> None:
    inner, groups, exits = _random_block(seed)
    n = groups.size - 1
    prep = kernels.Prepared(inner, groups)
    local = np.column_stack([np.zeros(n), np.ones(n)])
    x = [[0.0, 1.0] for _ in range(n)]
    sense = Sense.MIN if minimise else Sense.MAX
    # sweeps one call at a time, fewer than the watch before a guess: all watched
    for sweep in range(kernels_watch() - 1):
        done, over = kernels.compiled_sweeps(prep, exits, local, 1e-300, 1, sense,
                                             precision)
        change, want = _python_sweep(inner, groups, exits, x, 1e-300, precision, minimise)
        assert done == 1
        assert prep.track is not None and prep.track[0] == 0.0  # still watching
        np.testing.assert_array_equal(local, np.array(x), err_msg=f"sweep {sweep}")
        assert over == want
        assert [prep.track[kernels_off() + 8], prep.track[kernels_off() + 9]] == change


def kernels_watch() -> int:
    from mitld_lp.solvers import compiled_kernels

    return compiled_kernels.WATCH_SWEEPS


def kernels_off() -> int:
    from mitld_lp.solvers import compiled_kernels

    return compiled_kernels.OFF


# ------------------------------------- small MDPs: the bracket holds the exact value
def fraction_mdp(choices: list[list[dict[int, Fraction]]], n_states: int) -> MDP:
    """An MDP of ``n_states`` states (the last two: the goal and a fail state, both
    absorbing); ``choices[s]``: state ``s``'s choices as successor -> probability."""
    rows, cols, vals, groups = [], [], [], [0]
    row = 0
    for s in range(n_states):
        options = choices[s] if s < len(choices) else [{s: Fraction(1)}]
        for option in options:
            assert sum(option.values()) == 1
            for t, p in option.items():
                rows.append(row), cols.append(t), vals.append(float(p))
            row += 1
        groups.append(row)
    target = np.zeros(n_states, dtype=bool)
    sink = np.zeros(n_states, dtype=bool)
    target[n_states - 2], sink[n_states - 1] = True, True
    return MDP(matrix=sp.csr_array((vals, (rows, cols)), shape=(row, n_states)),
               row_groups=np.array(groups, dtype=np.int64),
               choice_actions=np.zeros(row, dtype=np.int32), action_names=("a",),
               initial=0, target=target, sink=sink,
               truncated=np.zeros(n_states, dtype=bool), states=tuple(range(n_states)))


def _exact(choices: list[list[dict[int, Fraction]]], n_states: int,
           maximise: bool = True) -> Fraction:
    """The optimal probability from state 0 of reaching the goal: every memoryless
    deterministic policy's chain solved in fractions (the states that cannot reach the
    goal under it at 0), the best of them."""
    goal = n_states - 2
    best: Fraction | None = None
    for policy in itertools.product(*(range(len(c)) for c in choices)):
        step = {s: choices[s][policy[s]] for s in range(len(choices))}
        # the states that reach the goal under the policy (backwards closure)
        good = {goal}
        grew = True
        while grew:
            grew = False
            for s, option in step.items():
                if s not in good and any(t in good for t in option):
                    good.add(s)
                    grew = True
        maybe = sorted(good - {goal})
        value = chain_values(step, maybe, goal)
        v = value.get(0, Fraction(0))
        best = v if best is None else (max(best, v) if maximise else min(best, v))
    assert best is not None
    return best


def _dyadic_choices(seed: int, n: int) -> list[list[dict[int, Fraction]]]:
    """Random choices over ``n`` transient states, the goal ``n`` and fail ``n + 1``,
    with probabilities k / 64 (exact in binary)."""
    rng = np.random.default_rng(seed)
    out = []
    for _s in range(n):
        options = []
        for _ in range(int(rng.integers(1, 3))):
            succ = rng.choice(n + 2, size=int(rng.integers(1, 4)), replace=False)
            cuts = np.sort(rng.choice(np.arange(1, 64), size=succ.size - 1, replace=False))
            parts = np.diff(np.concatenate([[0], cuts, [64]]))
            options.append({int(t): Fraction(int(k), 64) for t, k in zip(succ, parts,
                                                                           strict=True)})
        out.append(options)
    return out


def _rare_choices() -> list[list[dict[int, Fraction]]]:
    """Five states that wait for a rare event: each step reaches the goal with 2^-20
    and fails with 1/8 (choice a) or 2^-21 and 1/8 (choice b); else on to the next
    state (a ring), or back to state 0."""
    n, goal, fail = 5, 5, 6
    out = []
    for s in range(n):
        a = {goal: Fraction(1, 2**20), fail: Fraction(1, 8)}
        a[(s + 1) % n] = 1 - sum(a.values())
        b = {goal: Fraction(1, 2**21), fail: Fraction(1, 8)}
        b[0] = 1 - sum(b.values())  # state 0's own: a self-loop
        out.append([a, b])
    return out


def _holds(lower: float, exact: Fraction, upper: float) -> bool:
    """``exact`` inside ``[lower, upper]`` widened by 4 units in the last place: the
    iteration's bounds are float sums rounded to nearest (the certificate stage makes
    the bracket strict), so an exact value can sit a rounding beyond a bound that equals
    it in float (1/131073 here: the upper bound its nearest double, 3e-21 below it)."""
    slack = 4
    return (Fraction(lower) - slack * Fraction(float(np.spacing(lower))) <= exact
            <= Fraction(upper) + slack * Fraction(float(np.spacing(upper))))


@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
def test_compiled_bracket_holds_the_exact_optimum(seed: int, sense: Sense) -> None:
    n = 6
    choices = _dyadic_choices(seed, n)
    mdp = fraction_mdp(choices, n + 2)
    exact = _exact(choices, n + 2, maximise=sense is Sense.MAX)
    res = interval_iteration(mdp, mdp.target, sense=sense, compiled=True)
    assert res.status is Status.OPTIMAL
    assert _holds(res.value_lower, exact, res.value_upper)
    assert res.value_upper - res.value_lower <= 1e-9


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
def test_rare_event_bracket_holds_the_exact_value_to_its_precision(sense: Sense) -> None:
    choices = _rare_choices()
    mdp = fraction_mdp(choices, 7)
    exact = _exact(choices, 7, maximise=sense is Sense.MAX)
    assert 1e-6 < exact < 1e-5  # a rare event: tol's 1e-9 alone is 1e-3 of it
    res = interval_iteration(mdp, mdp.target, sense=sense, compiled=True, precision=1e-6)
    assert res.status is Status.OPTIMAL
    assert _holds(res.value_lower, exact, res.value_upper)
    # relative precision: the gap within 1e-6 of the lower bound, not tol's 1e-9
    assert res.value_upper - res.value_lower <= 1e-6 * res.value_lower
