"""``mitld-lp solve FILE.jani`` against Storm on the same JANI file and property: each
certified bracket holds Storm's exact value (Storm's own JANI parser, exact build and
model checker, computed here), ``--exact`` equals it, the file's own properties are
answered (all, or one by name or number), and what does not map is refused by name."""

from __future__ import annotations

import json
from fractions import Fraction
from pathlib import Path

import pytest

stormpy = pytest.importorskip("stormpy")

from mitld_lp.cli import main  # noqa: E402

DATA = Path(__file__).parent / "data"
WALK = str(DATA / "door.jani")


def storm_exact(prop: str | None, constants: dict[str, int], path: str = WALK,
                name: str | None = None) -> Fraction:
    """Storm's exact value at the initial state of ``prop`` (or of the file's property
    ``name``) on the JANI file."""
    model, own = stormpy.parse_jani_model(path)
    props = ([p for p in own if p.get_name() == name] if prop is None else
             stormpy.parse_properties(prop, model))
    model, props = stormpy.instantiate_constants(model, constants, props)
    built = stormpy.build_model[stormpy.Rational](model, props)
    result = stormpy.model_checking(built, props[0], only_initial_states=True)
    return Fraction(str(result.get_value(built.initial_states[0])))


def ours(capsys: pytest.CaptureFixture[str], *argv: str, path: str = WALK,
         ) -> tuple[int, list[dict]]:
    code = main(["solve", path, "--json", "-q", *argv])
    lines = capsys.readouterr().out.strip().splitlines()
    return code, [json.loads(line) for line in lines]


@pytest.mark.parametrize("prop", [
    'Pmax=? [F "goal"]', 'Pmin=? [F "goal"]', 'Pmin=? [F x >= 2]',
    'Pmax=? [F<=3 "goal"]', 'Pmin=? [F<=4 "goal"]', 'Pmax=? [F<3 (x >= 2 & !bad)]',
    'Pmax=? [!bad U "goal"]', 'Pmin=? [!bad U (x >= 2)]', 'Pmax=? [x < 2 U<=3 "goal"]',
    'Pmin=? [G !bad]', 'Pmax=? [X (x >= 1)]',
])
def test_one_line_bracket_holds_storms_value(capsys, prop: str) -> None:
    code, [answer] = ours(capsys, "--prop", prop, "--const", "N=3")
    assert code == 0 and answer["certified"]
    value = storm_exact(prop, {"N": 3})
    assert Fraction(answer["lower"]) <= value <= Fraction(answer["upper"]), (prop, value)
    assert answer["upper"] - answer["lower"] <= 1e-6 * max(float(value), 1e-9) + 1e-12
    assert answer["objective"] == ("min" if prop.startswith("Pmin") else "max")


@pytest.mark.parametrize("prop", ['Pmin=? [F<=4 "goal"]', 'Pmin=? [!bad U (x >= 2)]'])
def test_exact_is_storms_exact_value(capsys, prop: str) -> None:
    code, [answer] = ours(capsys, "--prop", prop, "--const", "N=3", "--exact")
    assert code == 0 and answer["exact"] is not None
    assert Fraction(answer["exact"]) == storm_exact(prop, {"N": 3})


def test_the_files_own_properties_all_by_name_by_number(capsys) -> None:
    code, answers = ours(capsys, "--const", "N=3")
    assert code == 0  # the file's expected steps (Emin of 1, Storm's T) included
    assert [a["property"] for a in answers] == ["steps", "reach", "avoid", "soon"]
    for answer in answers:
        value = storm_exact(None, {"N": 3}, name=answer["property"])
        assert answer["certified"]
        assert Fraction(answer["lower"]) <= value <= Fraction(answer["upper"])
    code, [steps] = ours(capsys, "--prop", "steps", "--const", "N=3", "--exact")
    assert code == 0 and Fraction(steps["value"]) == storm_exact(None, {"N": 3},
                                                                 name="steps")
    code, [soon] = ours(capsys, "--prop", "soon", "--const", "N=3")
    assert code == 0 and soon["property"] == "soon" and soon["spec"] == "F[0,3] goal"
    code, [third] = ours(capsys, "--prop", "3", "--const", "N=3")
    assert code == 0 and third["property"] == "avoid"


def test_a_maximum_over_the_initial_states_is_the_initial_value(capsys) -> None:
    # QVBS's JANI properties are filter(max, ..., initial); a world has one initial state
    for fun in ("max", "min"):
        prop = f'filter({fun}, Pmin=? [F<=4 "goal"], "init")'
        code, [answer] = ours(capsys, "--prop", prop, "--const", "N=3", "--exact")
        assert code == 0 and Fraction(answer["exact"]) == storm_exact(
            'Pmin=? [F<=4 "goal"]', {"N": 3})


def test_missing_constant_says_const(capsys) -> None:
    assert main(["solve", WALK, "--prop", 'Pmax=? [F "goal"]']) == 2
    err = capsys.readouterr().err
    assert "N" in err and "--const NAME=VALUE" in err
    assert main(["solve", WALK, "--prop", "reach"]) == 2
    assert "--const" in capsys.readouterr().err


