"""``mitld-lp solve FILE.prism --prop ... --const ...`` against Storm on the same file and
property: each answer's certified bracket holds Storm's exact value (Storm's exact
engine, computed here independently), ``P~p`` is decided as Storm's value decides it, and
the forms without a faithful task are refused by name (exit 2)."""

from __future__ import annotations

import json
from fractions import Fraction
from pathlib import Path

import pytest

stormpy = pytest.importorskip("stormpy")

from mitld_lp.cli import main  # noqa: E402

DATA = Path(__file__).parent / "data"
WALK = str(DATA / "door.prism")
PROPS = str(DATA / "door.props")


def storm_exact(prop: str, constants: dict[str, int], path: str = WALK) -> Fraction:
    """Storm's exact value of ``prop`` at the initial state (its own parser, its exact
    build and model checker)."""
    program = stormpy.parse_prism_program(path)
    program, props = stormpy.instantiate_constants(
        program, constants, stormpy.parse_properties(prop, program))
    model = stormpy.build_model[stormpy.Rational](program, props)
    result = stormpy.model_checking(model, props[0], only_initial_states=True)
    return Fraction(str(result.get_value(model.initial_states[0])))


def ours(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, list[dict]]:
    code = main(["solve", WALK, "--json", "-q", *argv])
    lines = capsys.readouterr().out.strip().splitlines()
    return code, [json.loads(line) for line in lines]


@pytest.mark.parametrize("prop", [
    'Pmax=? [F "goal"]', 'Pmin=? [F "goal"]',
    'Pmax=? [F<=3 "goal"]', 'Pmin=? [F<=4 "goal"]', 'Pmax=? [F<3 "goal"]',
    'Pmax=? [!"crash" U "goal"]', 'Pmin=? [!"crash" U "goal"]',
    'Pmax=? [x<2 U<=3 "goal"]', 'Pmin=? [x<3 U<=4 ("goal" | bad)]',
    'Pmax=? [G !"crash"]', 'Pmin=? [G !"crash"]',
    'Pmax=? [X (x >= 1)]', 'Pmin=? [X (x >= 1 & !bad)]',
])
def test_one_line_bracket_holds_storms_value(capsys, prop: str) -> None:
    code, [answer] = ours(capsys, "--prop", prop, "--const", "N=4")
    assert code == 0 and answer["certified"]
    value = storm_exact(prop, {"N": 4})
    assert Fraction(answer["lower"]) <= value <= Fraction(answer["upper"]), (prop, value)
    assert answer["upper"] - answer["lower"] <= 1e-6 * max(float(value), 1e-9) + 1e-12
    assert answer["objective"] == ("min" if prop.startswith("Pmin") else "max")


@pytest.mark.parametrize("prop, optimum", [
    ('P>=0.5 [F<=3 "goal"]', 'Pmin=? [F<=3 "goal"]'),
    ('P<=0.5 [F<=3 "goal"]', 'Pmax=? [F<=3 "goal"]'),
    ('P>0.4 [X (x >= 1)]', 'Pmin=? [X (x >= 1)]'),
    ('P<0.9 [X (x >= 1)]', 'Pmax=? [X (x >= 1)]'),
    ('Pmax>=0.7 [X (x >= 1)]', 'Pmax=? [X (x >= 1)]'),
])
def test_threshold_is_decided_as_storms_value_decides_it(capsys, prop: str,
                                                          optimum: str) -> None:
    code, [answer] = ours(capsys, "--prop", prop, "--const", "N=4")
    value = storm_exact(optimum, {"N": 4})
    p = Fraction(answer["threshold"])
    expected = {">=": value >= p, ">": value > p, "<=": value <= p, "<": value < p}[
        answer["comparison"]]
    assert code == 0 and answer["verdict"] is expected


def test_threshold_exactly_at_the_optimum_is_decided_by_exact(capsys) -> None:
    # Pmin of X (x >= 1) is 1/2 (the safe step): P>=1/2 holds, P>1/2 does not
    for prop, truth in (("P>=1/2 [X (x >= 1)]", True), ("P>1/2 [X (x >= 1)]", False)):
        code, [answer] = ours(capsys, "--prop", prop, "--const", "N=4", "--exact")
        assert storm_exact("Pmin=? [X (x >= 1)]", {"N": 4}) == Fraction(1, 2)
        assert code == 0 and answer["verdict"] is truth


def test_properties_file_all_by_name_by_number(capsys) -> None:
    code, answers = ours(capsys, "--prop", PROPS, "--const", "N=5")
    assert code == 0
    assert [a["property"] for a in answers] == ["reach", "avoid", "3"]
    texts = ('Pmax=? [F<=3 "goal"]', 'Pmin=? [!"crash" U "goal"]')
    for answer, text in zip(answers, texts, strict=False):
        value = storm_exact(text, {"N": 5})
        assert Fraction(answer["lower"]) <= value <= Fraction(answer["upper"])
    assert answers[2]["verdict"] is (storm_exact("Pmin=? [X (x >= 1)]", {"N": 5}) >= Fraction(2, 5))
    code, [avoid] = ours(capsys, "--prop", PROPS, "avoid", "--const", "N=5")
    assert avoid["lower"] == answers[1]["lower"] and avoid["property"] == "avoid"
    code, [third] = ours(capsys, "--prop", PROPS, "3", "--const", "N=5")
    assert third["property"] == "3" and third["verdict"] == answers[2]["verdict"]


