"""The route chain (mitld_lp.routes.precedence): a new route is one class and one line
in the precedence list, with no edit anywhere else; every problem has one owner."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest

from mitld_lp import Model, synthesize
from mitld_lp.distributions.literal import from_table
from mitld_lp.problem import ProblemError
from mitld_lp.result import Part, Result
from mitld_lp.routes import precedence
from mitld_lp.routes.route import Route
from mitld_lp.routes.stages import build_task
from mitld_lp.synthesis import pose
from mitld_lp.worlds.grid import GridWorld

MARKER = "sweep me"


@dataclass(frozen=True, slots=True, eq=False)
class SweepPart(Part):
    """The toy route's own part of the answer."""

    sweeps: int = 0

    def policy_table(self, result: Result) -> list[dict[str, Any]]:
        return []

    def summary(self, result: Result) -> dict[str, Any]:
        return {"states": result.mdp.n_states, "choices": result.mdp.n_choices}


class SweepRoute(Route):
    """A toy route: the plain route's product, solved by plain value iteration (every
    state at once, from 0, truncation losing: a lower bound that rises to the lower
    model's optimum) on a model named MARKER only."""

    name = "value-sweep"

    def claims(self, posed: Any) -> bool:
        return posed.model.name == MARKER

    def refusal(self, posed: Any) -> list[str]:
        return [] if posed.problem.objective == "max" else ["value-sweep: maxima only"]

    def build(self, posed: Any, progress: bool | None = None) -> Any:
        return build_task(posed, progress)

    def solve(self, posed: Any, built: Any, **_: Any) -> Result:
        mdp = built.mdp
        goal = np.asarray(mdp.target, dtype=bool)
        v = goal.astype(float)
        state_of = mdp.choice_state()
        sweeps, change = 0, 1.0
        while change >= 1e-13:
            best = np.zeros(mdp.n_states)
            np.maximum.at(best, state_of, mdp.matrix @ v)
            new = np.where(goal, 1.0, best)
            sweeps, change, v = sweeps + 1, float(np.max(np.abs(new - v))), new
        from mitld_lp.solvers.result import Status

        value = float(v[mdp.initial])
        return Result(route=self.name, model=posed.model, objective="max", method="vi",
                      epsilon=posed.model.epsilon, status=Status.OPTIMAL, lower=value,
                      upper=value, value=value, certified=False, checks=(), controller=None,
                      sta=built.sta, mdp=mdp, timings=dict(built.timings),
                      part=SweepPart(sweeps), dta=built.dta)


def _model(name: str) -> Model:
    world = GridWorld.make(3, 2, start=(0, 0), slip=0.1, regions={"goal": [(2, 1)]})
    m = Model.from_game(world, "D[mu] b & F(b & F[0,2] goal)",
                        distributions={"mu": from_table({"geometric": 0.4}, "mu")})
    from dataclasses import replace

    return replace(m, name=name)


def test_a_new_route_is_one_class_and_one_line(monkeypatch: pytest.MonkeyPatch) -> None:
    """Registered at the head of the list, the toy route owns its marker problems
    through the public entry points (pose, synthesize, summary) with no other edit.  Its
    value, the lower truncation model's optimum by value iteration, lies in the plain
    route's certified bracket (an occupancy LP and a certificate: another algorithm)
    and equals its lower model's optimum within the solvers' tolerance."""
    monkeypatch.setattr(precedence, "ROUTES", [SweepRoute(), *precedence.ROUTES])
    plain = synthesize(_model("other"))
    assert plain.route == "plain"
    r = synthesize(_model(MARKER))
    assert r.route == "value-sweep" and isinstance(r.part, SweepPart) and r.part.sweeps > 1
    assert plain.lower - 1e-9 <= r.lower <= plain.upper + 1e-9
    assert r.lower == pytest.approx(plain.lower_model.value, abs=1e-8)
    said = r.summary()
    assert said["route"] == "value-sweep" and said["states"] == plain.mdp.n_states
    assert r.constraints == () and r.lower_model is None  # Part's defaults
    with pytest.raises(ProblemError, match="value-sweep: maxima only"):
        pose(_model(MARKER), objective="min")


def test_without_the_line_the_route_is_not_asked() -> None:
    assert pose(_model(MARKER)).route.name == "plain"


def test_no_route_claims_a_problem_gives_every_routes_reasons() -> None:
    """Asked only routes of another kind, pose names why each refuses."""
    from mitld_lp.routes.constrained import ConstrainedRoute
    from mitld_lp.routes.sensed import SensedRoute

    with pytest.raises(ProblemError) as info:
        pose(_model("x"), routes=(SensedRoute(), ConstrainedRoute()))
    assert any("sensed route" in why for why in info.value.reasons)


@pytest.mark.parametrize("routes", [None, "reversed"])
def test_every_problem_has_one_owner(routes: str | None) -> None:
    """The bundled routes' claims do not overlap: for each kind of problem one route
    claims it, so the precedence list's order decides nothing among them."""
    world = GridWorld.make(3, 2, start=(0, 0), slip=0.1, regions={"goal": [(2, 1)]})
    spec = "D[mu] b & F(b & F[0,2] goal)"
    cases = {
        "plain": (0.4, {}, ()),
        "robust": ([0.3, 0.5], {}, ()),
        "constrained": (0.4, {}, ("P(F goal) >= 0.1",)),
        "sensed": (0.4, {"b": {"detect": 0.5}}, ()),
    }
    for expected, (laws, sensors, cons) in cases.items():
        m = Model.from_game(world, spec, distributions={"mu": from_table({"geometric": laws},
                                                                          "mu")},
                            sensors=sensors)
        asked = precedence.ROUTES if routes is None else precedence.ROUTES[::-1]
        posed = pose(m, cons, routes=asked)
        assert posed.route.name == expected
        owners = [r for r in precedence.ROUTES if r.claims(posed)]
        assert len(owners) == 1