@pytest.mark.parametrize("prop, says", [
    ('Pmax=? [F "nowhere"]', "label 'nowhere' is not defined (labels: goal)"),
    ('R{"r"}max=? [F "goal"]', 'no reward structure "r" (reward structures: none)'),
    ('Pmax=? [X X "goal"]', "nested in another"),
])
def test_refused_by_name(capsys, prop: str, says: str) -> None:
    assert main(["solve", WALK, "--prop", prop, "--const", "N=3"]) == 2
    assert says in capsys.readouterr().err


def _coin(tmp_path: Path, kind: str, edges: list[dict]) -> str:
    """A one-automaton JANI model of type ``kind``: a counter c in [0..2] from 0."""
    model = {
        "jani-version": 1, "name": "coin", "type": kind,
        "variables": [{"name": "c", "type": {"kind": "bounded", "base": "int",
                                             "lower-bound": 0, "upper-bound": 2},
                       "initial-value": 0}],
        "automata": [{"name": "a", "locations": [{"name": "l"}], "initial-locations": ["l"],
                      "edges": edges}],
        "system": {"elements": [{"automaton": "a"}]},
    }
    path = tmp_path / f"coin_{kind}.jani"
    path.write_text(json.dumps(model))
    return str(path)


def _step(guard: dict | bool, p: int, q: int, rate: int | None = None) -> dict:
    """An edge from c (guarded) to c+1 with probability p/q, else c stays."""
    edge: dict = {"location": "l", "guard": {"exp": guard}, "destinations": [
        {"location": "l", "probability": {"exp": {"op": "/", "left": p, "right": q}},
         "assignments": [{"ref": "c", "value": {"op": "+", "left": "c", "right": 1}}]},
        {"location": "l", "probability": {"exp": {"op": "/", "left": q - p, "right": q}}}]}
    if rate is not None:
        edge["rate"] = {"exp": rate}
    return edge


def test_a_dtmc_with_one_edge_a_state_is_answered(capsys, tmp_path) -> None:
    path = _coin(tmp_path, "dtmc", [_step({"op": "<", "left": "c", "right": 2}, 1, 3),
                                    _step({"op": "=", "left": "c", "right": 2}, 0, 1)])
    code, [answer] = ours(capsys, "--prop", "Pmax=? [F<=3 c = 2]", path=path)
    # reaching c = 2 within 3 steps at 1/3 a step: 1 - P(at most one success in 3)
    assert Fraction(7, 27) == 1 - Fraction(2, 3) ** 3 - 3 * Fraction(1, 3) * Fraction(2, 3) ** 2
    assert storm_exact("P=? [F<=3 c = 2]", {}, path=path) == Fraction(7, 27)
    assert code == 0 and Fraction(answer["lower"]) <= Fraction(7, 27) <= Fraction(answer["upper"])


@pytest.mark.parametrize("kind, edges, says", [
    ("ctmc", [_step(True, 1, 1, rate=2)], "the model is a ctmc; a game needs an mdp"),
    ("dtmc", [_step({"op": "<", "left": "c", "right": 2}, 1, 2),
              _step({"op": "<", "left": "c", "right": 2}, 1, 3)],
     "a dtmc with two edges enabled at state"),
])
def test_unsupported_model_refused_by_name(capsys, tmp_path, kind: str, edges: list[dict],
                                           says: str) -> None:
    path = _coin(tmp_path, kind, edges)
    assert main(["solve", path, "--prop", "Pmax=? [F c = 2]"]) == 2
    err = capsys.readouterr().err
    assert says in err and "error:" in err


def test_decided_states_are_not_expanded_as_storm_does() -> None:
    """The world for ``F x >= 2`` has the states Storm builds for ``Pmax=? [F x >= 2]``
    (Storm stops at its target), the silent edges are named, and both silent edges of a
    state are told apart by the automaton and location they leave."""
    from mitld_lp.logic.parser import parse
    from mitld_lp.worlds.jani import load_jani

    game = load_jani(WALK, constants={"N": 3}, define={"far": "x >= 2"},
                     task=parse("F far"))
    model, _ = stormpy.parse_jani_model(WALK)
    model, props = stormpy.instantiate_constants(
        model, {"N": 3}, stormpy.parse_properties("Pmax=? [F x >= 2]", model))
    assert game.n_states == stormpy.build_model(model, props).nr_states < 18
    assert game.decided == sum(1 for s in game.states if "far" in game.propositions(s))
    whole = load_jani(WALK, constants={"N": 3})
    names = {a for s in whole.states for a in whole.actions(s)}
    assert {"safe", "risky", "silent", "silent@walk.l", "silent@wind.gusty"} <= names


def test_spec_over_a_jani_file(capsys) -> None:
    code = main(["solve", WALK, "--spec", "!goal U goal", "--objective", "min",
                 "--const", "N=3", "--json", "-q"])
    answer = json.loads(capsys.readouterr().out)
    value = storm_exact('Pmin=? [F "goal"]', {"N": 3})
    assert code == 0 and Fraction(answer["lower"]) <= value <= Fraction(answer["upper"])
