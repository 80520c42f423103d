"""The door's bounded questions against Storm's exact engine on the same file and
property: the cumulative reward ``C<=k`` and the instantaneous reward ``I=k`` (max and
min), the reward-bounded probability ``F{"r"}<=b`` (max and min, ``<b``, a left side),
and expected rewards on a JANI file; the answer is compared as a fraction (no
tolerance) and lies in its certified bracket; the forms still refused are refused by
name (exit 2) and a bound past the budget stops naming its size (exit 3)."""

from __future__ import annotations

import json
import random
from fractions import Fraction
from pathlib import Path

import pytest

stormpy = pytest.importorskip("stormpy")
pytest.importorskip("flint")

from storm_exact import random_prism, storm_value  # noqa: E402

from mitld_lp.cli import main  # noqa: E402

DATA = Path(__file__).parent / "data"
WALK = str(DATA / "rewards.prism")
JANI = str(DATA / "rewards.jani")

# a small MDP with integer rewards: action rewards ("act"), state rewards ("st"), a
# zero-reward loop ("zero"); "goal" is s = 2
INTEGER = """mdp
module m
  s : [0..3] init 0;
  [a] s=0 -> 1/2 : (s'=1) + 1/2 : (s'=0);
  [b] s=0 -> 1/3 : (s'=2) + 2/3 : (s'=3);
  [c] s=1 -> 1/2 : (s'=2) + 1/2 : (s'=1);
  [d] s>=2 -> true;
endmodule
rewards "act"
  [a] true : 1;
  [b] true : 2;
  [c] true : 1;
endrewards
rewards "st"
  s=0 : 1;
  s=2 : 5;
endrewards
rewards "zero"
  [a] true : 0;
  [c] true : 1;
endrewards
label "goal" = s=2;
"""


def ours(capsys: pytest.CaptureFixture[str], path: str, *argv: str) -> tuple[int, list[dict]]:
    code = main(["solve", path, "--json", "-q", *argv])
    lines = capsys.readouterr().out.strip().splitlines()
    return code, [json.loads(line) for line in lines]


def check(answer: dict, value: Fraction) -> None:
    assert answer["certified"] and Fraction(answer["value"]) == value
    assert Fraction(answer["lower"]) <= value <= Fraction(answer["upper"])


@pytest.mark.parametrize("prop", [
    'R{"cost"}max=? [C<=3]', 'R{"cost"}min=? [C<=3]', 'R{"time"}max=? [C<=4]',
    'R{"time"}min=? [C<=4]', 'Rmax=? [C<2]', 'R{"cost"}max=? [C<=0]',
    'R{"time"}max=? [I=2]', 'R{"time"}min=? [I=2]', 'R{"time"}min=? [I=5]',
    'R{"time"}max=? [I=0]'])
@pytest.mark.parametrize("idle", ["true", "false"])
def test_step_bounded_rewards_are_storms(capsys, prop: str, idle: str) -> None:
    code, [answer] = ours(capsys, WALK, "--prop", prop, "--const", f"N=3,IDLE={idle}")
    assert code == 0
    # R without a name is the file's first structure (PRISM's rule; Storm calls it
    # ambiguous), "cost"
    named = prop.replace("Rmax", 'R{"cost"}max')
    check(answer, storm_value(WALK, named, {"N": 3, "IDLE": idle == "true"}))
    assert answer["kind"] == ("cumulative" if "[C" in prop else "instantaneous")


def test_cumulative_by_hand(capsys) -> None:
    """Two steps of the walk (N = 3): max takes two jumps (3/2 each, the second only if
    the first was not lost, 5/6), 3/2 + 5/6 * 3/2 = 11/4; min idles at cost 0."""
    _, [high] = ours(capsys, WALK, "--prop", 'R{"cost"}max=? [C<=2]', "--const",
                     "N=3,IDLE=true")
    _, [low] = ours(capsys, WALK, "--prop", 'R{"cost"}min=? [C<=2]', "--const",
                    "N=3,IDLE=true")
    assert Fraction(high["value"]) == Fraction(11, 4) and Fraction(low["value"]) == 0


