"""What a band's answer reports for its expected steps, the band constrained answers
that used to end ``failed``, and a band whose laws' never masses differ (issue 43).

Independent routes:

* a hand calculation: on a world whose task is decided the step the bus comes, the
  expected steps are the bus's expected arrival step whatever the robot does, ``1 /
  h`` for a geometric hazard ``h``, and nature (maximising them) plays the band's low
  end: ``1 / 0.3 = 10 / 3``; for a band of tables of masses, the probability that the
  bus ever comes at the band's worst and best hazards;
* Storm's robust check (``R{"steps"}max``, uncertainty MAXIMIZE) of the exported
  interval chain, fully observed and seen through a sensor with false alarms;
* on the reacting world of tests/test_sensing_reacting_band.py, for a robot that sees
  the bus (no automaton, no information state): an occupancy LP in scipy over its
  histories at a constant law of the band (no controller meeting a bound under every
  law guarantees more than its optimum there), and an expectimin-max in exact
  arithmetic of the least risk a robot can keep when nature picks each step's hazard (a
  bound below it is met by no controller); the returned controller's worst cases by that
  file's enumeration in exact arithmetic.
"""

from __future__ import annotations

import importlib.util
import json
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy.optimize import linprog
from test_band_chain import storm_robust
from test_false_alarms_band_constrained import CONSTRAINT as ALARM_RISK
from test_false_alarms_band_constrained import model as alarm_model
from test_sensing_reacting_band import (
    CAUGHT,
    GAME,
    HORIZON,
    in_ditch,
    plan_value,
    verdict,
)
from test_sensing_reacting_band import model as reacting_model

from mitld_lp import ExplicitGame, Model, synthesize
from mitld_lp.cli import main
from mitld_lp.distributions import from_table

needs_storm = pytest.mark.skipif(importlib.util.find_spec("stormpy") is None,
                                 reason="needs stormpy")

MODELS = Path(__file__).resolve().parent.parent / "models"

# three states: "go" risks the ditch (h) half the time; the task is the bus b alone
THREE = ExplicitGame(initial="mid", labels={"d": {"h"}}, transitions={
    "mid": {"go": {"sa": 0.5, "d": 0.5}, "wait": {"mid": 1.0}},
    "sa": {"stay": {"sa": 1.0}}, "d": {"stay": {"d": 1.0}}})
BUS = Fraction(10, 3)  # 1 / 0.3: the bus's expected step at the band's low end


def three(**sensors: Any) -> Model:
    """The three-state world, the bus's hazard in [0.3, 0.6]."""
    law = from_table({"geometric": [0.3, 0.6]}, "mu")
    return Model.from_game(THREE, "D[mu] b & F b", distributions={"mu": law},
                           sensors=sensors)


@pytest.mark.parametrize("sensors", [{}, {"b": {"detect": 0.5}}],
                         ids=["fully-observed", "sensed"])
def test_expected_steps_without_then_are_the_band_s_worst_case(sensors: Any) -> None:
    """A constraint and no ``then`` nor steps bound: ``steps`` is the worst law's, 10/3
    seeing the bus (its geometric clock is exact); with the camera, whose information
    states cut the hypotheses at the truncation point ``T`` (the count stops there, as
    for every truncated run, docs/constraints.md), ``sum_{k < T} 0.7^k = (1 - 0.7^T) /
    0.3``.  At the middle law, where the answer's policy is solved, it would be about
    1 / 0.45 (what the sensed answer reported)."""
    r = synthesize(three(**sensors), constraints=["P(F h) <= 0.25"])
    assert r.status.value == "optimal" and r.bands and r.constraints[0].holds
    if sensors:
        cut = r.sta.truncation_points["b"]
        expected = (1 - Fraction(7, 10) ** cut) / Fraction(3, 10)
    else:
        expected = BUS
    assert r.steps == pytest.approx(float(expected), abs=1e-8)
    assert r.summary()["expected_at"] == "worst law"