def test_properties_file_constant_given_on_the_command_line(capsys, tmp_path) -> None:
    props = tmp_path / "open.props"
    props.write_text('const int T;\nPmax=? [F<=T "goal"];\n')
    code, [answer] = ours(capsys, "--prop", str(props), "--const", "N=4,T=2")
    value = storm_exact('Pmax=? [F<=2 "goal"]', {"N": 4})
    assert code == 0 and Fraction(answer["lower"]) <= value <= Fraction(answer["upper"])


@pytest.mark.parametrize("prop, says", [
    ('R{"r"}max=? [F "goal"]', 'the file has no reward structure "r"'),
    ('S=? ["goal"]', "long-run average"),
    ('Pmax=? [F<=2.5 "goal"]', "must be a non-negative integer"),
    ('Pmax=? [F>=2 "goal"]', "only a lower end"),
    ('Pmax=? [F (P>0.5 [F "goal"])]', "inside a path formula"),
    ('Pmax=? [(F "goal") & (G !"crash")]', "Boolean combination of path formulas"),
    ('Pmax=? [X X "goal"]', "nested in another"),
    ('P=? [F "goal"]', "without min or max"),
    ('multi(Pmax=? [F "goal"], Pmax=? [G !"crash"])', "multi-objective"),
    ('filter(max, Pmax=? [F "goal"], "crash")', "a filter is refused"),
    ('Pmax=? [F "nowhere"]', "label 'nowhere' is not defined"),
    ('Pmax=? [F "init"]', "Storm's label \"init\""),
])
def test_refused_by_name_exit_2(capsys, prop: str, says: str) -> None:
    assert main(["solve", WALK, "--prop", prop, "--const", "N=4", "-q"]) == 2
    err = capsys.readouterr().err
    assert says in err and "error:" in err


def test_bad_syntax_names_the_place(capsys) -> None:
    assert main(["solve", WALK, "--prop", 'Pmax=? [F "goal"', "--const", "N=4"]) == 2
    assert "--prop:1:17: property parse error" in capsys.readouterr().err


def test_bad_syntax_in_a_file_names_its_line(capsys, tmp_path) -> None:
    props = tmp_path / "bad.props"
    props.write_text('Pmax=? [F "goal"];\n\nPmin=? [F "goal" ;\n')
    assert main(["solve", WALK, "--prop", str(props), "--const", "N=4"]) == 2
    assert f"{props}:3:" in capsys.readouterr().err


def test_missing_constant_says_const(capsys) -> None:
    assert main(["solve", WALK, "--prop", 'Pmax=? [F "goal"]']) == 2
    err = capsys.readouterr().err
    assert "N" in err and "--const NAME=VALUE" in err


@pytest.mark.parametrize("prop", ['Pmax=? [F "goal"]', "PROPS"])
def test_an_undeclared_constant_is_named_not_dropped(capsys, prop: str) -> None:
    """``--const`` with a name the file does not declare (a typo of ``N``) was dropped
    and the property answered at the file's other values: exit 2 naming it, for a
    property on the line and for a properties file."""
    prop = PROPS if prop == "PROPS" else prop
    assert main(["solve", WALK, "--prop", prop, "--const", "N=4,M=3", "-q"]) == 2
    err = capsys.readouterr().err
    assert "constant 'M' is not declared" in err and "constants: N" in err


def test_file_with_a_refused_property_answers_the_rest(capsys, tmp_path) -> None:
    props = tmp_path / "mixed.props"
    props.write_text('"r": R{"x"}min=? [F "goal"];\n"p": Pmax=? [F "goal"];\n')
    code, answers = ours(capsys, "--prop", str(props), "--const", "N=4")
    assert code == 2
    assert answers[0]["status"] == "model_error" and "reward" in answers[0]["error"]
    assert answers[1]["property"] == "p" and answers[1]["certified"]


def test_spec_and_objective_over_the_prism_file(capsys) -> None:
    code = main(["solve", WALK, "--spec", "!crash U goal", "--objective", "min",
                 "--const", "N=4", "--json", "-q"])
    answer = json.loads(capsys.readouterr().out)
    value = storm_exact('Pmin=? [!"crash" U "goal"]', {"N": 4})
    assert code == 0 and Fraction(answer["lower"]) <= value <= Fraction(answer["upper"])


def test_objective_for_a_model_file(capsys) -> None:
    model = str(Path(__file__).parents[1] / "models" / "corridor.toml")
    assert main(["solve", model, "--objective", "min", "--json", "-q"]) == 0
    answer = json.loads(capsys.readouterr().out)
    assert answer["objective"] == "min" and answer["lower"] == 0.0  # the robot can wait


@pytest.mark.parametrize("argv, says", [
    (["--prop", 'Pmax=? [F "goal"]', "--objective", "min"], "--objective does not go"),
    (["--prop", 'Pmax=? [F "goal"]', "--then", "min-steps"], "--then does not go"),
    ([], "give a property with --prop"),
    (["--prop", "Pmax=? [F \"goal\"]", "--const", "N"], "is not NAME=VALUE"),
])
def test_bad_combinations_exit_2(capsys, argv: list[str], says: str) -> None:
    assert main(["solve", WALK, *argv]) == 2
    assert says in capsys.readouterr().err
