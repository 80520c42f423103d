"""A sensor with false alarms and a law known only within a band read for its best law
(``bands = "best"``, issue 43): solved as without false alarms
(mitld_lp/routes/sensed_optimistic.py), each candidate a point-law solve with false
alarms whose chain draws every step's report; with constraints, ``then`` and the
trade-off curve a pair of a controller and a constant law of the band
(mitld_lp/routes/sensed_optimistic_constrained.py).

Independent routes: an enumeration in exact arithmetic, written here, of every hidden
scenario of a tiny world (the step the event comes, the sensor's report or silence at
every step: ``detect`` from the step the event comes, ``false_alarm`` before it) with
nature choosing each step's hazard among the band's two ends after seeing everything,
on the robot's side, the returned controller asked for its action after replaying each
observation history (no automaton, no information states, no chain); the same
enumeration over every deterministic observation-based policy (the optimum the bracket
must hold); the point-law answers with false alarms at the band's ends (nature may play
either end at every step, so the best case is at least each); and Storm, in exact
arithmetic, on the chain ``export --chain`` writes."""

from __future__ import annotations

import importlib.util
import json
from collections.abc import Callable
from fractions import Fraction
from pathlib import Path
from typing import Any

import pytest

from mitld_lp import ExplicitGame, Model, synthesize
from mitld_lp.controllers.observation import Observation
from mitld_lp.distributions import from_table
from mitld_lp.sensing import Sensor

needs_storm = pytest.mark.skipif(importlib.util.find_spec("stormpy") is None,
                                 reason="needs stormpy")

# the robot waits in "w" or goes: "go" puts it at the stop "s" (A) next step, then it
# walks round "r" and back to "w" (a round of 3 steps): at A at most once in any two
# steps, so a report of the bus tells it when to go, and a false alarm misleads it
WORLD = ExplicitGame(initial="w", labels={"s": {"A"}}, transitions={
    "w": {"go": {"s": 1.0}, "wait": {"w": 1.0}}, "s": {"on": {"r": 1.0}},
    "r": {"on": {"w": 1.0}}})
LAST = 3  # the bus must come by step LAST
TASKS = {"max": f"D[mu] b & F[0,{LAST}] (b & F[0,1] A)",  # at A the step b comes or next
         "min": f"D[mu] b & F[0,{LAST}] (b & !A)"}  # b comes while the robot is not at A
BAND, DETECT, ALARM = ("0.1", "0.3"), "0.7", "0.3"

Seen = tuple[tuple[str, frozenset[str]], ...]


def model(objective: str, band: tuple[str, str] = BAND, alarm: str = ALARM,
          detect: str = DETECT) -> Model:
    law = from_table({"geometric": [float(band[0]), float(band[1])] if band[0] != band[1]
                      else float(band[0])}, "mu")
    return Model.from_game(WORLD, TASKS[objective], objective=objective,
                           distributions={"mu": law},
                           sensors={"b": Sensor(float(detect), false_alarm=float(alarm))})


def verdict(objective: str, t: int, here: str, bus: int | None) -> int | None:
    """1 or 0 once the task is decided at step ``t`` in ``here`` with the bus at step
    ``bus`` (None: not yet), else None (the formulas of :data:`TASKS`, read by hand)."""
    at_a = here == "s"
    if objective == "max":
        if bus is not None and bus <= t <= bus + 1 and at_a:
            return 1
        late = bus is None and t >= LAST
        return 0 if late or (bus is not None and t >= bus + 1) else None
    if bus == t:
        return int(not at_a)
    return 0 if bus is None and t >= LAST else None


def enumerate_value(act: Callable[[Seen], str], objective: str, band: tuple[str, ...] = BAND,
                    alarm: str = ALARM, detect: str = DETECT,
                    judge: Callable[[str, int, str, int | None], int | None] = verdict,
                    num: Callable[[Any], Any] = Fraction) -> Any:
    """The task's probability (``judge``'s) under the robot's ``act`` (an observation
    history to an action) with nature picking the hazard of every step the bus has not
    come among the band's two ends, having seen everything, on the robot's side (the
    greatest for a maximum, the least for a minimum); the sensor reports at every step,
    with ``detect`` from the step the bus comes and ``alarm`` before it (``band`` of one
    hazard: that constant law); in fractions
    (``num=float``: in floats, for the searches over every policy)."""
    ends = [num(x) for x in band]
    said = {True: num(detect), False: num(alarm)}
    pick = max if objective == "max" else min
    memo: dict[tuple[int | None, Seen], Any] = {}

    def node(bus: int | None, seen: Seen) -> Any:
        key = (bus, seen)
        if key in memo:
            return memo[key]
        t, here = len(seen) - 1, seen[-1][0]
        decided = judge(objective, t, here, bus)
        if decided is not None:
            memo[key] = num(decided)
            return memo[key]
        action = act(seen)
        moves = WORLD.successors(here, action, frozenset())

        def then(bus2: int | None) -> Any:
            p = said[bus2 is not None]
            total = num(0)
            for report, pr in ((True, p), (False, 1 - p)):
                for there, pw in moves:
                    out = frozenset({"b"}) if report else frozenset()
                    total += pr * num(str(pw)) * node(bus2, (*seen, (there, out)))
            return total

        if bus is not None:
            memo[key] = then(bus)
        else:
            memo[key] = pick(h * then(t + 1) + (1 - h) * then(None) for h in ends)
        return memo[key]

    return node(None, ((WORLD.initial, frozenset()),))


