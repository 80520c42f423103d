"""Constraints, ``then`` and the trade-off curve with a sensor that gives false alarms on
a bus law that may never happen (``pmf(0.25, 0.25, 0.25)``: never with 0.25, by hand):
bracketed on route sensed-constrained (mitld_lp/routes/sensed_never.py) between the
constrained optimum of the controller that ignores the reports (the one returned) and
that of a sensor without false alarms at least as informative.

The independent value is tests/test_false_alarms_constrained.py's occupancy LP over every
step's report history (scipy), with the bus that never comes as a bus after the horizon:
every hypothesis's task is decided by step 5 and the risk after the horizon is the least
one from the world state, so the cut at the horizon is exact.  At ``detect = false_alarm
= 0`` the same LP is the blind controllers' optimum.  Storm re-checks the returned
controller's exported chain: its task value and each constraint's."""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path
from typing import Any

import pytest
from test_false_alarms_constrained import STEPS, every_step_lp, storm
from test_sensed_constrained import HORIZON, STATION, best

from mitld_lp import Model, synthesize
from mitld_lp.routes.sensed_never import informed_detect

#: the bus at step 1, 2 or 3; the remaining 0.25 (never) as a bus after the horizon
LAW = (0.25, 0.25, 0.25)
NEVER = (*LAW, *([0.0] * (HORIZON - len(LAW))), 0.25)
SPEC = f"D[pmf({', '.join(map(str, LAW))})] b & F(b & F[0,2] A)"
CHECK = "false alarms, law that may never happen"


def _model(detect: float, false_alarm: float) -> Model:
    return Model.from_game(STATION, SPEC, sensors={"b": {"detect": detect,
                                                         "false_alarm": false_alarm}})


@pytest.fixture(scope="module")
def lps() -> dict[tuple[float, float], dict[str, Any]]:
    """The every-step LPs of the blind sensor and of the two posed ones, by (detect,
    false alarm)."""
    return {(d, f): every_step_lp(d, f, NEVER)
            for d, f in ((0.0, 0.0), (0.8, 0.2), (0.3, 0.6))}


@pytest.mark.parametrize("detect, false_alarm", [(0.8, 0.2), (0.3, 0.6)])
@pytest.mark.parametrize("bound", [0.1, 0.3])
def test_the_bracket_holds_the_every_step_lp(detect: float, false_alarm: float,
                                             bound: float, lps: dict, tmp_path: Path) -> None:
    """A risk constraint that binds, a sensor better and one worse than its false alarms:
    ``lower`` is the blind controllers' constrained optimum (the LP at ``detect = 0``),
    the every-step LP's optimum lies in the bracket, which is certified only where its
    ends meet (here they do not: the reports are worth reading); Storm on the exported
    chain gives the task value ``lower`` and the risk within its bound."""
    from mitld_lp.running.chain import write_chain

    r = synthesize(_model(detect, false_alarm), constraints=[f"P(F wet) <= {bound}"])
    assert r.route == "sensed-constrained"
    rows = [("wet", "<=", bound)]
    blind = best(lps[(0.0, 0.0)], "task", True, rows)
    exact = best(lps[(detect, false_alarm)], "task", True, rows)
    assert abs(r.lower - blind) <= 1e-7
    assert r.lower - 1e-7 <= exact <= r.upper + 1e-7
    assert blind < exact - 1e-3  # the reports are worth reading ...
    check = next(c for c in r.checks if c.name == CHECK)
    assert not check.passed and not r.certified and "not read" in check.detail
    assert r.width["information"] > 1e-3  # ... and the bracket says so
    (c,) = r.constraints
    assert c.holds and Fraction(c.bounds[1]) <= Fraction(str(bound))
    path = write_chain(r, tmp_path / "c.drn")
    assert abs(storm(path, 'P=? [F "accept"]') - Fraction(r.lower)) <= Fraction(1, 10**8)
    assert storm(path, 'P=? [F "c1"]') <= Fraction(str(bound))