def test_sensed_steps_at_the_chosen_law_say_so() -> None:
    """The camera on the three-state world with ``--bands best``: the steps are at the
    band's high end, ``sum_{k < T} 0.4^k = (1 - 0.4^T) / 0.6`` with ``T`` the
    truncation point, and the summary says they are at the chosen law."""
    r = synthesize(three(b={"detect": 0.5}), constraints=["P(F h) <= 0.25"], bands="best")
    cut = r.sta.truncation_points["b"]
    said = r.summary()
    assert said["expected_at"] == "chosen law" and said["bands_reading"] == "best"
    assert said["expected_steps"] == pytest.approx(
        float((1 - Fraction(2, 5) ** cut) / Fraction(3, 5)), abs=1e-8)


@needs_storm
def test_sensed_band_constrained_steps_are_storm_s_worst_case(tmp_path: Path) -> None:
    """A sensor with false alarms, a band and a risk bound, no ``then``: the answer's
    ``steps`` is Storm's worst case of the exported interval chain's steps (it was the
    chosen candidate's at its own law, 2.2005 against Storm's 2.5866)."""
    from mitld_lp.running.sensed_band_chain import write_sensed_band_chain

    r = synthesize(alarm_model(), constraints=[ALARM_RISK])
    assert r.route == "sensed-constrained" and r.controller is not None and r.then is None
    path = write_sensed_band_chain(r, tmp_path / "c.drn")
    assert abs(storm_robust(path, 'R{"steps"}max=? [F "done"]', maximise=True) - r.steps) <= 1e-8


@needs_storm
def test_fully_observed_band_constrained_steps_are_storm_s_worst_case(
        tmp_path: Path, capsys: Any) -> None:
    """bus_fit with a probability constraint, no ``then``: the answer's ``steps`` is
    Storm's worst case on the exported interval chain, and the printed ``E(steps)`` says
    it is the worst law's."""
    from mitld_lp.model import load_model
    from mitld_lp.running.band_mixture_chain import write_mixture_chain

    path, risk = MODELS / "bus_fit.toml", "P(F A) >= 0.3"
    r = synthesize(load_model(path), constraints=[risk])
    storm = storm_robust(write_mixture_chain(r, tmp_path / "c.drn"),
                         'R{"steps"}max=? [F "decided"]', maximise=True)
    assert abs(storm - r.steps) <= 1e-7
    assert main(["solve", str(path), "--constraint", risk, "-q"]) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if x.startswith("E(steps)"))
    assert line == f"E(steps):     {r.steps:.6g}  (at the worst law of the bands)"


def test_steps_at_the_best_law_say_so(capsys: Any) -> None:
    """``--bands best``: the steps are those at the law the answer chose, and the line
    says that it is no worst case; with ``then = "min-steps"`` on the three-state world
    nature helps the robot decide the task soonest, the band's high end: 1 / 0.6."""
    assert main(["solve", str(MODELS / "bus_fit.toml"), "--constraint", "E(steps) <= 9",
                 "--bands", "best", "-q"]) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if x.startswith("E(steps)"))
    assert line.endswith("(at the law of the bands the answer chose, not a worst case)")
    r = synthesize(three(), constraints=["P(F h) <= 0.25"], then="min-steps", bands="best")
    assert r.part.reading == "best" and r.steps == pytest.approx(1 / 0.6, abs=1e-7)



@pytest.mark.parametrize(("file", "reading", "at"), [
    ("bus_fit.toml", "worst", "worst law"), ("bus_fit.toml", "best", "chosen law"),
    ("bus_risk.toml", "worst", None)], ids=["band-worst", "band-best", "point-law"])
