"""The composition matrix with a sensor that misses its event: every task class x law
(a point law, a law that may never happen, a band) x extra (none, ``objective = "min"``,
a constraint, ``then``) on one small world with a camera on the event.  Each cell is
solved within the bounds of independent routes, or refused naming a combination that
docs/results.md's composition table lists as not solved (the table and this test name
the same cells).

The independent routes: what the robot can do seeing the event is an upper bound of what
it can do through a camera, and what it can do blind (``detect = 0``) a lower bound (for
a minimum the other way round), each solved on its own route; the exported chain of the
answer's controller, checked by Storm, gives at least ``lower``; a constraint holds.
"""

from __future__ import annotations

import dataclasses
import itertools
from fractions import Fraction
from pathlib import Path
from types import MappingProxyType

import pytest
from storm_exact import exact_fraction

from mitld_lp import GridWorld, Model, synthesize
from mitld_lp.distributions.literal import from_table
from mitld_lp.problem import ProblemError
from mitld_lp.sensing import Sensor

_TASKS = {  # class -> (spec, whether the spec asks for the event's law by D[mu] b)
    "co-safe": ("D[mu] b & F(b & F[0,2] goal)", True),
    "safety": ("G (b -> F[0,2] goal)", False),
    "obligation": ("G !puddle & D[mu] b & F(b & F[0,2] goal)", True),
}
_LAWS = {"point": {"geometric": 0.4}, "never": {"pmf": [0.3, 0.3]},
         "band": {"geometric": [0.3, 0.5]}}
_EXTRAS = {"none": {}, "min": {}, "constraint": {"constraints": ["P(F puddle) <= 0.2"]},
           "then": {"then": "min-steps"}}

#: The cells not solved yet, each with the words of its refusal: the rows of the
#: composition table (docs/results.md) that say "refused".
NOT_SOLVED: dict[tuple[str, str, str], str] = {}

TOL = 1e-7


def _model(task: str, law: str, detect: float | None, extra: str) -> Model:
    spec, asks = _TASKS[task]
    world = GridWorld.make(3, 2, start=(0, 0), slip=0.2,
                           regions={"goal": [(2, 1)], "puddle": [(1, 0)]})
    the_law = from_table(_LAWS[law], "mu")
    laws = {"distributions": {"mu": the_law}} if asks else {"events": {"b": the_law}}
    model = Model.from_game(world, spec, objective="min" if extra == "min" else "max",
                            epsilon=0.05, **laws)
    if detect is None:
        return model
    return dataclasses.replace(model, sensors=MappingProxyType({"b": Sensor(detect)}))


def _refusal(task: str, law: str, extra: str) -> str | None:
    return NOT_SOLVED.get((law, task, extra))


@pytest.mark.parametrize(("task", "law", "extra"),
                         list(itertools.product(sorted(_TASKS), sorted(_LAWS),
                                                sorted(_EXTRAS))))
