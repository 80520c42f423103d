"""The block kernel's one-model sweeps (``sweep_two``: two columns, their sums, bests and
the guesses' flags in scalars; each sweep returns the largest gap over its threshold
read as it sets the bounds) against routes written here:

* one sweep of each kind (plain, watched, verifying) in plain Python floats, the same
  operations in the same order, so the same bits: the bounds, the guesses, the flags,
  the changes and the gap over its threshold, on random blocks with cycles, self-loops,
  choices that never leave and exits of ``-0.0`` (max and min); the compiled sweep and
  its ``py_func`` alike;
* the whole kernel (``gauss_seidel`` through ``kernels.compiled_sweeps``, guesses made,
  verified and proven) a sweep a call: the gap it returns equal, to the bit, to NumPy's
  ``kernels.excess`` of the bounds it leaves, in the calls where a guess is proven too;
* the interval iteration on random MDPs with cycles, every block compiled: the bracket
  holds SciPy ``linprog``'s optimum (max: the least ``v >= P v + b``; min: the greatest
  ``v <= P v + b`` with 0 where a policy surely avoids the target)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.optimize import linprog

from mitld_lp.mdp import MDP
from mitld_lp.solvers import interval_iteration, kernels
from mitld_lp.solvers.graph import Sense

pytestmark = pytest.mark.skipif(kernels.compiled_kernel() is None,
                                reason="numba is not installed")

FLOOR = kernels.FLOOR
INF = float("inf")
NO_ROWS = np.empty(0, dtype=np.int64)


def random_block(seed: int, n: int = 40) -> tuple[sp.csr_array, np.ndarray, np.ndarray]:
    """A block of ``n`` states, 1-3 choices each, 1-3 entries a choice among the block
    (cycles; a self-loop in some; a choice wholly a self-loop in a few), exits to the
    target small or ``+0.0`` (some ``-0.0``), each row plus its exit at most 1."""
    rng = np.random.default_rng(seed)
    rows, cols, vals, groups, exits = [], [], [], [0], []
    for _s in range(n):
        for _ in range(int(rng.integers(1, 4))):
            r = len(exits)
            if rng.random() < 0.03:  # never leaves: worth 0
                rows.append(r), cols.append(_s), vals.append(1.0)
                exits.append(0.0)
                continue
            targets = rng.choice(n, size=int(rng.integers(1, 4)), replace=False)
            w = rng.random(targets.size + 2)
            w[-2] *= 0.01 if rng.random() < 0.5 else 0.0
            w /= w.sum()
            for t, p in zip(targets, w[:-2], strict=True):
                rows.append(r), cols.append(int(t)), vals.append(float(p))
            exits.append(-0.0 if w[-2] == 0.0 and rng.random() < 0.3 else float(w[-2]))
        groups.append(len(exits))
    inner = sp.csr_array((vals, (rows, cols)), shape=(len(exits), n))
    e = np.array(exits)
    return inner, np.array(groups, dtype=np.int64), np.column_stack([e, e.copy()])


def _sums(inner, groups, exits, x, s, cols, minimise, widen):
    """State ``s``'s best choice's sums over ``x``'s columns ``cols`` (each from the
    choice's exit of column ``j % 2``, its entries in order but the self-loop, divided by
    ``1 - self-loop`` unless that is 1, 0 if it is not positive); ``widen``: the second
    pair lowered (lower) and raised (upper) by ``(entries + 8)`` units of 2^-52."""
    best = [INF if minimise else -INF] * len(cols)
    for c in range(int(groups[s]), int(groups[s + 1])):
        first, last = int(inner.indptr[c]), int(inner.indptr[c + 1])
        acc = [float(exits[c, j % 2]) for j in range(len(cols))]
        loop = 0.0
        for e in range(first, last):
            t, w = int(inner.indices[e]), float(inner.data[e])
            if t == s:
                loop += w
                continue
            acc = [a + w * x[t][j] for a, j in zip(acc, cols, strict=True)]
        leave = 1.0 - loop
        if leave != 1.0:
            acc = [a / leave for a in acc] if leave > 0.0 else [0.0] * len(cols)
        if widen:
            wide = (last - first + 8) * 2.0**-52
            acc[2] *= 1.0 - wide
            acc[3] *= 1.0 + wide
        best = [min(b, a) if minimise else max(b, a) for b, a in zip(best, acc, strict=True)]
    return best


def _gap(lo: float, hi: float, tol: float, precision: float) -> float:
    th = tol if precision < 0.0 else min(tol, max(precision * lo, FLOOR))
    return (hi - lo) / th


def _clip(v: float) -> float:
    return min(max(v, 0.0), 1.0)


def python_sweep(inner, groups, exits, x, minimise, tol, precision, flags=None):
    """One Gauss--Seidel sweep of ``x`` (rows of [lower, upper] or, with ``flags``
    [lower on, upper on, lower fell, upper rose], [lower, upper, lower guess, upper
    guess]; in place) from the last state to the first; each bound's change and the
    largest gap over its threshold."""
    n = len(x)
    over = 0.0
    change = [0.0] * n
    for s in range(n - 1, -1, -1):
        cols = [0, 1, 2, 3] if flags is not None else [0, 1]
        best = _sums(inner, groups, exits, x, s, cols, minimise, flags is not None)
        old = list(x[s])
        x[s][0] = max(x[s][0], _clip(best[0]))
        x[s][1] = min(x[s][1], _clip(best[1]))
        change[s] = (abs(x[s][0] - old[0]), abs(x[s][1] - old[1]))
        over = max(over, _gap(x[s][0], x[s][1], tol, precision))
        if flags is not None:
            if flags[0] == 1.0:
                v = _clip(best[2])
                flags[2] = 1.0 if v < x[s][2] else flags[2]
                x[s][2] = v
                flags[0] = 3.0 if v > x[s][1] else flags[0]
            if flags[1] == 1.0:
                v = _clip(best[3])
                flags[3] = 1.0 if v > x[s][3] else flags[3]
                x[s][3] = v
                flags[1] = 3.0 if v < x[s][0] else flags[1]
    return change, over


def start_bounds(n: int, seed: int, guesses: bool) -> np.ndarray:
    """Bounds (and guesses between them) of ``n`` states, some equal, some at 0 and 1."""
    rng = np.random.default_rng(seed + 100)
    lo = rng.random(n) * 0.3
    hi = np.minimum(lo + rng.random(n) * 0.5, 1.0)
    lo[::7] = 0.0
    hi[::5] = 1.0
    hi[3::11] = lo[3::11]
    if not guesses:
        return np.column_stack([lo, hi])
    gl = lo + (hi - lo) * rng.random(n)
    gh = gl + (hi - gl) * rng.random(n)
    return np.column_stack([lo, hi, gl, gh])


def one_model_track() -> np.ndarray:
    """The kernel's state between calls for one model, watching (compiled_kernels.OFF's
    layout: 8 header slots, then 6 a column), the guesses' first margin 1/16."""
    track = np.zeros(8 + 6 * 2)
    track[5] = 1.0 / 16.0
    return track


