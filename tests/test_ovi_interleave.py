"""The compiled block kernel's verifying sweeps on packed rows (each state's bounds and
guesses side by side, mitld_lp.solvers.compiled_kernels): the proven bounds bracket the
optimum after every call, wherever a call stops (mid-verification included), for one
model (two columns, the scalar path) and two (four, the general path), maximum and
minimum.  Expected values from independent routes: a closed form (a symmetric ring:
every state's value is its best choice's odds of the goal against the fail state) and
exact rational arithmetic over every deterministic policy of a small uneven ring."""

from __future__ import annotations

import itertools
from fractions import Fraction

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.solvers import kernels as kernels_module
from mitld_lp.solvers.graph import Sense

# a choice: ring steps with their probabilities, the goal's and the fail state's
Choice = tuple[tuple[tuple[int, str], ...], str, str]

SYMMETRIC: list[Choice] = [
    (((1, "0.5"), (-1, "0.497")), "0.0018", "0.0012"),  # goal odds 0.6, fail odds 0.4
    (((2, "0.3"), (-3, "0.6976")), "0.0015", "0.0009"),  # goal odds 0.625, fail 0.375
]


@pytest.fixture(scope="module")
def kernel():
    """numba loaded once for the module (the kernel compiled or read from its cache)."""
    if kernels_module.compiled_kernel() is None:
        pytest.skip("numba is not installed")
    return kernels_module


def _block(n: int, choices: list[list[Choice]]):
    """The ring's block (choices x states, no self-loops) and its exits: per choice the
    goal's probability, then the fail state's (a second model), as floats."""
    rows, cols, vals, groups, exits = [], [], [], [0], []
    for i in range(n):
        for steps, goal, fail in choices[i]:
            for step, p in steps:
                rows.append(len(exits)), cols.append((i + step) % n), vals.append(float(p))
            exits.append((float(goal), float(fail)))
        groups.append(len(exits))
    inner = sp.csr_array((vals, (rows, cols)), shape=(len(exits), n))
    return inner, np.array(groups, dtype=np.int64), np.array(exits)


def _sweep(kern, inner, groups, exits, sense: Sense, chunk: int, check) -> tuple:
    """From ``[0, 1]``, ``chunk`` sweeps a call until closed (``check(local)`` after
    each call); the sweeps and the kernel's state."""
    prep = kern.Prepared(inner, groups)
    k = exits.shape[1]
    local = np.tile([0.0, 1.0], (groups.size - 1, k // 2))
    done, over = 0, np.inf
    while over >= 1.0:
        swept, over = kern.compiled_sweeps(prep, exits, local, 1e-9, chunk, sense)
        done += swept
        check(local)
        assert done < 20_000
    return done, prep.track, local


def _bracket(local: np.ndarray, exact: list[list[Fraction]]) -> None:
    """Every proven bound on its side of the exact value (a hair for the plain
    updates' own rounding, as the kernel's docs allow)."""
    for j, column in enumerate(exact):
        for s, value in enumerate(column):
            lo, hi = local[s, 2 * j], local[s, 2 * j + 1]
            assert Fraction(lo) <= value + Fraction(1, 10**15), (s, j, lo, value)
            assert value - Fraction(1, 10**15) <= Fraction(hi), (s, j, hi, value)


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize("chunk", [1, 16])
def test_symmetric_ring_one_model_brackets_the_closed_form(kernel, sense, chunk) -> None:
    n = 10
    inner, groups, exits = _block(n, [SYMMETRIC] * n)
    exact = Fraction(5, 8) if sense is Sense.MAX else Fraction(3, 5)  # best goal odds
    done, track, local = _sweep(kernel, inner, groups, exits[:, [0, 0]], sense, chunk,
                                lambda x: _bracket(x, [[exact] * n]))
    assert float(np.max(local[:, 1] - local[:, 0])) < 1e-9
    assert track[6] > 0 and track[3] >= 1  # sweeps verified guesses, a guess proven
    assert done < 2_000  # the plain sweeps close by 0.996 a sweep: some 4,700


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
def test_symmetric_ring_two_models_bracket_their_closed_forms(kernel, sense) -> None:
    # four columns: the general path, its guesses at an offset in the same rows
    n = 10
    inner, groups, exits = _block(n, [SYMMETRIC] * n)
    goal, fail = ((Fraction(5, 8), Fraction(2, 5)) if sense is Sense.MAX
                  else (Fraction(3, 5), Fraction(3, 8)))
    done, track, local = _sweep(kernel, inner, groups, exits[:, [0, 0, 1, 1]], sense, 1,
                                lambda x: _bracket(x, [[goal] * n, [fail] * n]))
    assert float(np.max(local[:, 1::2] - local[:, 0::2])) < 1e-9
    assert track[6] > 0 and track[3] >= 1


def _uneven(n: int) -> list[list[Choice]]:
    """Exits that differ along the ring, every third state with one choice only."""
    out = []
    for i in range(n):
        g, f = 1 + i % 5, 1 + (2 * i) % 3
        first = (((1, "0.6"), (-1, f"0.{400 - g - f:03d}")), f"0.{g:03d}", f"0.{f:03d}")
        second = (((3, "0.25"), (-2, "0.747")), "0.002", "0.001")
        out.append([first] if i % 3 == 0 else [first, second])
    return out


def _exact(inner, groups, exits: np.ndarray, sense: Sense) -> list[Fraction]:
    """The optimum of every state by brute force: each deterministic policy's values
    solved exactly (Gauss-Jordan over the floats' rationals), best per state."""
    n = groups.size - 1
    dense = inner.toarray()
    best: list[Fraction] | None = None
    for pick in itertools.product(*[range(groups[s], groups[s + 1]) for s in range(n)]):
        a = [[Fraction(int(r == s)) - Fraction(dense[c, s]) for s in range(n)]
             + [Fraction(exits[c])] for r, c in enumerate(pick)]
        for col in range(n):
            piv = next(r for r in range(col, n) if a[r][col] != 0)
            a[col], a[piv] = a[piv], a[col]
            a[col] = [v / a[col][col] for v in a[col]]
            for r in range(n):
                if r != col and a[r][col] != 0:
                    a[r] = [v - a[r][col] * w for v, w in zip(a[r], a[col], strict=True)]
        values = [a[s][n] for s in range(n)]
        better = max if sense is Sense.MAX else min
        best = values if best is None else [better(b, v) for b, v in zip(best, values,
                                                                        strict=True)]
    return best


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
def test_uneven_ring_brackets_the_brute_force_optimum_after_every_sweep(kernel,
                                                                         sense) -> None:
    n = 8
    inner, groups, exits = _block(n, _uneven(n))
    exact = _exact(inner, groups, exits[:, 0], sense)
    assert len(set(exact)) > 2  # values that vary along the ring
    done, track, local = _sweep(kernel, inner, groups, exits[:, [0, 0]], sense, 1,
                                lambda x: _bracket(x, [exact]))
    assert float(np.max(local[:, 1] - local[:, 0])) < 1e-9
    assert track[6] > 0  # verifying sweeps ran, and calls stopped inside them