def test_instantaneous_without_state_rewards_is_zero(capsys) -> None:
    """``cost`` has action rewards only: the state reward at any step is 0 (Storm
    declines it as trivially 0)."""
    _, [answer] = ours(capsys, WALK, "--prop", 'R{"cost"}max=? [I=2]', "--const",
                       "N=3,IDLE=true")
    assert answer["value"] == "0" and "no state rewards" in answer["why"]


@pytest.mark.parametrize("prop", [
    'Pmax=? [F{"act"}<=3 "goal"]', 'Pmin=? [F{"act"}<=3 "goal"]',
    'Pmax=? [F{"act"}<=2 "goal"]', 'Pmax=? [F{"act"}<=1 "goal"]',
    'Pmax=? [F{"st"}<=2 "goal"]', 'Pmin=? [F{"st"}<=4 "goal"]',
    'Pmax=? [F{"zero"}<1 "goal"]', 'Pmax=? [F{"act"}<=5/2 "goal"]',
    'Pmax=? [s!=1 U{"act"}<=3 "goal"]', 'Pmin=? [s<2 U{"zero"}<=2 "goal"]'])
def test_reward_bounded_is_storms(capsys, tmp_path, prop: str) -> None:
    path = tmp_path / "integer.prism"
    path.write_text(INTEGER)
    code, [answer] = ours(capsys, str(path), "--prop", prop)
    assert code == 0
    check(answer, storm_value(str(path), prop, {}))


def test_reward_bounded_by_hand(capsys, tmp_path) -> None:
    """``F{"act"}<=2``: b reaches the goal at once w.p. 1/3 (reward 2); a then c needs
    reward 2 and succeeds w.p. 1/2 * 1/2; so Pmax = 1/3 and, with 3, a-a-c, a-c-c and
    b give Pmax = max(1/3, 1/2 (1/2 (1/4) + ...)) = 13/24 (Storm agrees above)."""
    path = tmp_path / "integer.prism"
    path.write_text(INTEGER)
    _, [two] = ours(capsys, str(path), "--prop", 'Pmax=? [F{"act"}<=2 "goal"]')
    assert Fraction(two["value"]) == Fraction(1, 3)
    # by hand for <=3: a first (w.p. 1/2 to s=1 with 1 spent: c, c reach w.p. 3/4; w.p.
    # 1/2 stay at s=0 with 1 spent: b fits (1/3)) = 1/2 * 3/4 + 1/2 * 1/3 = 13/24
    _, [three] = ours(capsys, str(path), "--prop", 'Pmax=? [F{"act"}<=3 "goal"]')
    assert Fraction(three["value"]) == Fraction(3, 8) + Fraction(1, 6)


@pytest.mark.parametrize("seed", range(4))
def test_random_models_against_storm(capsys, tmp_path, seed: int) -> None:
    rng = random.Random(seed)
    path = tmp_path / f"random{seed}.prism"
    path.write_text(random_prism(rng, rng.randint(4, 7), integer=True))
    for prop in ('Pmax=? [F{"r"}<=3 "goal"]', 'Pmin=? [F{"r"}<=2 "goal"]',
                 'R{"r"}max=? [C<=4]', 'R{"r"}min=? [C<=4]', 'R{"r"}max=? [I=3]',
                 'R{"r"}min=? [I=3]'):
        _, [answer] = ours(capsys, str(path), "--prop", prop)
        try:
            value = storm_value(str(path), prop, {})
        except RuntimeError as exc:  # I=k without state rewards: "trivially 0" to Storm
            assert "trivially 0" in str(exc)
            value = Fraction(0)
        assert Fraction(answer["value"]) == value, (seed, prop)


