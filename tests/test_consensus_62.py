"""The early jump's budget (mitld_lp.solvers.iteration._EARLY, policy_jump.Abandoned):
a compiled block forecast at 32 sweeps to need many more is jumped there, but only
within the rounds of policy iteration that the sweeps it would save pay for (in entries
touched, mitld_lp.solvers.jump_cost); a block whose LUs fill (a random sparse chain)
makes the jump abandon, one whose LUs do not (a line) is jumped; either way the
interval iteration's bracket holds Storm's exact value.

Expected values from independent routes: the sweeps saved by hand; Storm's exact
engine on the gambler's ruin of tests/test_sweep_forecast.py written in PRISM."""

from __future__ import annotations

import logging
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
from storm_exact import storm_rational
from test_sweep_forecast import PRISM as RUIN
from test_sweep_forecast import _ruin

from mitld_lp import defaults
from mitld_lp.solvers import Status, interval_iteration, iteration, jump_cost
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.policy_jump import Abandoned, jump
from mitld_lp.solvers.topological import Block

LEAK = 1e-3


def _block(n: int, successors) -> Block:
    """``n`` states with two choices each, ``successors(s, k)`` giving choice ``k``'s
    four successors (probabilities 0.3, 0.3, 0.2, 0.2 - LEAK; the rest leaves the
    block), its exit reward LEAK or LEAK / 2."""
    r, c, v, starts, reward = [], [], [], [], []
    for s in range(n):
        starts.append(len(reward))
        for k in range(2):
            for t, p in zip(successors(s, k), (0.3, 0.3, 0.2, 0.2 - LEAK), strict=True):
                r.append(len(reward)), c.append(int(t)), v.append(p)
            reward.append(LEAK * (0.5 + 0.5 * ((s + k) % 3 == 0)))
    m = len(reward)
    inner = sp.csr_array((v, (r, c)), shape=(m, n))
    return Block(np.arange(n), np.arange(m), inner, sp.csr_array((m, n)),
                 np.array(starts, dtype=np.int64), np.array(reward))


def _random(n: int) -> Block:
    """Each choice moves to four random states: the LU of such a chain fills."""
    rng = np.random.default_rng(7)
    picks = {(s, k): rng.choice(n, 4, replace=False) for s in range(n) for k in range(2)}
    return _block(n, lambda s, k: picks[s, k])


def _line(n: int) -> Block:
    """A ring, each choice a step one way or the other: its LU does not fill."""
    return _block(n, lambda s, k: [(s + 1) % n, (s + 2) % n, (s - 1) % n, (s - 2) % n]
                  if k == 0 else [(s - 1) % n, (s - 2) % n, (s + 1) % n, (s + 2) % n])


def test_the_sweeps_saved_are_those_forecast_at_most_the_limit_s() -> None:
    # 500 more forecast after 32, 968 left to the limit of 1,000
    early = iteration._Early(done=32, needed=500.0, stopped=True)
    assert iteration._saved(early, 1000) == 500.0
    early.needed = 5000.0  # no more than the limit's sweeps are saved
    assert iteration._saved(early, 1000) == 968.0


def test_the_budget_abandons_a_block_that_fills_and_jumps_one_that_does_not() -> None:
    """With a budget of 100 sweeps on each block, in rounds of policy iteration (entries
    touched): the random chain (1,500 states; one round, an LU that fills, costs some
    2,500 sweeps) is abandoned after its first round with its bounds untouched, the
    line (1,500 states; a round some 60 sweeps) is jumped to within the tolerance."""
    tol = 1e-6
    for block, fills in ((_random(1500), True), (_line(1500), False)):
        n = block.states.size
        lo, hi = np.zeros(n), np.ones(n)
        start = block.starts  # the rounds' cost: any policy's chain fills alike here
        allowance = jump_cost.cost(block, start).allowance(100.0)
        if fills:
            assert allowance < 1.0
            with pytest.raises(Abandoned):
                jump(block, lo, hi, tol, None, Sense.MAX, allowance=allowance)
            assert np.all(lo == 0.0) and np.all(hi == 1.0)
        else:
            assert allowance > 1.0
            assert jump(block, lo, hi, tol, None, Sense.MAX, allowance=allowance)
            assert np.all(hi - lo <= tol) and np.all(lo <= hi)


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize("budget", [None, 1e9, 0.0])
def test_the_ruin_jumped_early_or_refused_holds_storms_exact_value(
        tmp_path: Path, sense: Sense, budget: float | None, monkeypatch, caplog) -> None:
    """The ruin's block swept by the compiled kernel: read at 32 sweeps and jumped
    there (its own cost model's decision, ``None``, or sweeps saved without end), or,
    with no sweeps to save, the jump refused before the work and the block swept on;
    every bracket holds Storm's exact value."""
    pytest.importorskip("stormpy")
    pytest.importorskip("numba")
    path = tmp_path / "ruin.prism"
    path.write_text(RUIN, encoding="utf-8")
    exact = storm_rational(path, f'P{sense.value}=? [F "goal"]')
    if budget is not None:
        monkeypatch.setattr(iteration, "_saved", lambda early, limit: budget)
    mdp = _ruin()
    with caplog.at_level(logging.DEBUG, logger="mitld_lp.solvers.iteration"):
        r = interval_iteration(mdp, mdp.target, sense=sense, progress=False,
                               compiled=True)
    assert r.status is Status.OPTIMAL, r.message
    lo, hi = Fraction(r.value_lower), Fraction(r.value_upper)
    # rounded to nearest, the lower bound may sit one rounding above the exact value
    # (tests/test_rare_events.py), the upper one not below it
    assert lo <= exact * (1 + Fraction(1, 2**50)) and exact <= hi, (lo, exact, hi)
    assert hi - lo <= Fraction(defaults.TOL)
    refused = "refused" in caplog.text
    assert refused is (budget == 0.0), caplog.text
    assert "abandoned" not in caplog.text, caplog.text
    if budget != 0.0:  # jumped at the early look
        assert r.iterations == iteration._EARLY[0], r.iterations
    else:  # swept on past the early look
        assert r.iterations > iteration._EARLY[0], r.iterations


def test_the_rounds_forecast_reads_the_switches_rate() -> None:
    """By hand: the first round forecasts one more; 9,495 then 9,187 switches fall by
    9,187/9,495 a round, so ln 9,187 / ln(9,495/9,187) = 9.1256 / 0.032976 = 276.7 rounds
    remain; switches that grow never end; a round of one switch or a quick fall, one."""
    from mitld_lp.solvers.policy_jump import _rounds_left

    assert _rounds_left(None, 9495) == 1.0
    assert _rounds_left(9495, 9187) == pytest.approx(276.7, rel=1e-3)
    assert _rounds_left(2950, 3232) == float("inf")
    assert _rounds_left(1000, 10) == 1.0
    assert _rounds_left(5, 1) == 1.0