def _two():
    from mitld_lp.solvers import sweep_two

    return sweep_two


@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize("minimise", [False, True])
@pytest.mark.parametrize("precision", [-1.0, 1e-3])
@pytest.mark.parametrize("python", [False, True])
def test_each_sweep_equals_a_python_sweep_to_the_bit(seed, minimise, precision, python):
    inner, groups, exits = random_block(seed)
    prep = kernels.Prepared(inner, groups)
    indptr, indices = prep.index
    order = prep.order
    tol = 1e-3
    args = (indptr, indices, inner.data, prep.groups, prep.leave, exits)
    pick = (lambda f: f.py_func) if python else (lambda f: f)
    route = (NO_ROWS, False, True)  # the general route: order and every exit read
    check_each_sweep(pick, (inner, groups, exits), args, order, route, seed, minimise, tol,
                     precision)


def check_each_sweep(pick, block, args, order, route, seed, minimise, tol, precision):
    """``sweep_two``'s three sweeps (each through ``pick``) on ``block`` (``inner``,
    ``groups``, ``exits``; ``args`` the kernel's first six), ``order`` and ``route``
    (``rows``, ``listed``, ``loops``) against :func:`python_sweep`, to the bit: the
    bounds, the changes, the largest changes, the gap, the guesses and their flags."""
    two = _two()
    inner, groups, exits = block
    n = groups.size - 1
    local = start_bounds(n, seed, False)
    x = local.tolist()
    over = pick(two.plain2)(*args, local, order, minimise, tol, precision, FLOOR, *route)
    _, want = python_sweep(inner, groups, exits, x, minimise, tol, precision)
    np.testing.assert_array_equal(local, np.array(x))
    assert over == want
    # watched: the changes into guess, the largest of each column into track
    local = start_bounds(n, seed, False)
    x = local.tolist()
    guess = np.full_like(local, -1.0)
    track = one_model_track()
    over = pick(two.watched2)(*args, local, order, minimise, guess, track, tol, precision,
                              FLOOR, *route)
    change, want = python_sweep(inner, groups, exits, x, minimise, tol, precision)
    np.testing.assert_array_equal(local, np.array(x))
    np.testing.assert_array_equal(guess, np.array(change))
    assert over == want
    assert list(track[16:18]) == [max(c[0] for c in change), max(c[1] for c in change)]
    # verifying, with each guess on trial, verified or crossed
    for on in ((1.0, 1.0), (2.0, 1.0), (1.0, 3.0)):
        work = start_bounds(n, seed, True)
        x = work.tolist()
        track = one_model_track()
        track[0] = 1.0
        track[14:16] = on
        flags = [*on, 0.0, 0.0]
        over = pick(two.verifying2)(*args, work, order, minimise, track, tol, precision,
                                    FLOOR, *route)
        _, want = python_sweep(inner, groups, exits, x, minimise, tol, precision, flags)
        np.testing.assert_array_equal(work, np.array(x))
        assert over == want
        assert [track[14], track[15], track[18], track[19]] == flags