def test_a_slack_constraint_meets_where_the_reports_cannot_help(lps: dict) -> None:
    """Without a binding constraint the blind optimum is the every-step one (the robot
    can wait at the stop for every bus): the ends meet, certified, and both LPs give
    ``lower``."""
    r = synthesize(_model(0.8, 0.2), constraints=["P(F wet) <= 0.9"])
    rows = [("wet", "<=", 0.9)]
    for lp in (lps[(0.0, 0.0)], lps[(0.8, 0.2)]):
        assert abs(best(lp, "task", True, rows) - r.lower) <= 1e-7
    assert r.certified and next(c for c in r.checks if c.name == CHECK).passed


def test_then_min_steps_is_the_blind_controllers(tmp_path: Path) -> None:
    """``then min-steps``: the first objective's ends meet (every bus can be waited
    for), the steps are the returned (blind) controller's, Storm's total reward on its
    chain, and the blind camera's lexicographic answer (a sensor that never reports,
    solved without the bracket); the informed end's are fewer, so the check fails
    saying so."""
    from mitld_lp.running.chain import write_chain

    r = synthesize(_model(0.8, 0.2), then="min-steps")
    assert r.route == "sensed-constrained" and r.upper - r.lower <= 1e-5
    plain_blind = synthesize(_model(0.0, 0.0), then="min-steps")
    assert r.secondary == pytest.approx(plain_blind.secondary, abs=1e-6)
    path = write_chain(r, tmp_path / "c.drn")
    assert float(storm(path, STEPS)) == pytest.approx(r.secondary, abs=1e-6)
    assert abs(storm(path, 'P=? [F "accept"]') - Fraction(r.lower)) <= Fraction(1, 10**8)
    check = next(c for c in r.checks if c.name == CHECK)
    informed = synthesize(_model(informed_detect(0.8, 0.2), 0.0), then="min-steps")
    assert informed.secondary < r.secondary - 1e-3
    assert not check.passed and "then min-steps" in check.detail


def test_failed_where_only_reading_the_reports_may_meet_the_constraints(
        lps: dict, capsys: pytest.CaptureFixture[str]) -> None:
    """Risk at most 0.1 and the task at least 0.2: no blind controller meets both (the
    LP at ``detect = 0`` is infeasible) but one reading every report does (the every-step
    LP is feasible): ``failed``, no controller, ``upper`` the informed optimum's bound
    (at least the every-step LP's optimum), which ``solve`` prints with the reason (exit
    3); with the task at least 0.3 infeasible even reading the reports (the every-step
    LP too): ``infeasible``."""
    from argparse import Namespace

    from mitld_lp.cli import constrained as cli
    from mitld_lp.synthesis import pose

    rows = [("wet", "<=", 0.1)]
    exact = best(lps[(0.8, 0.2)], "task", True, rows)
    assert best(lps[(0.0, 0.0)], "task", True, rows) < 0.2 < exact < 0.3
    task = "P(F(b & F[0,2] A))"
    asked = ["P(F wet) <= 0.1", f"{task} >= 0.2"]
    r = synthesize(_model(0.8, 0.2), constraints=asked)
    assert r.status == "failed" and r.controller is None and not r.certified
    assert r.lower != r.lower and exact <= r.upper + 1e-7
    assert "infeasibility is not proved" in r.message
    assert cli.solve(Namespace(json=False), pose(_model(0.8, 0.2), asked), None) == 3
    out = capsys.readouterr().out
    assert "optimum in:   [nan, 0.22" in out and "infeasibility is not proved" in out
    said = [ln for ln in out.splitlines() if ln.startswith("constraint:")]
    assert len(said) == 2 and all(ln.endswith(": no controller returned") for ln in said)
    r = synthesize(_model(0.8, 0.2), constraints=["P(F wet) <= 0.1", f"{task} >= 0.3"])
    assert r.status == "infeasible" and r.controller is None