def test_jani_rewards_are_storms(capsys) -> None:
    """The JANI file's own properties (Emin over cost until goal, Emax over time until
    stop: infinity with the idle loop, Emin of time at step 2) and R properties on it."""
    code, answers = ours(capsys, JANI, "--const", "N=3", "--exact")
    assert code == 0 and [a["property"] for a in answers] == ["cost_min", "time_max",
                                                             "time_at"]
    model, props = stormpy.parse_jani_model(JANI)
    model, props = stormpy.instantiate_constants(model, {"N": 3}, props)
    built = stormpy.build_model[stormpy.Rational](model, props)
    env = stormpy.Environment()
    env.solver().force_exact = True
    for answer, prop in zip(answers, props, strict=True):
        value = str(stormpy.model_checking(built, prop, environment=env).get_value(
            built.initial_states[0]))
        if value == "inf":
            assert answer["value"] == "inf"
        else:
            check(answer, Fraction(value))
    for prop in ('R{"cost"}max=? [C<=3]', 'R{"time"}min=? [C<=3]', 'R{"time"}max=? [I=1]',
                 'R{"cost"}min=? [F "stop"]'):
        _, [answer] = ours(capsys, JANI, "--prop", prop, "--const", "N=3", "--exact")
        check(answer, storm_value(JANI, prop, {"N": 3}))
    # without --exact an expected reward until a target is the float route's bracket
    for prop in ('R{"cost"}min=? [F "stop"]', 'R{"cost"}min=? [F "goal"]'):
        code, [answer] = ours(capsys, JANI, "--prop", prop, "--const", "N=3")
        value = storm_value(JANI, prop, {"N": 3})
        assert code == 0 and answer["certified"]
        assert Fraction(answer["lower"]) <= value <= Fraction(answer["upper"])


@pytest.mark.parametrize("path, prop, says", [
    (WALK, 'Pmax=? [F{"cost"}>=2 "goal"]', "a lower bound or an interval is not answered"),
    (WALK, 'Pmax=? [F{"cost"}[1,3] "goal"]', "a lower bound or an interval"),
    (WALK, 'Pmax=? [F{"cost"}<=3, {"time"}<=2 "goal"]', "several bounds on one until"),
    (WALK, 'Pmax=? [F{"cost"}<=3 "goal"]', "not a non-negative integer"),
    (WALK, 'Pmax=? [F{"money"}<=3 "goal"]', 'no reward structure "money"'),
    (WALK, 'Pmax=? [F{"cost"}<0 "goal"]', "no collected reward is below 0"),
    (WALK, 'R{"cost"}max=? [LRA]', "a long-run average reward LRA is refused"),
    (JANI, 'Rmin=? [F "goal"]', "which reward structure is meant"),
])
def test_refused_by_name_exit_2(capsys, path: str, prop: str, says: str) -> None:
    assert main(["solve", path, "--prop", prop, "--const", "N=3" + (
        ",IDLE=true" if path == WALK else ""), "-q"]) == 2
    err = capsys.readouterr().err
    assert says in err and "Traceback" not in err


def test_budgets_stop_naming_the_size(capsys, tmp_path) -> None:
    """A reward bound whose unfolding may pass max_states, and a step bound whose work
    passes the floating-point bracket's budget (past the exact one), stop before the
    work with the size (exit 3)."""
    path = tmp_path / "integer.prism"
    path.write_text(INTEGER)
    assert main(["solve", str(path), "--prop", 'Pmax=? [F{"act"}<=100 "goal"]',
                 "--max-world-states", "50", "-q"]) == 3
    err = capsys.readouterr().err
    assert "it may take 405" in err and "max_states = 50" in err and "states (it may take" in err
    assert main(["solve", str(path), "--prop", 'R{"act"}max=? [C<=100000000]', "-q"]) == 3
    err = capsys.readouterr().err
    assert "100,000,000 steps" in err and "HORIZON_MAX_WORK" in err