def _rare_block(seed: int, n: int = 60) -> tuple[sp.csr_array, np.ndarray, np.ndarray]:
    """A block that closes slowly (each step reaches the target with about 1e-4, fails
    with about 1e-2, else moves on inside the block): the guesses are made and tried."""
    rng = np.random.default_rng(seed)
    rows, cols, vals, groups, exits = [], [], [], [0], []
    for s in range(n):
        for _ in range(int(rng.integers(1, 3))):
            r = len(exits)
            goal = 1e-4 * rng.random()
            fail = 1e-2 * rng.random()
            targets = [(s + 1) % n, int(rng.integers(n))]
            w = rng.random(2)
            w *= (1.0 - goal - fail) / w.sum()
            for t, p in zip(targets, w, strict=True):
                rows.append(r), cols.append(t), vals.append(float(p))
            exits.append(goal)
        groups.append(len(exits))
    inner = sp.csr_array((vals, (rows, cols)), shape=(len(exits), n))
    inner.sum_duplicates()
    e = np.array(exits)
    return inner, np.array(groups, dtype=np.int64), np.column_stack([e, e])


@pytest.mark.parametrize("minimise", [False, True])
def test_the_kernels_gap_is_numpys_in_every_phase(minimise):
    sense = Sense.MIN if minimise else Sense.MAX
    proven = verifying = 0.0
    for seed in range(4):
        inner, groups, exits = _rare_block(seed)
        n = groups.size - 1
        prep = kernels.Prepared(inner, groups)
        local = np.column_stack([np.zeros(n), np.ones(n)])
        for _call in range(120):
            done, over = kernels.compiled_sweeps(prep, exits, local, 1e-300, 1, sense,
                                                 1e-9)
            assert done == 1
            assert over == kernels.excess(local, 1e-300, 1e-9)
        proven += prep.track[3]
        verifying += prep.track[6]
    assert verifying > 0 and proven > 0  # the verifying sweeps ran, and proved a guess