def test_the_json_says_which_law_the_steps_are_at(file: str, reading: str, at: str | None,
                                                   capsys: Any) -> None:
    """``--json``'s ``expected_at``: a band answer's ``expected_steps`` are the worst
    law's, with ``--bands best`` the law the answer chose; a point law has none (its
    steps are still reported), and the printed line says the same."""
    args = ["solve", str(MODELS / file), "--constraint", "E(steps) <= 9", "--bands", reading]
    assert main([*args, "--json"]) == 0
    said = json.loads(capsys.readouterr().out)
    assert said["expected_at"] == at and said["expected_steps"] > 0
    assert main([*args, "-q"]) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if x.startswith("E(steps)"))
    assert line.endswith(")") == (at is not None)


@pytest.mark.parametrize(("reading", "at", "steps"), [
    ("worst", "worst law", BUS), ("best", "chosen law", Fraction(5, 3))])
def test_the_summary_labels_the_hand_computed_steps(reading: str, at: str,
                                                   steps: Fraction) -> None:
    """The library's summary on the three-state world, whose steps are the bus's
    expected arrival step whatever the robot does: ``1 / 0.3`` at the worst law
    (``"worst law"``), ``1 / 0.6`` at the law ``--bands best`` chooses with ``then =
    "min-steps"`` (``"chosen law"``); ``then``'s value is at the same law."""
    r = synthesize(three(), constraints=["P(F h) <= 0.25"], then="min-steps", bands=reading)
    said = r.summary()
    assert said["expected_at"] == at and said["bands_reading"] == reading
    assert said["expected_steps"] == pytest.approx(float(steps), abs=1e-7)
    assert said["secondary"] == pytest.approx(float(steps), abs=1e-6)

# ------------------------------------------------- the reacting world's band constraints

def history_lp(h: Fraction, risk: Fraction | None) -> float:
    """The best probability of CAUGHT over fully observed policies (the robot sees the
    bus) with ``P(F[0,3] h) <= risk`` (None: minimise the risk instead), the bus's
    hazard ``h`` at every step: an occupancy LP over the histories of GAME (trace, step
    of the bus), solved by scipy; NaN when infeasible."""
    nodes: list[tuple[tuple[str, ...], int | None]] = []
    index: dict[tuple[tuple[str, ...], int | None], int] = {}
    pairs: list[tuple[int, str]] = []  # (node, action): the LP's variables
    edges: list[tuple[int, int, float]] = []  # (pair, child node, probability)

    def node(trace: tuple[str, ...], k: int | None) -> int:
        key = (trace, k)
        if key not in index:
            index[key] = len(nodes)
            nodes.append(key)
            t, w = len(trace) - 1, trace[-1]
            if t < HORIZON and (verdict(GAME, CAUGHT, trace, k) is None
                                or in_ditch(trace, k) is None):
                for action in sorted(GAME.transitions[w]):
                    pair = len(pairs)
                    pairs.append((index[key], action))
                    for k2, pe in ([(t + 1, h), (None, 1 - h)] if k is None else [(k, 1)]):
                        events = frozenset({"b"}) if k2 == t + 1 else frozenset()
                        for nxt, pw in GAME.successors(w, action, events):
                            edges.append((pair, node((*trace, nxt), k2),
                                          float(pe) * float(pw)))
        return index[key]

    node((GAME.initial,), None)
    n, m = len(nodes), len(pairs)
    inflow = np.zeros((n, m))  # the mass each pair sends into each node
    for pair, child, p in edges:
        inflow[child, pair] += p
    out = np.zeros((n, m))
    for j, (i, _) in enumerate(pairs):
        out[i, j] = 1.0
    inner = out.sum(axis=1) > 0
    start = np.zeros(n)
    start[0] = 1.0
    # an inner node's mass leaves it by its actions; a leaf's mass is its inflow
    a_eq, b_eq = (out - inflow)[inner], start[inner]
    caught = np.array([bool(verdict(GAME, CAUGHT, tr, k)) for tr, k in nodes])
    ditch = np.array([bool(in_ditch(tr, k)) for tr, k in nodes])
    leaf = ~inner
    reach = inflow[leaf & caught].sum(axis=0)
    danger = inflow[leaf & ditch].sum(axis=0)
    if risk is None:
        got = linprog(danger, A_eq=a_eq, b_eq=b_eq, bounds=(0, None), method="highs")
        return float(got.fun)
    got = linprog(-reach, A_ub=danger[None, :], b_ub=[float(risk)], A_eq=a_eq, b_eq=b_eq,
                  bounds=(0, None), method="highs")
    return float(-got.fun) if got.status == 0 else float("nan")


