"""The float route of expected rewards (the default; ``--exact`` is
tests/test_door_rewards.py) against Storm's exact engine on the same PRISM file and
property: the certified bracket holds Storm's rational value, compared as fractions with
no tolerance; ``inf`` exactly where Storm says infinity; a model past the exact budget is
answered by this route and refused by the rational one."""

from __future__ import annotations

import json
import random
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

stormpy = pytest.importorskip("stormpy")

from storm_exact import PROPS, random_prism, storm_value  # noqa: E402

from mitld_lp.cli import main  # noqa: E402

DATA = Path(__file__).parent / "data"
WALK = str(DATA / "rewards.prism")


def ours(capsys: pytest.CaptureFixture[str], *argv: str, path: str = WALK
         ) -> tuple[int, list[dict]]:
    code = main(["solve", path, "--json", "-q", *argv])
    lines = capsys.readouterr().out.strip().splitlines()
    return code, [json.loads(line) for line in lines]


def inside(answer: dict, value: Fraction | None) -> bool:
    """The answer is Storm's: ``inf`` for infinity, else a certified bracket holding the
    rational value, compared exactly."""
    if value is None:
        return answer["value"] == "inf" and answer["infinite"]
    return (answer["certified"] and not answer["infinite"]
            and Fraction(answer["lower"]) <= value <= Fraction(answer["upper"]))


@pytest.mark.parametrize("idle", ["true", "false"])
@pytest.mark.parametrize("prop", PROPS)
def test_bracket_holds_storms_exact_value(capsys, prop: str, idle: str) -> None:
    code, [answer] = ours(capsys, "--prop", prop, "--const", f"N=3,IDLE={idle}")
    value = storm_value(WALK, prop, {"N": 3, "IDLE": idle == "true"})
    assert code == 0 and inside(answer, value), (prop, idle, answer)
    assert "exact" not in answer  # the float route says no fraction
    if value is not None:  # the bracket is tight: the rounding, not a loose bound
        assert float(answer["upper"]) - float(answer["lower"]) <= 1e-8 * (1 + float(value))


@pytest.mark.parametrize("seed", range(8))
def test_random_models_against_storm(capsys, tmp_path, seed: int) -> None:
    rng = random.Random(100 + seed)
    path = tmp_path / f"random{seed}.prism"
    path.write_text(random_prism(rng, rng.randint(4, 9)))
    for prop in ('R{"r"}min=? [F "goal"]', 'R{"r"}max=? [F "goal"]'):
        code, [answer] = ours(capsys, "--prop", prop, path=str(path))
        assert code == 0 and inside(answer, storm_value(str(path), prop, {})), (seed, prop)


ZERO_LOOP = """mdp
module m
  s : [0..3] init 0;
  [wait] s=0 -> 1/3 : (s'=0) + 2/3 : (s'=1);
  [back] s=1 -> 1/2 : (s'=0) + 1/2 : (s'=1);
  [out0] s=0 -> 3/4 : (s'=2) + 1/4 : (s'=1);
  [out1] s=1 -> (s'=2);
  [end] s=2 -> true;
endmodule
rewards "c"
  [out0] true : 7/2;
  [out1] true : 5;
endrewards
label "goal" = s=2;
"""


def test_zero_reward_end_component_min(capsys, tmp_path) -> None:
    """``wait`` and ``back`` make a zero-reward end component from which both exits
    cost: Rmin is the cheaper way out.  Leaving by out0 costs 7/2 and then, w.p. 1/4,
    reaches s=1 from where the free loop may return: by hand ``v0 = min(7/2 + v1/4,
    v1)``, ``v1 = min(5, v0)`` gives ``v0 = v1``, ``v0 = 7/2 + v0/4``: 14/3 < 5."""
    path = tmp_path / "loop.prism"
    path.write_text(ZERO_LOOP)
    code, [answer] = ours(capsys, "--prop", 'R{"c"}min=? [F "goal"]', path=str(path))
    assert storm_value(str(path), 'R{"c"}min=? [F "goal"]', {}) == Fraction(14, 3)
    assert code == 0 and inside(answer, Fraction(14, 3))
    _, [most] = ours(capsys, "--prop", 'R{"c"}max=? [F "goal"]', path=str(path))
    assert most["value"] == "inf"  # the loop may be kept for ever: not reached w.p. 1


