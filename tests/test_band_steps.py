"""A band whose laws' never masses differ (issue 43).

Independent route: a hand calculation of the probability that the bus ever comes at
the band's worst and best hazards.
"""

from __future__ import annotations

from typing import Any

import pytest

from mitld_lp import ExplicitGame, Model, synthesize
from mitld_lp.distributions import from_table

# three states: "go" risks the ditch (h) half the time; the task is the bus b alone
THREE = ExplicitGame(initial="mid", labels={"d": {"h"}}, transitions={
    "mid": {"go": {"sa": 0.5, "d": 0.5}, "wait": {"mid": 1.0}},
    "sa": {"stay": {"sa": 1.0}}, "d": {"stay": {"d": 1.0}}})


def three(**sensors: Any) -> Model:
    """The three-state world, the bus's hazard in [0.3, 0.6]."""
    law = from_table({"geometric": [0.3, 0.6]}, "mu")
    return Model.from_game(THREE, "D[mu] b & F b", distributions={"mu": law},
                           sensors=sensors)


# ------------------------------------------------- a band whose never masses differ

def test_a_band_whose_never_masses_differ_is_solved_exactly_seeing_the_event() -> None:
    """The band of pmf [0.3, 0.3] and its neighbours pmf [0.2, 0.3], pmf [0.4, 0.3]
    (never with 0.4, 0.5, 0.3: no step has every law's survival within epsilon, which
    stopped every route): seeing the bus, its hazards are [0.2, 0.4] at step 1,
    [0.3/0.8, 0.3/0.6] at step 2 and 0 after, so the bus ever comes with probability
    at least 1 - 0.8 * (1 - 0.375) = 1/2 and at most 1 - 0.6 * (1 - 0.5) = 7/10, by
    hand; the robust route gives both exactly (nothing truncated), alone and with a
    constraint; the camera's route still stops on it, naming the law."""
    from mitld_lp.distributions import DistributionError, pmf
    from mitld_lp.distributions.band import band_of_laws

    band = band_of_laws("mu", pmf([0.3, 0.3]), [pmf([0.2, 0.3]), pmf([0.4, 0.3])])
    game = ExplicitGame(initial="s", labels={}, transitions={"s": {"w": {"s": 1.0}}})
    m = Model.from_game(game, "D[mu] b & F b", distributions={"mu": band})
    worst, best = synthesize(m), synthesize(m, bands="best")
    assert worst.route == "robust" and worst.certified and best.certified
    assert worst.lower == pytest.approx(0.5, abs=1e-9) == worst.upper
    assert best.lower == pytest.approx(0.7, abs=1e-9) == best.upper
    assert all(c.truncation is None for c in worst.sta.clocks.values())
    m3 = Model.from_game(THREE, "D[mu] b & F b", distributions={"mu": band})
    r = synthesize(m3, constraints=["P(F h) <= 0.25"])  # the constrained route too
    assert r.status.value == "optimal" and r.lower == pytest.approx(0.5, abs=1e-8)
    sensed = Model.from_game(game, "D[mu] b & F b", distributions={"mu": band},
                             sensors={"b": {"detect": 0.7}})
    with pytest.raises(DistributionError, match="mu: .*allows an event that never happens"):
        synthesize(sensed)
