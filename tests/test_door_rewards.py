"""``mitld-lp solve FILE.prism --prop 'R{"r"}min=? [F target]' --exact`` against Storm's
exact engine on the same file and property (the float route, the default, is
tests/test_rewards_float.py): the answer is the exact optimum (compared as a
fraction, no tolerance) inside its certified bracket, ``inf`` exactly where Storm says
infinity (a target not reached with probability 1), and the reward forms not answered
are refused by name (exit 2)."""

from __future__ import annotations

import json
import random
from fractions import Fraction
from pathlib import Path

import pytest

stormpy = pytest.importorskip("stormpy")
pytest.importorskip("flint")

from storm_exact import PROPS, random_prism, storm_value  # noqa: E402

from mitld_lp.cli import main  # noqa: E402

DATA = Path(__file__).parent / "data"
WALK = str(DATA / "rewards.prism")


def storm_exact(prop: str, constants: dict, path: str = WALK) -> Fraction | None:
    """Storm's exact value of ``prop`` at the initial state (None for infinity)."""
    return storm_value(path, prop, constants)


def ours(capsys: pytest.CaptureFixture[str], *argv: str, path: str = WALK
         ) -> tuple[int, list[dict]]:
    code = main(["solve", path, "--json", "-q", "--exact", *argv])
    lines = capsys.readouterr().out.strip().splitlines()
    return code, [json.loads(line) for line in lines]


@pytest.mark.parametrize("idle", ["true", "false"])
@pytest.mark.parametrize("prop", PROPS)
def test_exact_value_is_storms(capsys, prop: str, idle: str) -> None:
    code, [answer] = ours(capsys, "--prop", prop, "--const", f"N=3,IDLE={idle}")
    assert code == 0 and answer["certified"]
    value = storm_exact(prop, {"N": 3, "IDLE": idle == "true"})
    if value is None:
        assert answer["value"] == "inf" and answer["infinite"]
        assert answer["lower"] is None and answer["upper"] is None  # JSON has no inf
    else:
        assert Fraction(answer["value"]) == value, (prop, idle)
        assert Fraction(answer["lower"]) <= value <= Fraction(answer["upper"])
    assert answer["objective"] == ("min" if "min" in prop else "max")


def test_closed_form_of_the_safe_walk(capsys) -> None:
    """Without the jump (it can be lost), each step costs 1 and succeeds w.p. 1/2: the
    least expected cost to reach x = N is 2N; the idle loop (cost 0) cannot replace it."""
    for n in (1, 4):
        _, [answer] = ours(capsys, "--prop", 'R{"cost"}min=? [F "goal"]', "--const",
                           f"N={n},IDLE=true")
        assert Fraction(answer["value"]) == 2 * n


def test_unnamed_reward_is_the_first_structure(capsys) -> None:
    _, [answer] = ours(capsys, "--prop", 'Rmin=? [F "stop"]', "--const", "N=3,IDLE=true")
    assert answer["reward"] == "cost"
    value = storm_exact('R{"cost"}min=? [F "stop"]', {"N": 3, "IDLE": True})
    assert Fraction(answer["value"]) == value


def test_properties_file_mixing_p_and_r(capsys, tmp_path) -> None:
    props = tmp_path / "mixed.props"
    props.write_text('"p": Pmax=? [F "goal"];\n"c": R{"cost"}min=? [F "stop"];\n'
                     '"t": R{"time"}max=? [F "goal"];\n"q": Pmin=? [F "stop"];\n')
    code, answers = ours(capsys, "--prop", str(props), "--const", "N=3,IDLE=false")
    assert code == 0 and [a["property"] for a in answers] == ["p", "c", "t", "q"]
    constants = {"N": 3, "IDLE": False}
    for a, prop in zip(answers, ['Pmax=? [F "goal"]', 'R{"cost"}min=? [F "stop"]',
                                 'R{"time"}max=? [F "goal"]', 'Pmin=? [F "stop"]'],
                       strict=True):
        value = storm_exact(prop, constants)
        assert a["certified"]
        if value is None:
            assert a["value"] == "inf"
        else:
            assert Fraction(a["lower"]) <= value <= Fraction(a["upper"]), prop
    _, [one] = ours(capsys, "--prop", str(props), "c", "--const", "N=3,IDLE=false")
    assert one["property"] == "c" and one["reward"] == "cost"


def test_line_says_inf_and_why(capsys) -> None:
    assert main(["solve", WALK, "--prop", 'R{"cost"}max=? [F "stop"]', "--const",
                 "N=3,IDLE=true", "-q"]) == 0
    out = capsys.readouterr().out
    assert "= inf" in out and "not reached with probability 1 under some scheduler" in out