def replayed(controller: Any) -> Callable[[Seen], str]:
    """The returned controller as an observation history's action, replayed from its
    start at every call."""
    def act(seen: Seen) -> str:
        controller.reset()
        action = controller.act(Observation(seen[0][0]))
        for here, reports in seen[1:]:
            action = controller.act(Observation(here, reports=reports))
        return action
    return act


def every_plan() -> list[dict[Seen, str]]:
    """Every deterministic observation-based policy up to step :data:`LAST`: a choice
    at each history ending in "w" its earlier choices reach, with the report or silence
    at every step ("on" is the only move elsewhere)."""
    def waits(seen: Seen, action: str) -> list[Seen]:
        out, todo = [], [(seen, action)]
        while todo:
            here, move = todo.pop()
            for there, _ in WORLD.successors(here[-1][0], move, frozenset()):
                for report in (frozenset(), frozenset({"b"})):
                    longer = (*here, (there, report))
                    if len(longer) > LAST + 1:
                        continue
                    if there == "w":
                        out.append(longer)
                    else:
                        todo.append((longer, "on"))
        return out

    def plans(frontier: list[Seen]) -> list[dict[Seen, str]]:
        if not frontier:
            return [{}]
        first, rest = frontier[0], frontier[1:]
        return [{first: a, **p} for a in ("go", "wait") for p in plans(rest + waits(first, a))]

    return plans([((WORLD.initial, frozenset()),)])


def following(plan: dict[Seen, str]) -> Callable[[Seen], str]:
    """A plan as an observation history's action ("on" where it has no choice)."""
    return lambda seen: plan.get(seen, "on")


def optimum(objective: str, band: tuple[str, str] = BAND) -> float:
    """The best over :func:`every_plan` of :func:`enumerate_value` (in floats)."""
    pick = max if objective == "max" else min
    return pick(enumerate_value(following(p), objective, band, num=float)
                for p in every_plan())


@pytest.mark.parametrize("objective", ["max", "min"])
def test_the_controllers_best_case_is_its_end_of_the_bracket(objective: str) -> None:
    """The returned controller replayed against every report pattern and nature's help
    at every step: ``lower`` for a maximum, ``upper`` for a minimum (from the sound side,
    within the iteration's stop); the optimum over every observation-based policy lies
    in the bracket."""
    r = synthesize(model(objective), bands="best")
    assert r.route == "sensed" and r.part.reading == "best" and r.bands
    own = enumerate_value(replayed(r.controller), objective)
    end = Fraction(r.lower if objective == "max" else r.upper)
    assert abs(own - end) <= Fraction(1, 10**9)
    assert (own >= end) if objective == "max" else (own <= end)
    best = optimum(objective)
    assert r.lower - 1e-12 <= best <= r.upper + 1e-12
    rest = r.upper - r.lower - r.width["truncation"]
    assert r.certified == (rest <= r.precision * (r.lower if objective == "max" else
                                                  1 - r.upper))


@pytest.mark.parametrize("objective", ["max", "min"])
def test_at_least_each_ends_point_law_answer_and_the_alarms_are_read(objective: str
                                                                      ) -> None:
    """Nature may play either end of the band at every step: the best case is at least
    each end's point-law optimum with false alarms (for a minimum at most); and the
    false alarms cost the robot something here: the optimum over every policy reading
    every report (the enumeration) is below what the controller of a camera without
    them achieves (0.5229 against 0.567)."""
    r = synthesize(model(objective), bands="best")
    for end in BAND:
        point = synthesize(model(objective, (end, end)))
        assert point.route == "sensed" and not point.bands
        if objective == "max":
            assert r.lower >= point.lower - 1e-12
        else:
            assert r.upper <= point.upper + 1e-12
    if objective == "max":  # (for the minimum here nature's help makes them moot)
        quiet = synthesize(model(objective, alarm="0"), bands="best")
        assert optimum(objective) < quiet.lower - 1e-3


