"""The trade-off curve (``pareto``) with a camera and a law known only within a band, its
worst case (``bands = "worst"``, each point the sensed band constrained route's answer)
and its best case (``bands = "best"``, the sensed optimistic constrained route's),
checked against the constrained optima at the band's end laws, posed as point laws on
the sensed constrained route: a controller meeting the bound under every law of the band
is worth at most the best one at either end law (the worst case's ``lower`` is at most
each end's ``upper``), and the best law's optimum is at least the optimum at either
end (the best case's ``upper`` is at least each end's ``lower``)."""

from __future__ import annotations

import dataclasses
from types import MappingProxyType

import pytest

from mitld_lp import GridWorld, Model, pareto, synthesize_constrained
from mitld_lp.distributions.literal import from_table
from mitld_lp.problem import ProblemError, pose_on
from mitld_lp.routes.sensed_constrained import SensedConstrainedRoute
from mitld_lp.sensing import Sensor

TOL = 1e-7
BAND = {"geometric": [0.3, 0.5]}


def _camera(law: dict, detect: float = 0.6) -> Model:
    world = GridWorld.make(3, 2, start=(0, 0), slip=0.2, regions={"A": [(2, 1)]})
    model = Model.from_game(world, "D[mu] b & F(b & F[0,2] A)", epsilon=0.05,
                            distributions={"mu": from_table(law, "mu")})
    return dataclasses.replace(model, sensors=MappingProxyType({"b": Sensor(detect)}))


def _at_ends(bound: float) -> list:
    """The sensed constrained optimum under ``E(steps) <= bound`` at each end law."""
    return [synthesize_constrained(_camera({"geometric": p}), [f"E(steps) <= {bound!r}"])
            for p in BAND["geometric"]]


@pytest.mark.parametrize("bands", ["worst", "best"])
def test_pareto_with_a_camera_and_a_band(bands: str) -> None:
    points = pareto(_camera(BAND), "steps", 3, bands=bands)
    assert len(points) == 3 and [p.bound for p in points] == sorted(p.bound for p in points)
    solved = [p for p in points if p.status == "optimal"]
    assert solved, points  # the loosest bound is met (by the unconstrained policy)
    for p in solved:
        assert -TOL <= p.lower <= p.upper + TOL <= 1 + TOL
        ends = _at_ends(p.bound)
        if bands == "worst":  # no better than the best controller at either end law
            assert all(p.lower <= e.upper + TOL for e in ends if e.status == "optimal")
        else:  # at least what either end law allows, below the fully observed bound
            assert all(e.lower <= p.upper + TOL for e in ends if e.status == "optimal")
    # a looser bound is worth at least a tighter one
    lows = [p.lower for p in solved]
    assert all(a <= b + TOL for a, b in zip(lows, lows[1:], strict=False))


def test_the_band_on_a_point_law_route_says_which_route_takes_it() -> None:
    """A route list holding only the sensed constrained route (which reads laws as
    points) refuses the band with constraints naming the routes that take it."""
    with pytest.raises(ProblemError, match="sensed band constrained route's"):
        pose_on([SensedConstrainedRoute()], _camera(BAND), ["E(steps) <= 5"])