def test_past_the_exact_budget_the_float_route_answers(capsys, monkeypatch, tmp_path) -> None:
    """The exact route's transitions budget lowered below a walk of N = 12: ``--exact``
    stops naming it (exit 3), the default answers with a bracket holding Storm's value."""
    from mitld_lp import defaults

    monkeypatch.setattr(defaults, "EXACT_MAX_TRANSITIONS", 40)
    prop = 'R{"time"}min=? [F "stop"]'
    constants = {"N": 12, "IDLE": True}
    assert main(["solve", WALK, "--prop", prop, "--const", "N=12,IDLE=true", "-q",
                 "--exact"]) == 3
    assert "EXACT_MAX_TRANSITIONS" in capsys.readouterr().err
    code, [answer] = ours(capsys, "--prop", prop, "--const", "N=12,IDLE=true")
    value = storm_value(WALK, prop, constants)
    assert code == 0 and answer["choices"] > 0 and inside(answer, value)


def test_without_python_flint_the_float_route_answers(capsys, monkeypatch) -> None:
    import sys

    monkeypatch.setitem(sys.modules, "flint", None)
    prop = 'R{"cost"}min=? [F "stop"]'
    code, [answer] = ours(capsys, "--prop", prop, "--const", "N=3,IDLE=true")
    assert code == 0 and inside(answer, storm_value(WALK, prop, {"N": 3, "IDLE": True}))


def test_occupancy_lp_agrees_and_its_policy_is_optimal(capsys) -> None:
    """The LP's objective (the cross-check) lies within its tolerance of the bracket,
    and the line names it."""
    prop = 'R{"cost"}min=? [F "stop"]'
    _, [answer] = ours(capsys, "--prop", prop, "--const", "N=4,IDLE=false")
    value = storm_value(WALK, prop, {"N": 4, "IDLE": False})
    assert answer["lp_status"] == "optimal"
    assert abs(answer["lp_value"] - float(value)) <= 1e-6 * (1 + float(value))
    assert main(["solve", WALK, "--prop", prop, "--const", "N=4,IDLE=false"]) == 0
    assert "occupancy LP" in capsys.readouterr().out


def test_cycle_by_hand_in_the_library() -> None:
    """0 -> 1 (reward 1), 1 -> 0 or the target w.p. 1/2 each (reward 1): E0 = 1 + E1,
    E1 = 1 + E0 / 2, so E0 = 4; a probability stored 1 ulp off still brackets 4 (the
    allowance), and a reward of 0.1 (not a double) brackets 4 * 1/10 = 2/5."""
    from mitld_lp.solvers.reward import solve_reward_float
    from mitld_lp.worlds.prism_rewards import RewardMDP

    def model(half: float, reward: float) -> RewardMDP:
        return RewardMDP(groups=np.array([0, 1, 2, 3]), indptr=np.array([0, 1, 3, 4]),
                         indices=np.array([1, 0, 2, 2]),
                         probabilities=np.array([1.0, half, 1.0 - half, 1.0]),
                         rewards=np.array([reward, reward, 0.0]),
                         target=np.array([False, False, True]), initial=0)

    for sense in ("min", "max"):
        a = solve_reward_float(model(0.5, 1.0), sense)
        assert a.certified and Fraction(a.lower) <= 4 <= Fraction(a.upper)
        b = solve_reward_float(model(np.nextafter(0.5, 1.0), 1.0), sense)
        assert b.certified and Fraction(b.lower) <= 4 <= Fraction(b.upper)
        c = solve_reward_float(model(0.5, 0.1), sense)
        assert c.certified and Fraction(c.lower) <= Fraction(2, 5) <= Fraction(c.upper)
