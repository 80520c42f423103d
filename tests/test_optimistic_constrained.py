"""Constraints and ``then`` with a band read for its best law (``bands = "best"``,
mitld_lp.routes.optimistic_constrained): the optimistic constrained optimum against an
occupancy LP over (robot action, corner law) pairs written here and solved by scipy's
linprog, and a brute force over corner-law sequences in exact fractions; the exported
chain at nature's chosen law checked by Storm."""

from __future__ import annotations

import itertools
import json
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from mitld_lp import ExplicitGame, Model, synthesize
from mitld_lp.cli import main
from mitld_lp.distributions import from_table

# the robot goes left (event a counts) or right (event b counts) once, then waits; the
# task: its side's event within 3 steps.  Both events have a band, so every waiting
# choice has two band events pending (four corners: the snapping to independent hazards
# is exercised).
SPEC = "D[mu] a & D[nu] b & F[0,3] ((a & atL) | (b & atR))"
MU, NU = (Fraction(1, 5), Fraction(1, 2)), (Fraction(1, 10), Fraction(3, 5))
STEPS = 3


def sides() -> Model:
    game = ExplicitGame(initial="s", transitions={
        "s": {"left": {"L": 1.0}, "right": {"R": 1.0}},
        "L": {"wait": {"L": 1.0}}, "R": {"wait": {"R": 1.0}}},
        labels={"L": ["atL"], "R": ["atR"]})
    return Model.from_game(game, SPEC, distributions={
        "mu": from_table({"geometric": [float(x) for x in MU]}, "mu"),
        "nu": from_table({"geometric": [float(x) for x in NU]}, "nu")})


def linprog_optimum(maximise: bool, right_at_most: float) -> float:
    """The (action, corner) LP written here: states s, (side, k) for k < STEPS waited;
    at s the robot goes left or right; at (side, k) nature and the robot pick together
    one of the four corners (h_mu, h_nu) of the bands, and the side's event comes with
    its hazard (won) or not (next k, lost after STEPS).  Occupancy variables, flow
    conservation, the constraint P(go right) <= right_at_most; scipy's HiGHS."""
    from scipy.optimize import linprog

    corners = list(itertools.product(MU, NU))
    states = ["s"] + [(side, k) for side in (0, 1) for k in range(STEPS)]
    index = {st: i for i, st in enumerate(states)}
    var: list[tuple[object, object]] = [("s", 0), ("s", 1)]  # left, right
    var += [((side, k), v) for side in (0, 1) for k in range(STEPS) for v in corners]
    a_eq = np.zeros((len(states), len(var)))
    b_eq = np.zeros(len(states))
    b_eq[index["s"]] = 1.0
    win = np.zeros(len(var))
    for j, (st, act) in enumerate(var):
        a_eq[index[st], j] += 1.0  # outflow
        if st == "s":
            a_eq[index[(act, 0)], j] -= 1.0
            continue
        side, k = st
        h = float(act[side])
        win[j] = h
        if k + 1 < STEPS:
            a_eq[index[(side, k + 1)], j] -= 1.0 - h
    a_ub = np.zeros((1, len(var)))
    a_ub[0, 1] = 1.0
    res = linprog(-win if maximise else win, A_ub=a_ub, b_ub=[right_at_most], A_eq=a_eq,
                  b_eq=b_eq, bounds=(0, None), method="highs")
    assert res.status == 0
    return float(win @ res.x)


def corner_brute_force(maximise: bool, right_at_most: Fraction) -> Fraction:
    """Nature cooperating picks the best sequence of corner laws on each side (exact);
    the robot then mixes the sides, going right with probability at most the bound:
    the optimum is at that bound or at 0 (a linear function of the mix)."""
    pick = max if maximise else min

    def reach(side: int) -> Fraction:
        return pick(1 - np.prod([1 - h[side] for h in seq], dtype=object)
                    for seq in itertools.product(itertools.product(MU, NU), repeat=STEPS))

    left, right = reach(0), reach(1)
    return pick(left, right_at_most * right + (1 - right_at_most) * left)


