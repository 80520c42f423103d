"""Expected times ``Tmin=? [F target]`` and the bounds ``R{"r"}<=b [...]``, ``R>=b``,
``T~b`` through the door, against Storm on the same PRISM text: ``T``'s exact value is
Storm's exact value (compared as fractions), the float route's certified bracket holds
it, ``inf`` where Storm says infinity, and a bound is true or false exactly as Storm's
own check of that bound says (Storm's exact engine), or undecided (exit 3) where the
float bracket straddles the threshold; a tiny chain's expected steps by hand."""

from __future__ import annotations

import json
from fractions import Fraction
from pathlib import Path

import pytest

stormpy = pytest.importorskip("stormpy")
pytest.importorskip("flint")

from storm_exact import storm_holds, storm_value  # noqa: E402

from mitld_lp.cli import main  # noqa: E402

DATA = Path(__file__).parent / "data"
WALK = str(DATA / "rewards.prism")

# s = 0: a (1/3 to the goal, else stay), b (1/2 to the goal, 1/2 to the trap 2), c (stay,
# only when LOOP); the goal 1; the trap 2 never reaches it.  By hand: Tmin from 0 is 3
# (the geometric law of 1/3; b risks the trap, infinity), Tmax is infinite (b, or c),
# and from the trap both are infinite.
GEOMETRIC = """mdp
const bool LOOP;
module m
  s : [0..2] init 0;
  [a] s=0 -> 1/3 : (s'=1) + 2/3 : true;
  [b] s=0 -> 1/2 : (s'=1) + 1/2 : (s'=2);
  [c] s=0 & LOOP -> true;
  [d] s>0 -> true;
endmodule
label "goal" = s=1;
label "trap" = s=2;
"""


def ours(capsys: pytest.CaptureFixture[str], *argv: str, path: str = WALK
         ) -> tuple[int, list[dict]]:
    code = main(["solve", path, "--json", "-q", *argv])
    lines = capsys.readouterr().out.strip().splitlines()
    return code, [json.loads(line) for line in lines]


TIMES = ['Tmin=? [F "goal"]', 'Tmax=? [F "goal"]', 'Tmin=? [F "stop"]',
         'Tmax=? [F "stop"]', 'Tmin=? [F x>=2 & !lost]', 'Tmax=? [F (x>=2 | lost)]',
         'Tmin=? [F lost]']


@pytest.mark.parametrize("idle", ["true", "false"])
@pytest.mark.parametrize("prop", TIMES)
def test_expected_time_is_storms(capsys, prop: str, idle: str) -> None:
    constants = {"N": 3, "IDLE": idle == "true"}
    value = storm_value(WALK, prop, constants)
    for exact in (["--exact"], []):
        code, [answer] = ours(capsys, "--prop", prop, "--const", f"N=3,IDLE={idle}",
                              *exact)
        assert code == 0 and answer["certified"] and answer["reward"] is None
        if value is None:
            assert answer["value"] == "inf" and answer["infinite"], (prop, idle, exact)
            continue
        assert not answer["infinite"]
        assert Fraction(answer["lower"]) <= value <= Fraction(answer["upper"]), (prop, idle)
        if exact:
            assert Fraction(answer["value"]) == value, (prop, idle)


def test_expected_steps_by_hand_and_infinity(capsys, tmp_path) -> None:
    path = tmp_path / "geometric.prism"
    path.write_text(GEOMETRIC)
    for loop in ("true", "false"):
        _, [low] = ours(capsys, "--prop", 'Tmin=? [F "goal"]', "--const", f"LOOP={loop}",
                        "--exact", path=str(path))
        assert Fraction(low["value"]) == 3  # a: geometric with 1/3
        _, [high] = ours(capsys, "--prop", 'Tmax=? [F "goal"]', "--const",
                         f"LOOP={loop}", path=str(path))
        assert high["value"] == "inf"  # b reaches the trap with probability 1/2
    code, [never] = ours(capsys, "--prop", 'Tmin=? [F "goal" & "trap"]', "--const",
                         "LOOP=false", path=str(path))
    assert code == 0 and never["value"] == "inf" and "every scheduler" in never["why"]
    assert storm_value(str(path), 'Tmin=? [F "goal"]', {"LOOP": True}) == 3
    assert storm_value(str(path), 'Tmax=? [F "goal"]', {"LOOP": False}) is None


def test_the_line_says_expected_steps(capsys) -> None:
    assert main(["solve", WALK, "--prop", 'Tmin=? [F "goal"]', "--const",
                 "N=3,IDLE=true", "-q", "--exact"]) == 0
    out = capsys.readouterr().out
    assert "1 per step" in out and "certified" in out


def test_the_library_poses_t_as_one_per_step(tmp_path) -> None:
    """``pose_reward`` and ``reward_mdp`` without the command line: every choice's
    reward is 1 (no structure of the file read: the file has none), the value by hand."""
    from mitld_lp.exact.reward import solve_reward
    from mitld_lp.solvers.reward import solve_reward_float
    from mitld_lp.worlds.prism_rewards import pose_reward, reward_mdp

    path = tmp_path / "geometric.prism"
    path.write_text(GEOMETRIC)
    program = stormpy.parse_prism_program(str(path))
    [prop] = stormpy.parse_properties('Tmin=? [F "goal"]', program)
    query = pose_reward("1", prop, [])
    assert query.per_step and query.objective == "min" and query.structure is None
    for exact in (True, False):
        model = reward_mdp(path, program, query, constants={"LOOP": True}, exact=exact)
        assert all(r == 1 for r in model.rewards)
        if exact:
            assert solve_reward(model, "min").value == 3
        else:
            bracket = solve_reward_float(model, "min")
            assert bracket.certified and bracket.lower <= 3 <= bracket.upper