def test_minimum_with_a_constraint(tmp_path: Path) -> None:
    """``objective = "min"`` with a constraint that sends the robot to the stop (``P(F[2,4]
    A) >= 0.5``): ``upper`` is the returned controller's value, that of the blind camera
    solved on its own (a sensor that never reports: no bracket), ``lower`` the informed
    camera's (``detect = 0.75``, no false alarms) solved on its own; Storm on the
    exported chain (the complement's, as for every minimum with constraints) gives ``1 -
    upper`` and the constraint met."""
    from mitld_lp.running.chain import write_chain

    cons = ["P(F[2,4] A) >= 0.5"]
    r = synthesize(_model(0.8, 0.2), objective="min", constraints=cons)
    assert r.route == "sensed-constrained" and r.status == "optimal"
    blind = synthesize(_model(0.0, 0.0), objective="min", constraints=cons)
    informed = synthesize(_model(informed_detect(0.8, 0.2), 0.0), objective="min",
                          constraints=cons)
    assert informed_detect(0.8, 0.2) == pytest.approx(0.75)  # (0.8 - 0.2) / (1 - 0.2)
    assert r.upper == blind.upper and r.lower == informed.lower < r.upper - 1e-3
    assert not r.certified
    path = write_chain(r, tmp_path / "c.drn")
    assert abs(1 - storm(path, 'P=? [F "accept"]') - Fraction(r.upper)) <= Fraction(1, 10**8)
    assert storm(path, 'P=? [F "c1"]') >= Fraction(1, 2) - Fraction(1, 10**9)


def test_pareto_points_hold_the_every_step_lp(lps: dict) -> None:
    """The trade-off curve against the risk: each point's bracket holds the every-step
    LP's optimum at its bound, its ``lower`` the blind LP's (each point this route's
    answer)."""
    from mitld_lp.tradeoff import pareto

    points = pareto(_model(0.8, 0.2), "P(F wet)", points=3)
    assert len(points) == 3
    for p in points:
        rows = [("wet", "<=", p.bound)]
        exact = best(lps[(0.8, 0.2)], "task", True, rows)
        assert abs(p.lower - best(lps[(0.0, 0.0)], "task", True, rows)) <= 1e-6
        assert p.lower - 1e-6 <= exact
        assert p.upper != p.upper or exact <= p.upper + 1e-6  # NaN: no bound, said
        assert p.achieved <= p.bound + 1e-9


def test_the_randomised_controller_runs_dropping_the_reports(tmp_path: Path) -> None:
    """The returned randomised controller, simulated with every step's report drawn
    (false alarms included, the bus that never comes too), succeeds at ``lower``'s rate
    and meets no observation it cannot read; saved and run by :mod:`mitld_lp.runtime`,
    it plays the live controller's actions, and so does a copy never given a report:
    it ignores them."""
    import numpy as np

    from mitld_lp.controllers.observation import Observation
    from mitld_lp.runtime import load
    from mitld_lp.sensing.observe import simulate_sensed

    model = _model(0.8, 0.2)
    r = synthesize(model, constraints=["P(F wet) <= 0.3"])
    sim = simulate_sensed(model, r.controller, runs=2000, seed=5, max_steps=20)
    sigma = (r.lower * (1 - r.lower) / sim.runs) ** 0.5
    assert abs(sim.estimate - r.lower) <= 4.5 * sigma and sim.beyond_model == 0
    saved = r.controller.save(tmp_path / "c.npz")
    loaded, deaf = load(saved), load(saved)
    rng = np.random.default_rng(7)
    for run in range(30):
        r.controller.reset(seed=run)
        loaded.reset(seed=run)
        deaf.reset(seed=run)
        bus = int(rng.choice(len(NEVER), p=NEVER)) + 1  # past the horizon: never
        w, reports = STATION.initial, frozenset()
        for t in range(HORIZON + 2):
            a = r.controller.act(Observation(w, reports=reports))
            assert loaded.act(w, reports=reports) == a == deaf.act(w, reports=frozenset())
            if a is None:
                break
            succ = STATION.successors(w, a, frozenset())
            w = succ[int(rng.choice(len(succ), p=[p for _, p in succ]))][0]
            q = 0.8 if t + 1 >= bus else 0.2
            reports = frozenset({"b"}) if rng.random() < q else frozenset()