def test_without_python_flint_an_expected_reward_is_refused_by_name(capsys, monkeypatch) -> None:
    """The rational solve needs the exact extra: without python-flint the property is
    refused with the install line (exit 2), not a traceback."""
    import sys

    monkeypatch.setitem(sys.modules, "flint", None)  # import flint raises ImportError
    assert main(["solve", WALK, "--prop", 'R{"cost"}min=? [F "stop"]', "--const",
                 "N=3,IDLE=true", "-q", "--exact"]) == 2
    err = capsys.readouterr().err
    assert "python-flint" in err and "mitld_lp[exact]" in err and "Traceback" not in err


@pytest.mark.parametrize("prop, says", [
    ('R{"cost"}max=? [C]', "a total reward C is refused"),
    ('R{"cost"}max=? [C<=5/2]', "the steps must be a non-negative integer"),
    ('R{"cost"}min=? [F<=3 "goal"]', "a reward-bounded or time-bounded F is refused"),
    ('R=? [C<=3]', "R=? without min or max is refused"),
    ('S=? ["goal"]', "a long-run average (S) is refused"),
    ('multi(Pmax=? [F "goal"], R{"cost"}min=? [F "stop"])', "a multi-objective query"),
    ('R{"cost"}max=? [LRA]', "long-run average reward LRA is refused"),
    ('T=? [F "goal"]', "T=? without min or max is refused"),
    ('Tmin=? [F<=3 "goal"]', "a reward-bounded or time-bounded F is refused"),
    ('R{"cost"}<=3 [LRA]', "long-run average reward LRA is refused"),
    ('R=? [F "goal"]', "R=? without min or max is refused"),
    ('R{"money"}min=? [F "goal"]', 'no reward structure "money"'),
    ('R{"cost"}min=? [F<=3 "goal"]', "is refused"),
])
def test_refused_by_name_exit_2(capsys, prop: str, says: str) -> None:
    assert main(["solve", WALK, "--prop", prop, "--const", "N=3,IDLE=true", "-q"]) == 2
    err = capsys.readouterr().err
    assert says in err and "error:" in err


@pytest.mark.parametrize("seed", range(6))
def test_random_models_against_storm(capsys, tmp_path, seed: int) -> None:
    rng = random.Random(seed)
    path = tmp_path / f"random{seed}.prism"
    path.write_text(random_prism(rng, rng.randint(4, 9)))
    for prop in ('R{"r"}min=? [F "goal"]', 'R{"r"}max=? [F "goal"]'):
        code, [answer] = ours(capsys, "--prop", prop, path=str(path))
        assert code == 0
        value = storm_exact(prop, {}, str(path))
        if value is None:
            assert answer["value"] == "inf", (seed, prop)
        else:
            assert Fraction(answer["value"]) == value, (seed, prop)


def test_cyclic_block_past_the_budget_stops_by_name(capsys) -> None:
    """A chain with a cycle of two states: solved (the value by hand), and past
    ``max_block = 1`` stopped naming the budget."""
    import numpy as np

    from mitld_lp.exact.errors import ExactTooLarge
    from mitld_lp.exact.reward import solve_reward
    from mitld_lp.worlds.prism_rewards import RewardMDP

    # 0 -> 1 (1), 1 -> 0 (1/2) or the target 2 (1/2); reward 1 per step: E = 4 from 0
    model = RewardMDP(groups=np.array([0, 1, 2, 3]), indptr=np.array([0, 1, 3, 4]),
                      indices=np.array([1, 0, 2, 2]),
                      probabilities=(Fraction(1), Fraction(1, 2), Fraction(1, 2),
                                     Fraction(1)),
                      rewards=(Fraction(1), Fraction(1), Fraction(0)),
                      target=np.array([False, False, True]), initial=0)
    assert solve_reward(model, "min").value == 4  # E0 = 1 + E1, E1 = 1 + E0 / 2
    with pytest.raises(ExactTooLarge, match="cyclic block of 2 states"):
        solve_reward(model, "max", max_block=1)


def test_dtmc_and_policy_refusal(capsys, tmp_path) -> None:
    path = tmp_path / "chain.prism"
    path.write_text("dtmc\nmodule m\n  s : [0..2] init 0;\n"
                    "  [] s=0 -> 1/3 : (s'=1) + 2/3 : (s'=0);\n  [] s=1 -> (s'=2);\n"
                    "  [] s=2 -> true;\nendmodule\n"
                    'rewards\n  s<2 : 1;\nendrewards\nlabel "end" = s=2;\n')
    _, [answer] = ours(capsys, "--prop", 'Rmin=? [F "end"]', path=str(path))
    assert Fraction(answer["value"]) == 4  # 3 expected steps to leave 0, then one
    assert storm_exact('R=? [F "end"]', {}, str(path)) == 4
    policy = tmp_path / "p.json"
    assert main(["solve", str(path), "--prop", 'Rmin=? [F "end"]', "--policy",
                 str(policy)]) == 2
    assert "writes no policy file" in capsys.readouterr().err and not policy.exists()
    assert main(["solve", str(path), "--prop", 'Rmin=? [F "end"]', "--policy",
                 str(policy), "--exact"]) == 2
    assert "writes no policy file" in capsys.readouterr().err and not policy.exists()
