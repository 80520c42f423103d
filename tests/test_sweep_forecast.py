"""The sweeps' forecast (issue 45): a block whose gap the sweeps cannot close before
their limit is jumped (policy iteration, verified bounds) as soon as the forecast says
so, not swept to the limit first; the bracket still holds Storm's exact value.

The model is a gambler's ruin with a coin slightly against the player (Dubins and
Savage's bold play): its 39 inner states are one strongly connected block, and the
upper bound, 1 at the start, leaves 1 only as fast as the timid walk of about
``x (N - x)`` steps escapes, so the Jacobi sweeps' gap stays near 1 for hundreds of
sweeps (QVBS ``consensus``'s blocks behave so)."""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import pytest
from conftest import build_mdp
from storm_exact import storm_rational

from mitld_lp import defaults
from mitld_lp.solvers import Status, interval_iteration, iteration

stormpy = pytest.importorskip("stormpy")

N = 40  # the goal; 0 is ruin
START = 13
UP = 0.48  # the coin, against the player


def _ruin():
    """States 0..N numbered by the fortune; ``timid`` stakes 1, ``bold`` stakes all it
    can use (``min(x, N - x)``)."""
    states = [[] for _ in range(N + 1)]
    for x in range(1, N):
        stake = min(x, N - x)
        states[x] = [("timid", {x + 1: UP, x - 1: 1 - UP}),
                     ("bold", {x + stake: UP, x - stake: 1 - UP})]
    return build_mdp(states, initial=START, target=[N], sink=[0])


PRISM = f"""mdp
module ruin
  x : [0..{N}] init {START};
  [timid] x>0 & x<{N} -> {UP} : (x'=x+1) + {1 - UP} : (x'=x-1);
  [bold] x>0 & x<{N} & x<={N // 2} -> {UP} : (x'=2*x) + {1 - UP} : (x'=0);
  [bold] x>{N // 2} & x<{N} -> {UP} : (x'={N}) + {1 - UP} : (x'=2*x-{N});
endmodule
label "goal" = x={N};
"""


def test_a_flat_gap_is_jumped_at_the_forecast_and_holds_storms_exact_value(
        tmp_path: Path) -> None:
    path = tmp_path / "ruin.prism"
    path.write_text(PRISM, encoding="utf-8")
    exact = storm_rational(path, 'Pmax=? [F "goal"]')
    mdp = _ruin()
    r = interval_iteration(mdp, mdp.target, progress=False, compiled=False)
    assert r.status is Status.OPTIMAL, r.message
    lo, hi = Fraction(r.value_lower), Fraction(r.value_upper)
    # the iteration's vectors are rounded to nearest: its lower bound may sit one
    # rounding above the exact value (tests/test_rare_events.py), its upper not below
    assert lo <= exact * (1 + Fraction(1, 2**50)) and exact <= hi
    assert hi - lo <= Fraction(defaults.TOL)
    # jumped where the forecast gave up on the sweeps, well before their limit
    assert r.iterations < iteration._SWEEPS_BEFORE_POLICY, r.iterations