def test_every_cell_with_a_sensor(task: str, law: str, extra: str, tmp_path: Path) -> None:
    kwargs = _EXTRAS[extra]
    camera = _model(task, law, 0.6, extra)
    said = _refusal(task, law, extra)
    try:
        r = synthesize(camera, **kwargs)
    except ProblemError as exc:
        assert said is not None, f"refused, not listed as refused: {exc}"
        assert said in str(exc)
        return
    assert said is None, f"listed as refused, but solved by {r.route}"
    assert r.route.startswith("sensed"), r.route
    # a band's worst case is certified where its bounds meet; else both bounds are sound
    # and the failed check says the gap
    assert r.certified or law == "band", r.summary()["failed_checks"]
    assert -TOL <= r.lower <= r.upper + TOL <= 1 + 2 * TOL
    seen = synthesize(_model(task, law, None, extra), **kwargs)
    blind = synthesize(_model(task, law, 0.0, extra), **kwargs)
    if extra == "min":  # seeing more can only lower the least probability
        assert seen.lower <= r.upper + TOL and r.lower <= blind.upper + TOL
    else:
        assert r.lower <= seen.upper + TOL and blind.lower <= r.upper + TOL
    if extra == "constraint":
        assert all(c.holds for c in r.constraints)
    if extra == "then":  # a second objective only after the first
        assert r.lower >= synthesize(camera).lower - 1e-5
        # certified steps are finite (a loop of the controller's with no way out said
        # inf, certified: tests/test_sensed_kept.py's blind robot)
        assert not r.certified or 0 <= r.secondary < float("inf"), r.secondary
    if law == "band":  # the controller's interval model: Storm's worst case is lower
        stormpy = pytest.importorskip("stormpy")
        from test_band_chain import storm_worst

        from mitld_lp.running.sensed_band_chain import sensed_band_claim, write_sensed_band_chain

        path = write_sensed_band_chain(r, tmp_path / "chain.drn")
        # a minimum's file is its complement's: Storm gives 1 - upper
        bound = 1 - r.upper if extra == "min" else r.lower
        assert abs(storm_worst(path) - bound) <= 1e-9
        assert abs(sensed_band_claim(r)[0] - bound) <= 1e-9
    elif extra != "min":  # the chain of the controller, checked by Storm
        stormpy = pytest.importorskip("stormpy")
        from mitld_lp.running.chain import write_chain

        path = write_chain(r, tmp_path / "chain.drn")
        chain = stormpy.build_model_from_drn[stormpy.Rational](str(path))
        got = stormpy.model_checking(chain, stormpy.parse_properties('P=? [F "accept"]')[0])
        value = exact_fraction(got.get_value(chain.initial_states[0]))
        assert Fraction(r.lower) <= value <= Fraction(r.upper), (value, r.lower, r.upper)


@pytest.mark.parametrize(("task", "extra"), list(itertools.product(sorted(_TASKS),
                                                                   sorted(_EXTRAS))))
def test_every_cell_with_a_sensor_and_the_best_law(task: str, extra: str,
                                                   tmp_path: Path) -> None:
    """The band read for its best law (``bands = "best"``) with the camera: solved within
    the fully observed best case (the robust routes' answer to the same problem), above
    the worst case (bands 'worst', the same camera) where that is quick, each constraint
    met, and the exported chain at nature's chosen law worth the claim by Storm (each
    constraint's label within its bound)."""
    kwargs = {**_EXTRAS[extra], "bands": "best"}
    camera = _model(task, "band", 0.6, extra)
    r = synthesize(camera, **kwargs)
    assert r.route.startswith("sensed") and r.summary()["bands_reading"] == "best"
    assert -TOL <= r.lower <= r.upper + TOL <= 1 + 2 * TOL
    seen = synthesize(_model(task, "band", None, extra), **kwargs)
    assert not seen.part.observation_based and seen.bands
    if extra == "min":  # nature and sight both help the robot make the task unlikely
        assert seen.lower <= r.lower + TOL
    else:
        assert r.upper <= seen.upper + TOL
    if extra == "none":  # (the worst case of the others: the cells above, slower)
        assert synthesize(camera).lower <= r.lower + TOL
    assert all(c.holds for c in r.constraints)
    pytest.importorskip("stormpy")
    from test_sensed_optimistic import storm_of

    from mitld_lp.running.chain import write_chain
    from mitld_lp.running.optimistic_chain import optimistic_claim

    storm = storm_of(write_chain(r, tmp_path / "chain.drn"))
    if extra in ("none", "min"):  # the best case's chain: Storm gives the claim
        claim = Fraction(optimistic_claim(r)[0])
        assert claim <= storm("accept") <= claim + Fraction(1, 10**9)
    else:  # the randomised controller's chain at the law it was solved at
        assert Fraction(r.lower) <= storm("accept") <= Fraction(r.upper)
    for i, v in enumerate(r.constraints, start=1):  # P(F puddle) <= 0.2 at nature's law
        assert storm(f"c{i}") <= Fraction(v.constraint.bound)
