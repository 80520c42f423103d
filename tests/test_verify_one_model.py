"""The block kernel's verifying sweep for one model (``compiled_kernels._verifying2``,
its guesses' flags held in locals for the sweep) against the general one
(``compiled_kernels.checked``, a column at a time through ``track``): a model iterated
alone (two columns) and the same model twice over (four columns, the general path) go
through the same sweeps, so every pair of columns must end at the same bits after every
call, the verifications included; and the bounds must bracket the closed form.

The blocks are rings whose every state is alike (each choice leaves the ring only to
the goal or to failure), so the optimum is the best choice's ``goal / (goal + fail)``
at every state, whatever its steps on the ring and its self-loop (solved exactly by the
kernel: ``1 - p`` divides)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.solvers import kernels
from mitld_lp.solvers.graph import Sense

pytest.importorskip("numba")

# (ring steps with their probabilities, self-loop, goal, fail) per choice
SYMMETRIC = (
    (((1, 0.5), (-1, 0.2968)), 0.2, 0.0018, 0.0014),   # goal 0.5625
    (((2, 0.3), (-3, 0.6976)), 0.0, 0.0015, 0.0009),   # goal 0.625
    (((1, 0.1), (4, 0.0994)), 0.8, 0.0004, 0.0002),    # goal 2/3
)
EXACT = {Sense.MAX: 2.0 / 3.0, Sense.MIN: 0.5625}


def _ring(n: int, choices: tuple, states_choices: list[int] | None = None
          ) -> tuple[sp.csr_array, np.ndarray, np.ndarray]:
    """The ring's block: its inner matrix (self-loops on the diagonal), the states'
    choice groups and each choice's exit reward (to the goal)."""
    rows, cols, vals, exits, groups = [], [], [], [], [0]
    for s in range(n):
        own = choices if states_choices is None else choices[:states_choices[s]]
        for steps, stay, goal, _fail in own:
            row = len(exits)
            for step, p in steps:
                rows.append(row), cols.append((s + step) % n), vals.append(p)
            if stay:
                rows.append(row), cols.append(s), vals.append(stay)
            exits.append(goal)
        groups.append(len(exits))
    inner = sp.csr_array((vals, (rows, cols)), shape=(len(exits), n))
    inner.sum_duplicates()
    return inner, np.array(groups), np.array(exits)


def _solve(inner, groups, exits, columns: int, sense: Sense, chunk: int):
    """The compiled sweeps of ``columns // 2`` copies of the model until closed: the
    bounds after each call and the kernel's track."""
    prep = kernels.Prepared(inner, groups)
    n = groups.size - 1
    local = np.tile([0.0, 1.0], (n, columns // 2))
    cols = np.repeat(exits[:, None], columns, axis=1)
    seen, done, over = [], 0, np.inf
    while over >= 1.0 and done < 50_000:
        swept, over = kernels.compiled_sweeps(prep, cols, local, 1e-12, chunk, sense)
        done += swept
        seen.append(local.copy())
    return seen, over, prep.track.copy()


@pytest.fixture(autouse=True)
def _compiled() -> None:
    if kernels.compiled_kernel() is None:
        pytest.skip("numba is not installed")


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize("chunk", [1, 7, 10_000])
def test_one_model_and_the_same_model_twice_end_at_the_same_bits(sense, chunk) -> None:
    rng = np.random.default_rng(5)
    uneven = [int(c) for c in rng.integers(1, 4, size=40)]  # 1-3 choices a state
    for inner, groups, exits in (_ring(12, SYMMETRIC), _ring(40, SYMMETRIC, uneven)):
        one, over1, track1 = _solve(inner, groups, exits, 2, sense, chunk)
        two, over2, track2 = _solve(inner, groups, exits, 4, sense, chunk)
        assert over1 < 1.0 and over2 < 1.0
        assert track1[6] > 0 and track1[3] >= 1  # it verified: sweeps, a guess proven
        assert track2[6] == track1[6]  # the same verifying sweeps
        assert len(one) == len(two)
        for a, b in zip(one, two, strict=True):
            assert np.array_equal(a, b[:, :2]) and np.array_equal(a, b[:, 2:])


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
def test_the_bounds_bracket_the_closed_form(sense) -> None:
    inner, groups, exits = _ring(12, SYMMETRIC)
    seen, over, track = _solve(inner, groups, exits, 2, sense, 5)
    assert over < 1.0 and track[6] > 0
    value = EXACT[sense]
    for local in seen:  # after every call, not only at the end
        assert np.all(local[:, 0] <= value) and np.all(value <= local[:, 1])
    assert np.all(seen[-1][:, 1] - seen[-1][:, 0] <= 1e-12)
