"""The compiled sweeps' close-out (mitld_lp.solvers.sweep_forecast.close_out): a block
whose gap is forecast to close within a chunk is swept plainly, no guess watched or
verified, and watches again if the forecast was wrong.  The forecast's arithmetic against
hand calculations; the switches on a kernel state made here; and the interval iteration's
bracket, with the close-out taken (a spy says so), against the exact optimum of small
rare-event MDPs (every memoryless policy's linear system solved here by Gauss--Jordan
elimination in fractions): a maximum near 1e-30 and a minimum near 1e-10."""

from __future__ import annotations

import itertools
import math
from fractions import Fraction

import numpy as np
import pytest
import scipy.sparse as sp
from test_iter_rare_sweeps import fraction_mdp

from mitld_lp.solvers import Status, interval_iteration, iteration, kernels
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.sweep_forecast import PLAIN_WITHIN, close_out, needed


def test_needed_is_the_chunks_rate_carried_to_the_threshold() -> None:
    # over 1e6 -> 1e2 in 16 sweeps: a factor 10 every 4 sweeps, 1e2 -> 1 in 8 more
    assert needed([(16, 1e6), (32, 1e2)], 16, 16) == pytest.approx(8.0)
    # 1e6 -> 1e5 in 16: a factor 10 every 16 sweeps, 1e5 -> 1 in 80 more
    assert needed([(16, 1e6), (32, 1e5)], 16, 16) == pytest.approx(80.0)
    assert needed([(16, 1e6), (32, 2e6)], 16, 16) == math.inf  # growing: never
    assert needed([(16, 1e6)], 32, 16) is None  # before ``start`` sweeps
    assert needed([(16, 1e6)], 16, 16) is None  # no reading a chunk before


def _prep() -> kernels.Prepared:
    """A Prepared of two states (one model: two columns) in the watching phase, its
    columns' changes and ratios set as after some watched sweeps."""
    inner = sp.csr_array(np.array([[0.0, 0.5], [0.5, 0.0]]))
    prep = kernels.Prepared(inner, np.array([0, 1, 2]))
    prep.guess = np.zeros((2, 2))
    prep.track = np.zeros(8 + 6 * 2)
    prep.track[4] = 12.0  # watched sweeps
    prep.track[8:14] = [1e-3, 2e-3, 2e-3, 4e-3, 0.5, 0.5]  # changes, before, ratios
    return prep


FAST = [(16, 1e6), (32, 1e2)]  # forecast 8 sweeps: within PLAIN_WITHIN
SLOW = [(16, 1e6), (32, 1e5), (48, 1e4)]  # forecast 64


def test_close_out_turns_the_watching_off_and_on_again() -> None:
    assert needed(FAST, 16, 16) <= PLAIN_WITHIN < needed(SLOW, 16, 16)
    prep = _prep()
    close_out(prep, FAST, 16)
    assert prep.track[0] == -1.0 and prep.closing
    close_out(prep, FAST + [(48, 0.5 * 1e2 ** 0.5)], 16)  # still soon: stays plain
    assert prep.track[0] == -1.0 and prep.closing
    close_out(prep, SLOW, 16)  # the forecast failed: watched again from the start
    assert prep.track[0] == 0.0 and not prep.closing
    assert prep.track[4] == 0.0
    assert np.all(prep.track[8:14] == 0.0)  # no ratio from before the plain sweeps


def test_close_out_leaves_a_verification_and_plain_sweeps_alone() -> None:
    prep = _prep()
    prep.track[0] = 1.0  # verifying a guess: never cut short
    close_out(prep, FAST, 16)
    assert prep.track[0] == 1.0 and not prep.closing
    prep = _prep()
    prep.track[0] = -1.0  # plain sweeps asked for (kernels.OPTIMISTIC off)
    close_out(prep, SLOW, 16)
    assert prep.track[0] == -1.0 and not prep.closing
    prep = _prep()
    prep.track = None  # the kernel not called yet
    close_out(prep, FAST, 16)
    assert prep.track is None