def test_unfolding_by_hand_with_a_left_side() -> None:
    """0 -> 1 (reward 0) or 0 -> target 2 w.p. 1/2, back to 0 w.p. 1/2 (reward 1); 1 ->
    2 (reward 0).  With bound 1: through 1 the target is sure (Pmax = 1); where the left
    side excludes state 1 only the retry is left, once within the bound: Pmax = 1/2;
    Pmin = 0 in both (0 -> 1 then stuck there when 1 is excluded; with 1 allowed, the
    retry twice costs 2 > 1, so 1/2)."""
    import numpy as np

    from mitld_lp.exact.reward_bounded import solve_reward_bounded
    from mitld_lp.worlds.prism_rewards import RewardMDP
    from mitld_lp.worlds.properties import Query
    from mitld_lp.worlds.reward_bounded import RewardBounded

    def model(left):
        return RewardMDP(groups=np.array([0, 2, 3, 4]), indptr=np.array([0, 1, 3, 4, 5]),
                         indices=np.array([1, 2, 0, 2, 2]),
                         probabilities=(Fraction(1), Fraction(1, 2), Fraction(1, 2),
                                        Fraction(1), Fraction(1)),
                         rewards=(Fraction(0), Fraction(1), Fraction(0), Fraction(0)),
                         target=np.array([False, False, True]), initial=0, left=left)

    def value(left, sense: str) -> Fraction:
        posed = RewardBounded(query=Query(name="1", text="", spec="", objective=sense),
                              reward="r", bound=1, reward_query=None)
        return solve_reward_bounded(model(left), posed).value

    assert value(None, "max") == 1 and value(None, "min") == Fraction(1, 2)
    excluded = np.array([True, False, False])
    assert value(excluded, "max") == Fraction(1, 2) and value(excluded, "min") == 0


@pytest.mark.parametrize("seed", range(3))
def test_float_bracket_past_the_exact_budget_holds_storms_value(capsys, tmp_path, monkeypatch,
                                                                seed: int) -> None:
    """Past the exact budget (here every step-bounded reward is past it) C<=k and I=k
    are answered by the floating-point bracket: Storm's exact value inside it, the
    bracket narrow."""
    from mitld_lp.exact import horizon
    from mitld_lp.exact.errors import ExactTooLarge

    check = horizon.check_horizon

    def past(model, steps, *budget):  # the exact budget passed, the float one kept
        if not budget:
            raise ExactTooLarge("past the budget")
        check(model, steps, *budget)

    monkeypatch.setattr(horizon, "check_horizon", past)
    rng = random.Random(100 + seed)
    path = tmp_path / "random.prism"
    path.write_text(random_prism(rng, rng.randint(4, 7)))
    for prop in ('R{"r"}max=? [C<=30]', 'R{"r"}min=? [C<=30]', 'R{"r"}max=? [I=7]'):
        code, [answer] = ours(capsys, str(path), "--prop", prop)
        assert code == 0 and answer["certified"] and answer["value"] is None
        try:
            value = storm_value(str(path), prop, {})
        except RuntimeError:  # I=k without state rewards: 0
            value = Fraction(0)
        lower, upper = Fraction(answer["lower"]), Fraction(answer["upper"])
        assert lower <= value <= upper and upper - lower <= Fraction(1, 10**9) * (1 + value)


def test_constants_of_the_file_in_a_step_bound(capsys, tmp_path) -> None:
    """``C<=K`` over the file's open constant K, given with --const, is a number."""
    path = tmp_path / "k.prism"
    path.write_text(INTEGER.replace("mdp\n", "mdp\nconst int K;\n"))
    _, [answer] = ours(capsys, str(path), "--prop", 'R{"act"}max=? [C<=K]', "--const", "K=3")
    assert answer["steps"] == 3
    assert Fraction(answer["value"]) == storm_value(str(path), 'R{"act"}max=? [C<=3]', {"K": 3})