@pytest.mark.parametrize(("objective", "bound"), [("max", "1/2"), ("min", "1/2"),
                                                  ("max", "1/5")])
def test_the_optimistic_constrained_optimum_is_the_corner_lp(objective: str, bound: str
                                                              ) -> None:
    x = Fraction(bound)
    r = synthesize(sides(), constraints=[f"P(F atR) <= {float(x)!r}"], bands="best",
                   objective=objective)
    assert r.route == "constrained" and r.certified, r.summary()["failed_checks"]
    assert r.summary()["bands_reading"] == "best" and "guarantees nothing" in r.message
    exact = corner_brute_force(objective == "max", x)
    assert Fraction(r.lower) <= exact <= Fraction(r.upper)
    assert linprog_optimum(objective == "max", float(x)) == pytest.approx(float(exact),
                                                                         abs=1e-9)
    assert all(c.holds for c in r.constraints)
    (c,) = r.constraints
    assert c.value <= float(x) + 1e-9
    # the pessimistic answer is below (above, minimising) the optimistic one
    worst = synthesize(sides(), constraints=[f"P(F atR) <= {float(x)!r}"],
                       objective=objective)
    if objective == "max":
        assert worst.upper < r.lower
    else:
        assert worst.lower > r.upper


def test_then_with_the_best_law_is_the_point_law_at_the_helpful_ends() -> None:
    """Nature helping both the task and the speed, each hazard sits at its band's upper
    end at every step: the answer is the point-law problem at those ends (solved by the
    constrained LP of point laws, another route), value 1 - (2/5)^3 by hand."""
    r = synthesize(sides(), then="min-steps", bands="best")
    assert r.certified, r.summary()["failed_checks"]
    p = Fraction(3, 5)
    assert Fraction(r.lower) <= 1 - (1 - p) ** 3 <= Fraction(r.upper)
    worst = synthesize(sides(), then="min-steps")
    assert worst.upper < r.lower
    go = {row["action"]: row["probability"] for row in r.policy_table()
          if row["game_state"] == "s"}
    assert go["right"] > 0.999
    point = Model.from_game(sides().game, SPEC, distributions={
        "mu": from_table({"geometric": float(MU[1])}, "mu"),
        "nu": from_table({"geometric": float(NU[1])}, "nu")})
    at_ends = synthesize(point, then="min-steps")
    assert at_ends.route == "constrained"
    assert r.lower == pytest.approx(at_ends.lower, abs=1e-6)
    assert r.steps == pytest.approx(at_ends.steps, abs=1e-4)


_FILE = """name = "sides"
spec = "D[mu] a & D[nu] b & F[0,3] ((a & atL) | (b & atR))"
constraints = ["P(F atR) <= 0.5"]
grid = { size = [3, 1], start = [1, 0] }
regions = { atL = [[0, 0]], atR = [[2, 0]] }
[distributions]
mu = { geometric = [0.2, 0.5] }
nu = { geometric = [0.1, 0.6] }
"""


def test_the_chain_at_natures_chosen_law_gives_lower_in_storm(tmp_path: Path,
                                                             capsys) -> None:
    stormpy = pytest.importorskip("stormpy")
    path = tmp_path / "sides.toml"
    path.write_text(_FILE)
    out = tmp_path / "c.drn"
    code = main(["export", str(path), "--bands", "best", "--chain", str(out), "--json"])
    said = json.loads(capsys.readouterr().out)
    assert code == 0 and out.exists()
    model = stormpy.build_model_from_drn(str(out))
    storm = stormpy.model_checking(model, stormpy.parse_properties('P=? [F "accept"]')[0])
    value = float(storm.get_value(model.initial_states[0]))
    assert said["lower"] - 1e-9 <= value <= said["upper"] + 1e-9
    assert value == pytest.approx(said["lower"], abs=1e-6)