def _ring(goal: Fraction, fail: Fraction, n: int = 5) -> list[list[dict[int, Fraction]]]:
    """``n`` states on a ring waiting for a rare event: each step reaches the goal with
    ``goal`` and fails with ``fail``, else moves one state on (choice a), or reaches the
    goal with twice ``goal`` and moves two states on (choice b)."""
    out = []
    for s in range(n):
        a = {n: goal, n + 1: fail}
        a[(s + 1) % n] = 1 - goal - fail
        b = {n: 2 * goal, n + 1: fail}
        b[(s + 2) % n] = 1 - 2 * goal - fail
        out.append([a, b])
    return out


def _optimum(choices: list[list[dict[int, Fraction]]], maximise: bool) -> Fraction:
    """State 0's optimal probability of the goal (state ``n``) over the memoryless
    policies of a ring of ``n`` transient states (every step fails with a positive
    probability, so each policy's ``(I - P) x = goal`` has one solution), each system
    solved by Gauss--Jordan elimination in fractions."""
    n = len(choices)
    values = []
    for policy in itertools.product(*(range(len(c)) for c in choices)):
        rows = []
        for s, c in enumerate(policy):
            step = choices[s][c]
            rows.append([(Fraction(s == t) - step.get(t, Fraction(0))) for t in range(n)]
                        + [step.get(n, Fraction(0))])
        for col in range(n):
            pivot = next(r for r in range(col, n) if rows[r][col] != 0)
            rows[col], rows[pivot] = rows[pivot], rows[col]
            lead = rows[col][col]
            rows[col] = [x / lead for x in rows[col]]
            for r in range(n):
                if r != col and rows[r][col] != 0:
                    f = rows[r][col]
                    rows[r] = [x - f * y for x, y in zip(rows[r], rows[col], strict=True)]
        values.append(rows[0][n])
    return max(values) if maximise else min(values)


def _within(lower: float, exact: Fraction, upper: float, ulps: int = 4) -> bool:
    """``exact`` in ``[lower, upper]`` widened by ``ulps`` units in the last place of
    each end (the iteration's bounds are float sums rounded to nearest; the certificate
    makes a bracket strict, not the iteration)."""
    return (Fraction(lower) - ulps * Fraction(float(np.spacing(lower))) <= exact
            <= Fraction(upper) + ulps * Fraction(float(np.spacing(upper))))


@pytest.mark.skipif(kernels.compiled_kernel() is None, reason="numba is not installed")
@pytest.mark.parametrize(("goal", "fail", "sense", "low", "high"), [
    (Fraction(1, 2**103), Fraction(1, 16), Sense.MAX, 1e-30, 1e-29),  # a maximum near 1e-30
    (Fraction(1, 2**37), Fraction(1, 16), Sense.MIN, 1e-10, 1e-9),  # a minimum near 1e-10
    (Fraction(1, 2**20), Fraction(1, 32), Sense.MAX, 1e-5, 1e-4),
    (Fraction(1, 2**20), Fraction(1, 32), Sense.MIN, 1e-5, 1e-4),
])
def test_the_bracket_holds_the_exact_value_with_the_close_out_taken(
        monkeypatch, goal: Fraction, fail: Fraction, sense: Sense, low: float,
        high: float) -> None:
    taken = []

    def spy(prep, seen, chunk):
        before = None if prep.track is None else float(prep.track[0])
        close_out(prep, seen, chunk)
        taken.append(before == 0.0 and prep.track[0] == -1.0)

    monkeypatch.setattr(iteration, "close_out", spy)
    choices = _ring(goal, fail)
    mdp = fraction_mdp(choices, 7)
    exact = _optimum(choices, maximise=sense is Sense.MAX)
    assert low < exact < high
    res = interval_iteration(mdp, mdp.target, sense=sense, compiled=True, precision=1e-6)
    assert any(taken)  # the block was closed out
    assert res.status is Status.OPTIMAL
    assert _within(res.value_lower, exact, res.value_upper)
    assert res.value_upper - res.value_lower <= 1e-6 * res.value_lower