BOUNDED = ['R{"cost"}<=B [F "goal"]', 'R{"cost"}>=B [F "goal"]', 'R{"cost"}<B [F "stop"]',
           'R{"cost"}>B [F "stop"]', 'R{"cost"}min<=B [F "stop"]', 'R{"time"}max>=B [F "stop"]',
           'T<=B [F "stop"]', 'T>=B [F "goal"]', 'Tmin<B [F "stop"]',
           'R{"cost"}<=B [C<=4]', 'R{"time"}min>B [I=2]']


def _optimum(prop: str) -> str:
    """The ``=?`` property whose optimum decides the bound ``prop`` (for every scheduler:
    the greatest for ``<=``, ``<``; the least for ``>=``, ``>``), written independently of
    the code's mapping."""
    head, body = prop.split(" ", 1)
    for op in ("<=", ">=", "<", ">"):
        if op in head:
            name, _ = head.split(op)
            break
    if not name.endswith(("min", "max")):
        name += "max" if op in ("<=", "<") else "min"
    return f"{name}=? {body}"


@pytest.mark.parametrize("idle", ["true", "false"])
@pytest.mark.parametrize("prop", BOUNDED)
def test_bound_decided_as_storm_decides_it(capsys, prop: str, idle: str) -> None:
    constants = {"N": 3, "IDLE": idle == "true"}
    value = storm_value(WALK, _optimum(prop), constants)
    offsets = (Fraction(-1, 7), Fraction(0), Fraction(1, 7))
    thresholds = [Fraction(2), Fraction(9)] if value is None else \
        [value + d for d in offsets if value + d >= 0]
    for b in thresholds:
        text = prop.replace("B", f"{b.numerator}/{b.denominator}")
        storm = storm_holds(WALK, text, constants)
        code, [exact] = ours(capsys, "--prop", text, "--const", f"N=3,IDLE={idle}",
                             "--exact")
        assert exact["verdict"] is storm and code == 0, (text, idle, value)
        code, [fast] = ours(capsys, "--prop", text, "--const", f"N=3,IDLE={idle}")
        if value is not None and b == value and "C<=" not in text and "I=" not in text:
            assert fast["verdict"] in (storm, None)  # a float bracket may straddle it
            assert code == (0 if fast["verdict"] is not None else 3)
        else:
            assert fast["verdict"] is storm and code == 0, (text, idle, value)


def test_undecided_says_so_exit_3(capsys) -> None:
    """Tmin to "stop" is 54/25 (Storm), no float: the float bracket holds it strictly
    inside, so ``Tmin<=54/25`` is undecided (exit 3), never a guess; the exact value
    decides it true, as Storm does."""
    text = 'Tmin<=54/25 [F "stop"]'
    assert storm_value(WALK, 'Tmin=? [F "stop"]', {"N": 3, "IDLE": False}) == \
        Fraction(54, 25)
    assert storm_holds(WALK, text, {"N": 3, "IDLE": False})
    assert main(["solve", WALK, "--prop", text, "--const", "N=3,IDLE=false", "-q"]) == 3
    assert "undecided: Tmin in [2.1599999, 2.1600001], threshold <= 54/25" in \
        capsys.readouterr().out
    assert main(["solve", WALK, "--prop", text, "--const", "N=3,IDLE=false", "-q",
                 "--exact"]) == 0
    out = capsys.readouterr().out
    assert "true: Tmin in [" in out and "exact 54/25" in out


CHAIN = """dtmc
module m
  s : [0..2] init 0;
  [] s=0 -> 1/3 : (s'=1) + 2/3 : (s'=0);
  [] s=1 -> (s'=2);
  [] s=2 -> true;
endmodule
rewards "time"
  s<2 : 1;
endrewards
label "end" = s=2;
"""


@pytest.mark.parametrize("exact", [True, False])
def test_a_dtmc_needs_no_min_or_max(capsys, tmp_path, exact: bool) -> None:
    """On a DTMC Storm reads ``R=?``, ``T=?`` and ``P=?`` as the chain's one value; by
    hand, leaving 0 (1/3 a step) then one step: 4 expected steps, and with at most 2
    collected only the direct path, 1/3.  The float route reads Storm's export of a
    chain (which has no choices table)."""
    path = tmp_path / "chain.prism"
    path.write_text(CHAIN)
    flag = ["--exact"] if exact else []
    for prop, value in (('T=? [F "end"]', Fraction(4)), ('R=? [F "end"]', Fraction(4)),
                        ('P=? [F{"time"}<=2 "end"]', Fraction(1, 3))):
        assert storm_value(str(path), prop, {}) == value
        code, [answer] = ours(capsys, "--prop", prop, *flag, path=str(path))
        assert code == 0 and answer["certified"], prop
        assert Fraction(answer["lower"]) <= value <= Fraction(answer["upper"]), prop
    code, [bound] = ours(capsys, "--prop", 'T<=5 [F "end"]', *flag, path=str(path))
    assert code == 0 and bound["verdict"] is storm_holds(str(path), 'T<=5 [F "end"]', {})