@needs_storm
@pytest.mark.parametrize("objective", ["max", "min"])
def test_storm_on_the_exported_chain_gives_the_controllers_end(tmp_path: Path,
                                                              objective: str) -> None:
    """The chain at nature's chosen law (plain: every step's report drawn): Storm's
    exact ``P=? [F "accept"]`` is ``lower`` (for a minimum the complement's, ``1 -
    upper``), from above within the iteration's stop."""
    from test_robust_optimistic import storm_exact

    from mitld_lp.running.chain import write_chain

    r = synthesize(model(objective), bands="best")
    value = storm_exact(write_chain(r, tmp_path / "c.drn"))
    end = Fraction(r.lower) if objective == "max" else 1 - Fraction(r.upper)
    assert end - Fraction(1, 10**12) <= value <= end + Fraction(1, 10**9)


@needs_storm
@pytest.mark.parametrize("objective", ["max", "min"])
@pytest.mark.parametrize("task", ["safety", "obligation"])
def test_a_safety_part_on_the_chain_at_nature_s_law(task: str, objective: str,
                                                    tmp_path: Path) -> None:
    """A task with a safety part (tests/test_sensing_tasks.py's worlds: ``G !(b & A)``,
    and a catch with a ditch to avoid): Storm's exact value of the exported chain is the
    controller's end of the bracket, and that end is at least each band end's point-law
    optimum with false alarms (for a minimum at most)."""
    from test_robust_optimistic import storm_exact
    from test_sensing_tasks import PUSHED, STATION

    from mitld_lp.running.chain import write_chain

    world, spec = {"safety": (PUSHED, "G !(b & A)"),
                   "obligation": (STATION, "F(b & F[0,1] A) & G[0,5] !h")}[task]

    def posed(law: Any) -> Model:
        return Model.from_game(world, spec, objective=objective, epsilon=0.05,
                               events={"b": from_table({"geometric": law}, "mu")},
                               sensors={"b": {"detect": 0.6, "false_alarm": 0.2}})

    r = synthesize(posed([0.6, 0.9]), bands="best")
    assert r.route == "sensed" and r.part.reading == "best"
    value = storm_exact(write_chain(r, tmp_path / "c.drn"))
    end = Fraction(r.lower) if objective == "max" else 1 - Fraction(r.upper)
    assert end - Fraction(1, 10**12) <= value <= end + Fraction(1, 10**9)
    for h in (0.6, 0.9):
        point = synthesize(posed(h))
        if objective == "max":
            assert r.lower >= point.lower - 1e-12
        else:
            assert r.upper <= point.upper + 1e-12


GRID = """name = "wait_for_b"
spec = "D[mu] b & F[0,2] (b & F[0,1] A)"
grid = { size = [2, 2], start = [0, 0] }
regions = { A = [[1, 1]] }
distributions = { mu = { geometric = [0.3, 0.6] } }
[sensors]
b = { detect = 0.5, false_alarm = 0.2 }
"""


@needs_storm
def test_the_command_line_solves_and_exports_the_chain(tmp_path: Path, capsys) -> None:
    """``solve --bands best`` and ``export --bands best --chain`` on a model file with a
    false-alarm sensor: Storm's exact value of the written chain is ``lower``."""
    from test_robust_optimistic import storm_exact

    from mitld_lp.cli import main

    path = tmp_path / "wait.toml"
    path.write_text(GRID)
    code = main(["solve", str(path), "--bands", "best", "--json"])
    said = json.loads(capsys.readouterr().out)
    assert code in (0, 3) and said["bands_reading"] == "best"
    out = tmp_path / "c.drn"
    assert main(["export", str(path), "--bands", "best", "--chain", str(out),
                 "--json"]) == code
    exported = json.loads(capsys.readouterr().out)
    assert exported["chain_accept"] == said["lower"]
    storm = storm_exact(out)
    assert Fraction(said["lower"]) - Fraction(1, 10**12) <= storm
    assert storm <= Fraction(said["lower"]) + Fraction(1, 10**9)


def visits(objective: str, t: int, here: str, bus: int | None) -> int | None:
    """``F[0,LAST] A``, the constraints' formula below, read by hand."""
    if here == "s":
        return 1
    return 0 if t >= LAST else None


CONSTRAINED = {"max": ("P(F[0,3] A) <= 0.5", "<="), "min": ("P(F[0,3] A) >= 0.5", ">=")}