ENDS = (Fraction(3, 10), Fraction(6, 10))


def test_a_tight_risk_on_the_reacting_world_is_met_under_every_law() -> None:
    """``P(F[0,3] h) <= 0.3`` with a camera (detect 0.5) on the reacting world: the
    search used to give up (``failed``, lower NaN); its candidates' bounds are now
    tightened as the fully observed route tightens them.  The returned controller's risk
    with nature making the ditch as likely as it can is within the bound, its task's
    worst case is ``lower`` (the enumeration, exactly), and neither end of the band lets
    a robot that sees the bus do better (the LP)."""
    r = synthesize(reacting_model(GAME, CAUGHT, 0.5), constraints=["P(F[0,3] h) <= 0.3"])
    assert r.status.value == "optimal" and r.controller is not None
    (v,) = r.constraints
    assert v.holds
    risk = plan_value(r.controller.plan, GAME, in_ditch, "0.5", 0, max)
    assert risk <= Fraction(3, 10)
    task = plan_value(r.controller.plan, GAME,
                      lambda trace, k: verdict(GAME, CAUGHT, trace, k), "0.5", 0, min)
    assert abs(task - Fraction(r.lower)) <= Fraction(1, 10**9)
    assert r.lower <= min(history_lp(h, Fraction(3, 10)) for h in ENDS) + 1e-9


def least_risk() -> Fraction:
    """The least probability of the ditch by step 3 a robot that sees the bus can keep
    when nature, seeing everything (the robot's action too), picks the bus's hazard at
    each step among the band's ends to make it most likely: an expectimin-max over the
    histories of GAME, in exact arithmetic (a robot that sees more does no worse than
    one acting on a camera's reports)."""
    def value(trace: tuple[str, ...], k: int | None) -> Fraction:
        t, w = len(trace) - 1, trace[-1]
        said = in_ditch(trace, k)
        if said is not None:
            return Fraction(int(said))
        best = None
        for action in sorted(GAME.transitions[w]):
            options = []
            for h in (ENDS if k is None else (None,)):
                v = Fraction(0)
                for k2, pe in ([(t + 1, h), (None, 1 - h)] if k is None else [(k, 1)]):
                    events = frozenset({"b"}) if k2 == t + 1 else frozenset()
                    for nxt, pw in GAME.successors(w, action, events):
                        v += pe * Fraction(str(pw)) * value((*trace, nxt), k2)
                options.append(v)
            worst = max(options)
            best = worst if best is None else min(best, worst)
        assert best is not None
        return best

    return value((GAME.initial,), None)


@pytest.mark.parametrize("detect", [0.5, 1.0], ids=["camera", "seen"])
def test_a_risk_no_policy_meets_is_infeasible_not_failed(detect: float) -> None:
    """``P(F[0,3] h) <= 0.25``: nature can make the ditch more likely than 0.25 against
    every robot that sees the bus (the enumeration), so against every controller; the
    answer says ``infeasible`` (it said ``failed``, feasibility unknown), with the
    constraint alone's robust optimum bracketing that least risk, for the camera and
    for the robot that sees the bus alike.  At each constant law of the band a robot
    seeing the bus could keep the risk below 0.25 (the LP): the adaptive nature of the
    band is what makes it infeasible."""
    least = least_risk()
    assert least > Fraction(1, 4)
    assert max(history_lp(h, None) for h in ENDS) < 0.25
    r = synthesize(reacting_model(GAME, CAUGHT, detect), constraints=["P(F[0,3] h) <= 0.25"])
    assert r.status.value == "infeasible" and r.controller is None
    assert "alone, seeing every event" in r.message
    said = r.message.split("over the bands in [")[1].split("]")[0]
    low, high = (float(x) for x in said.split(", "))
    assert low <= least <= high


