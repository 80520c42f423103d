"""The block kernel's sweeps for two models (``sweep_four``: four columns, their sums,
bests and the guesses' flags in scalars) against the general sweeps (``compiled_kernels``'
``update`` and ``checked``, a column at a time through arrays): two models A and B
iterated together (four columns) and A, B and A again (six columns, the general path)
go through the same sweeps (the third pair moves, steadies, fails and crosses exactly
as the first, so the guesses' bookkeeping is the same), so columns 0-3 must end at the
same bits after every call, plain, watched and verifying sweeps alike; and the bounds
must bracket each model's closed form.

The blocks are rings whose every state is alike (each choice leaves the ring only to
the goal or to failure), so model A's optimum (reaching the goal) is the best choice's
``goal / (goal + fail)`` at every state and model B's (reaching failure) the best
choice's ``fail / (goal + fail)``, whatever its steps on the ring and its self-loop."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.solvers import kernels
from mitld_lp.solvers.graph import Sense

pytest.importorskip("numba")

# (ring steps with their probabilities, self-loop, goal, fail) per choice
CHOICES = (
    (((1, 0.5), (-1, 0.2968)), 0.2, 0.0018, 0.0014),   # goal 0.5625, fail 0.4375
    (((2, 0.3), (-3, 0.6976)), 0.0, 0.0015, 0.0009),   # goal 0.625, fail 0.375
    (((1, 0.1), (4, 0.0994)), 0.8, 0.0004, 0.0002),    # goal 2/3, fail 1/3
)


def _closed(sense: Sense, model: int) -> Fraction:
    """The exact optimum of the model as stored (its floats, the self-loop's ``1 - p``
    rounded as the kernel rounds it): a state that keeps choosing one choice has value
    ``exit / (leave - ring mass)``; the best choice's (model 0: the goal, 1: failure)."""
    values = []
    for steps, stay, goal, fail in CHOICES:
        leave = Fraction(1.0 - stay) - sum(Fraction(p) for _step, p in steps)
        values.append(Fraction(goal if model == 0 else fail) / leave)
    return max(values) if sense is Sense.MAX else min(values)


def _ring(n: int, states_choices: list[int] | None = None):
    """The ring's block: its inner matrix (self-loops on the diagonal), the states'
    choice groups and each choice's exits to the goal and to failure."""
    counts = [len(CHOICES)] * n if states_choices is None else states_choices
    own = [(s, choice) for s in range(n) for choice in CHOICES[:counts[s]]]
    # each choice's ring steps, then its self-loop (a step of 0) where it has one
    rows, cols, vals = zip(*[(row, (s + step) % n, p)
                             for row, (s, (steps, stay, _g, _f)) in enumerate(own)
                             for step, p in (*steps, (0, stay)) if p], strict=True)
    groups = np.concatenate([[0], np.cumsum(counts)])
    exits = np.array([(goal, fail) for _s, (_st, _stay, goal, fail) in own])
    inner = sp.csr_array((vals, (rows, cols)), shape=(len(exits), n))
    inner.sum_duplicates()
    return inner, np.array(groups), np.array(exits)


def _solve(inner, groups, exits, models: tuple[int, ...], sense: Sense, chunk: int,
           precision: float | None):
    """The compiled sweeps of the models' columns until closed: the bounds after each
    call, the last gap over its threshold and the kernel's track."""
    if kernels.compiled_kernel() is None:
        pytest.skip("numba is not installed")
    prep = kernels.Prepared(inner, groups)
    n = groups.size - 1
    local = np.tile([0.0, 1.0], (n, len(models)))
    cols = exits[:, [m for m in models for _ in range(2)]]
    seen = []
    for _call in range(50_000 // chunk + 1):
        over = kernels.compiled_sweeps(prep, cols, local, 1e-12, chunk, sense, precision)[1]
        seen.append(local.copy())
        if over < 1.0:
            break
    return seen, over, prep.track.copy()


@pytest.mark.parametrize("precision", [None, 1e-9])
@pytest.mark.parametrize("chunk", [1, 7, 10_000])
@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
def test_two_models_end_where_the_general_sweeps_do(sense, chunk, precision) -> None:
    rng = np.random.default_rng(11)
    uneven = [int(c) for c in rng.integers(1, 4, size=40)]  # 1-3 choices a state
    for inner, groups, exits in (_ring(12), _ring(40, uneven)):
        four, over4, track4 = _solve(inner, groups, exits, (0, 1), sense, chunk, precision)
        six, over6, track6 = _solve(inner, groups, exits, (0, 1, 0), sense, chunk,
                                    precision)
        assert over4 < 1.0 and over6 < 1.0
        assert track4[6] > 0 and track4[3] >= 1  # it verified: sweeps, a guess proven
        assert track6[6] == track4[6] and track6[3] > track4[3]  # the same sweeps
        assert over4 == over6
        assert len(four) == len(six)
        for a, b in zip(four, six, strict=True):
            assert np.array_equal(a, b[:, :4]) and np.array_equal(a[:, :2], b[:, 4:])


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
def test_the_bounds_bracket_both_closed_forms(sense) -> None:
    inner, groups, exits = _ring(12)
    seen, over, track = _solve(inner, groups, exits, (0, 1), sense, 5, None)
    assert over < 1.0 and track[6] > 0
    for local in seen:  # after every call, not only at the end
        for m in (0, 1):
            value = _closed(sense, m)
            for lo, hi in local[:, 2 * m:2 * m + 2]:
                assert Fraction(lo) <= value <= Fraction(hi), (m, lo, hi)
    assert np.all(seen[-1][:, 1::2] - seen[-1][:, 0::2] <= 1e-12)