@pytest.mark.parametrize("objective", ["max", "min"])
def test_constraints_are_met_at_the_law_nature_chose(tmp_path: Path, objective: str
                                                     ) -> None:
    """With a constraint the answer is a pair (a controller reading every report, a
    constant law of the band) meeting it at that law: at least as good as every
    deterministic observation-based policy meeting it at one of the laws tried (the
    band's middle and ends, by the enumeration at a constant law); Storm on the chain at
    its law finds the task inside the bracket and the constraint met."""
    text, sense = CONSTRAINED[objective]
    r = synthesize(model(objective), bands="best", constraints=[text])
    assert r.route == "sensed-constrained" and r.summary()["bands_reading"] == "best"
    assert r.status == "optimal" and all(v.holds for v in r.constraints)
    pick = max if objective == "max" else min
    best = None
    half = Fraction(1, 2)
    for h in ("0.1", "0.2", "0.3"):
        for plan in every_plan():
            act = following(plan)
            c = enumerate_value(act, objective, (h,), judge=visits, num=float)
            if not (c <= 0.5 + 1e-12 if sense == "<=" else c >= 0.5 - 1e-12):
                continue
            v = enumerate_value(act, objective, (h,), num=float)
            best = v if best is None else pick(best, v)
    assert best is not None
    if objective == "max":  # the randomised optimum at a law tried does at least as well
        assert r.lower >= best - 1e-6 and best <= r.upper + 1e-9
    else:
        assert r.upper <= best + 1e-6 and best >= r.lower - 1e-9
    stormpy = pytest.importorskip("stormpy")
    from storm_exact import exact_fraction

    from mitld_lp.running.chain import write_chain

    chain = stormpy.build_model_from_drn[stormpy.Rational](
        str(write_chain(r, tmp_path / "c.drn")))

    def storm(label: str) -> Fraction:
        prop = stormpy.parse_properties(f'P=? [F "{label}"]')[0]
        return exact_fraction(stormpy.model_checking(chain, prop).get_value(
            chain.initial_states[0]))

    task = storm("accept") if objective == "max" else 1 - storm("accept")
    tol = Fraction(1, 10**9)
    assert Fraction(r.lower) - tol <= task <= Fraction(r.upper) + tol
    assert storm("c1") <= half + tol if sense == "<=" else storm("c1") >= half - tol


def test_then_and_the_trade_off_curve() -> None:
    """``then``: the task first, at least each constant law's point-law optimum with
    false alarms that the pair may be played at (up to the lexicographic LP's slack),
    the steps finite; the curve: each point a pair meeting its own bound, the task's
    value never falling as the bound on steps loosens."""
    from mitld_lp import pareto

    r = synthesize(model("max"), bands="best", then="min-steps")
    assert r.route == "sensed-constrained" and r.status == "optimal"
    ends = [synthesize(model("max", (h, h))).lower for h in BAND]
    assert r.lower >= max(ends) - 1e-5 and 0.0 < r.secondary < float("inf")
    points = pareto(model("max"), against="steps", bands="best", points=3)
    assert len(points) == 3 and all(p.status == "optimal" for p in points)
    assert all(p.achieved <= p.bound + 1e-9 for p in points)
    assert all(a.lower <= b.lower + 1e-9 for a, b in zip(points, points[1:], strict=False))


def test_a_band_that_may_never_happen() -> None:
    """A band of laws that leave the bus a chance of never coming (``pmf [0.3, 0.3]``
    and its neighbours: never with 0.4 at the middle law, 0.5 and 0.3 at the others, by
    hand): with constraints bracketed (tests/test_false_alarms_never_band_best.py), the
    blind end the optimistic constrained solve with the sensor blind (each candidate at a
    constant law, which the sensed constrained route truncates), done separately here;
    alone, camera with or without false alarms, the sensed route cuts this band, whose
    laws' never masses differ, at its last step (step 2: nothing truncated,
    tests/test_sensed_never_differ.py): the task needs the bus, which comes with
    probability at most ``1 - 3/5 * 1/2 = 7/10`` (nature's highest hazards, by hand), and
    the best case is that, certified."""
    from mitld_lp.distributions import pmf
    from mitld_lp.distributions.band import band_of_laws

    band = band_of_laws("mu", pmf([0.3, 0.3]), [pmf([0.2, 0.3]), pmf([0.4, 0.3])])
    assert band.is_ambiguous

    def posed(sensor: Sensor) -> Model:
        return Model.from_game(WORLD, TASKS["max"], distributions={"mu": band},
                               sensors={"b": sensor})

    r = synthesize(posed(Sensor(0.7, false_alarm=0.3)), bands="best",
                   constraints=["P(F A) <= 0.5"])
    blind = synthesize(posed(Sensor(0.0)), bands="best", constraints=["P(F A) <= 0.5"])
    assert r.status == "optimal" and all(v.holds for v in r.constraints)
    assert abs(r.lower - blind.lower) <= 1e-12 and r.lower < r.upper and not r.certified
    for sensor in (Sensor(0.7, false_alarm=0.3), Sensor(0.7)):
        alone = synthesize(posed(sensor), bands="best")
        assert alone.route == "sensed" and alone.certified
        assert alone.lower == pytest.approx(0.7, abs=1e-9) == alone.upper