def test_a_bound_only_some_laws_meet_is_infeasible(capsys: Any) -> None:
    """bus_fit with ``P(F[0,2] b1) >= 0.95``: the bus by step 2 has probability 1 -
    0.2^2 = 0.96 at the middle law (0.8) but 1 - 0.3^2 = 0.91 at the band's low end
    (0.7), whatever the robot does, by hand; the answer is ``infeasible`` (it was
    ``failed``, feasibility unknown), the constraint alone's robust optimum shown around
    0.91, exit 3."""
    assert main(["solve", str(MODELS / "bus_fit.toml"), "--constraint",
                 "P(F[0,2] b1) >= 0.95", "-q"]) == 3
    out = capsys.readouterr().out
    assert "status:       infeasible" in out
    assert "P(F[0,2] b1) >= 0.95: not met under every law of the bands" in out
    said = out.split("over the bands in [")[1].split("]")[0]
    low, high = (float(x) for x in said.split(", "))
    assert low <= 0.91 <= high and high - low < 1e-9


# ------------------------------------------------- a band whose never masses differ

def test_a_band_whose_never_masses_differ_is_solved_exactly_seeing_the_event() -> None:
    """The band of pmf [0.3, 0.3] and its neighbours pmf [0.2, 0.3], pmf [0.4, 0.3]
    (never with 0.4, 0.5, 0.3: no step has every law's survival within epsilon, which
    stopped every route): seeing the bus, its hazards are [0.2, 0.4] at step 1,
    [0.3/0.8, 0.3/0.6] at step 2 and 0 after, so the bus ever comes with probability
    at least 1 - 0.8 * (1 - 0.375) = 1/2 and at most 1 - 0.6 * (1 - 0.5) = 7/10, by
    hand; the robust route gives both exactly (nothing truncated), alone and with a
    constraint; the camera's route too (truncated at step 2, past which no law's bus
    comes: tests/test_sensed_never_differ.py), here where the robot has nothing to do;
    and where the band's hazard may stay positive for ever (a Poisson law among its
    laws, or a middle law that surely happens, ``pmf [0.5, 0.5]``, whose hazard past its
    support is 1 by convention: nature may bring the bus at any later step, and no step
    has the band's upper survival within a share of the middle law's never mass), which
    stopped the camera's route (issue 43): nature's least chance that the bus ever comes
    takes the least hazard at every step, by hand the Poisson law's ``e^-2`` and ``2e^-2
    / (1 - e^-2)`` at steps 1 and 2 and the tables' 0 after (``1 - (1 - e^-2) (1 -
    2e^-2 / (1 - e^-2)) = 3e^-2``), and ``0.4``, ``0.4 / 0.6`` then 0 for the second
    band (``1 - 0.6 / 3 = 0.8``); its controller's chain, nothing truncated, gives it
    (tests/test_sensed_never_tail.py)."""
    import math

    from mitld_lp.distributions import pmf
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
    seen = synthesize(sensed)
    assert seen.route == "sensed" and seen.certified
    assert seen.lower == pytest.approx(0.5, abs=1e-9) == seen.upper
    for unbounded, least in ((band_of_laws("mu", pmf([0.3, 0.3]), [
            pmf([0.2, 0.3]), from_table({"poisson": 2}, "mu")]), 3 * math.exp(-2)),
            (band_of_laws("mu", pmf([0.5, 0.5]), [pmf([0.4, 0.4]), pmf([0.6, 0.4])]), 0.8)):
        posed = Model.from_game(game, "D[mu] b & F b", distributions={"mu": unbounded},
                                sensors={"b": {"detect": 0.7}})
        r = synthesize(posed)
        assert r.route == "sensed" and r.lower == pytest.approx(least, abs=1e-9)
        assert r.lower <= r.upper + 1e-12 and r.width["truncation"] == 0.0