def _mdp(seed: int, n: int) -> tuple[MDP, np.ndarray]:
    """Random MDP: ``n`` states with cycles among them, the goal ``n`` and a fail state
    ``n + 1`` (both absorbing), each choice reaching them rarely."""
    rng = np.random.default_rng(seed)
    rows, cols, vals, groups = [], [], [], [0]
    r = 0
    for s in range(n + 2):
        if s >= n:
            rows.append(r), cols.append(s), vals.append(1.0)
            r += 1
            groups.append(r)
            continue
        for _ in range(int(rng.integers(1, 4))):
            succ = rng.choice(n, size=int(rng.integers(1, 4)), replace=False).tolist()
            w = rng.random(len(succ))
            goal, fail = 0.02 * rng.random(), 0.05 * rng.random()
            w *= (1.0 - goal - fail) / w.sum()
            for t, p in zip(succ + [n, n + 1], [*w, goal, fail], strict=True):
                rows.append(r), cols.append(int(t)), vals.append(float(p))
            r += 1
        groups.append(r)
    matrix = sp.csr_array((vals, (rows, cols)), shape=(r, n + 2))
    matrix.sum_duplicates()
    target = np.zeros(n + 2, dtype=bool)
    target[n] = True
    sink = np.zeros(n + 2, dtype=bool)
    sink[n + 1] = True
    mdp = MDP(matrix=matrix, row_groups=np.array(groups, dtype=np.int64),
              choice_actions=np.zeros(r, dtype=np.int32), action_names=("a",), initial=0,
              target=target, sink=sink, truncated=np.zeros(n + 2, dtype=bool),
              states=tuple(range(n + 2)))
    return mdp, target


def _linprog_optimum(mdp: MDP, target: np.ndarray, maximise: bool) -> np.ndarray:
    """Every state's optimum by SciPy's LP: max, the least ``v >= P v`` (``v`` 1 on the
    target); min, the greatest ``v <= P v`` with 0 where a policy surely avoids it."""
    m = mdp.matrix.toarray()
    groups = mdp.row_groups
    n = target.size
    owner = np.repeat(np.arange(n), np.diff(groups))
    zero = ~target.copy()
    if not maximise:  # states where some choice stays among them forever: value 0
        while True:
            keep = np.array([any(m[c][~zero].sum() == 0.0 for c in range(groups[s],
                                                                        groups[s + 1]))
                             for s in range(n)]) & zero
            if (keep == zero).all():
                break
            zero = keep
    else:
        zero = np.zeros(n, dtype=bool)
    free = ~target & ~zero
    rows = np.flatnonzero(free[owner])
    a = m[rows][:, free] - np.eye(n)[owner[rows]][:, free]  # P v - v_s
    b = m[rows][:, target].sum(1)  # the target's mass
    bounds = [(0.0, 1.0)] * int(free.sum())
    if maximise:  # min sum v s.t. v_s >= P v + b: -(P v - v_s) >= b
        res = linprog(np.ones(free.sum()), A_ub=a, b_ub=-b, bounds=bounds, method="highs")
    else:  # max sum v s.t. v_s <= P v + b
        res = linprog(-np.ones(free.sum()), A_ub=-a, b_ub=b, bounds=bounds, method="highs")
    assert res.status == 0
    v = np.zeros(n)
    v[target] = 1.0
    v[free] = res.x
    return v


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("maximise", [True, False])
def test_interval_iteration_brackets_linprogs_optimum(seed, maximise):
    mdp, target = _mdp(seed, 80)
    want = _linprog_optimum(mdp, target, maximise)[0]
    res = interval_iteration(mdp, target, sense=Sense.MAX if maximise else Sense.MIN,
                             compiled=True, precision=None)
    assert res.value_lower - 1e-9 <= want <= res.value_upper + 1e-9
    assert res.value_upper - res.value_lower <= 1e-6
    assert 0.0 < want < 1.0
