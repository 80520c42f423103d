"""experiments/qvbs_door.py (``qvbs.py --all``): the class of each property, the grouping
of refusals, the comparison with the reference, and one run through the door on a tiny
QVBS-shaped folder written here (a four-state MDP whose values are worked by hand)."""

from __future__ import annotations

import csv
import importlib
import importlib.util
import json
import sys
from fractions import Fraction
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def _door():
    sys.path.insert(0, str(ROOT / "experiments"))
    try:
        return importlib.import_module("qvbs_door")
    finally:
        sys.path.remove(str(ROOT / "experiments"))


@pytest.mark.parametrize("text, cls", [
    ('Pmax=? [ F "goal" ]', "P unbounded"),
    ('Pmin=? [ !"bad" U "goal" ]', "P unbounded"),
    ("Pmax=? [ F (l=4 & ip=1) ]", "P unbounded"),
    ('Pmax=? [ G "safe" ]', "P unbounded"),
    ('Pmax=? [F<=B "success"]', "P step-bounded"),
    ('Pmax=? [ !"two" U<=12 "seven" ]', "P step-bounded"),
    ('Pmin=? [ F^{rew{"time"}<=deadline} s=3 ]', "P reward-bounded"),
    ('Pmax=? [true Urew{"u"}>=5 (b = 0)]', "P reward-bounded"),
    ('Pmax=? [ F{"time"}<=7 "goal" ]', "P reward-bounded"),
    ('Pmax=? [ F[time<=2.5] "goal" ]', "P time-bounded"),
    ('P>=1 [ F "finished" ]', "P qualitative"),
    ('Pmin<=0 [ F "bad" ]', "P qualitative"),
    ('P>0 [ F "bad" ]', "P qualitative"),
    ('P>=0.5 [ F "goal" ]', "P threshold"),
    ('R{"steps"}max=? [ F "finished" ]', "R reach (F)"),
    ('R[exp]{"time"}min=? [F "done"]', "R reach (F)"),
    ('Tmin=? [F "success"]', "R reach (F)"),
    ('R{"time"}<=5 [ F "done" ]', "R threshold (R~b)"),
    ('Rmax>=2 [F x=1]', "R threshold (R~b)"),
    ('T<=3 [F "success"]', "R threshold (R~b)"),
    ('R{"rew_gold"}max=? [C<=B]', "R cumulative (C<=k)"),
    ('R{"q"}min=? [ I=10 ]', "R instantaneous (I=k)"),
    ('R{"q"}max=? [ S ]', "LRA / steady-state"),
    ('LRAmax=? [ "goal" ]', "LRA / steady-state"),
    ('S=? [ "up" ]', "LRA / steady-state"),
    ('Pmax=? [ X "goal" ]', "other"),
    ('filter(avg, P=? [F "goal"])', "other"),
])
def test_classes_of_prism_text(text: str, cls: str) -> None:
    assert _door().classify(text) == cls


GOAL = {"op": "=", "left": "s", "right": 1}


@pytest.mark.parametrize("expression, cls", [
    ({"op": "filter", "fun": "max", "states": {"op": "initial"},
      "values": {"op": "Pmax", "exp": {"op": "U", "left": True, "right": GOAL}}},
     "P unbounded"),
    ({"op": "Pmin", "exp": {"op": "F", "exp": GOAL, "step-bounds": {"upper": 5}}},
     "P step-bounded"),
    ({"op": "Pmax", "exp": {"op": "U", "left": True, "right": GOAL,
                            "time-bounds": {"upper": 2.5}}}, "P time-bounded"),
    ({"op": "Pmax", "exp": {"op": "F", "exp": GOAL, "reward-bounds": [
        {"exp": "energy", "accumulate": ["steps"], "bounds": {"upper": 9}}]}},
     "P reward-bounded"),
    ({"op": "≥", "left": {"op": "Pmin", "exp": {"op": "F", "exp": GOAL}}, "right": 1},
     "P qualitative"),
    ({"op": "Emin", "exp": "time", "accumulate": ["steps"], "reach": GOAL}, "R reach (F)"),
    ({"op": "Emax", "exp": "gold", "accumulate": ["steps"], "step-instant": 200},
     "R cumulative (C<=k)"),
    ({"op": "Emax", "exp": "queue", "step-instant": 10}, "R instantaneous (I=k)"),
    ({"op": "Smax", "exp": GOAL}, "LRA / steady-state"),
])
def test_classes_of_jani_expressions(expression: dict, cls: str) -> None:
    door = _door()
    assert door.classify(door.jani_text(expression)) == cls


def test_refusals_of_one_kind_group_together() -> None:
    door = _door()
    one = ('property expgold (R{"rew_gold"}max=? [C<=B]): a cumulative reward C<=k is '
           "refused: only the expected reward until a target is answered")
    two = one.replace("expgold", "other").replace("C<=B", "C<=20")
    budget = ("/q/mdp/ij/ij.30.prism: Storm explored 1,024 states, more than max_states = "
              "1,000: raise max_states (--max-world-states)")
    budget2 = budget.replace("ij.30", "ij.40").replace("1,024", "2,048")
    assert door.reason_key(one) == door.reason_key(two)
    # formulas nested deeper than one parenthesis, other property names, other bounds
    nested = ('property deadline (Pmin=? [true Urew{"time"}<=deadline (((s1 = 8) & '
              "(s2 = 7)) | ((s1 = 7) & (s2 = 8)))]): the bound 'Urew{\"time\"}<=deadline' "
              "is refused: a reward bound is not a step bound")
    flat = ('property ProbUtil (Pmax=? [true Urew{"u"}>=5 (b = 0)]): the bound '
            "'Urew{\"u\"}>=5' is refused: a reward bound is not a step bound")
    assert door.reason_key(nested) == door.reason_key(flat) != door.reason_key(one)
    unread = "not readable: no model file in the folder (original PPDDL: {}; {} not kept)"
    assert door.reason_key(unread.format("d.pddl, p01.pddl", "a.2.jani")) == \
        door.reason_key(unread.format("p02.pddl", "b.jani"))
    assert door.reason_key(budget) == door.reason_key(budget2) != door.reason_key(one)
    rows = [["a", "R cumulative (C<=k)"] + [""] * 3 + ["refused"] + [""] * 7 + [one],
            ["b", "R cumulative (C<=k)"] + [""] * 3 + ["refused"] + [""] * 7 + [two],
            ["c", "P unbounded"] + [""] * 3 + ["budget"] + [""] * 7 + [budget],
            ["d", "P unbounded"] + [""] * 3 + ["budget"] + [""] * 7 + [budget2],
            ["e", "P unbounded"] + [""] * 3 + ["refused"] + [""] * 7 + [budget]]
    # a budget text said as a refusal is another group: the outcome is part of the key
    assert door.reasons(rows) == [[2, "budget", "P unbounded", budget],
                                  [2, "refused", "R cumulative (C<=k)", one],
                                  [1, "refused", "P unbounded", budget]]


def test_the_reference_is_compared_as_it_is_given() -> None:
    door = _door()
    tenth = {"num": 1, "den": 10, "approx": 0.1}

    def answer(lower: float, upper: float, **more) -> dict:
        return {"lower": lower, "upper": upper, "certified": True, **more}

    # the float 0.1 is 0.1000000000000000055...: the point bracket [0.1, 0.1] misses 1/10
    assert door.judge(tenth, answer(0.1, 0.1)) == "NO"
    assert door.judge(tenth, answer(0.09999999999999999, 0.1)) == "yes"
    assert door.judge(75, answer(75.0, 75.0)) == "yes"  # an integer is exact
    assert door.judge(75, answer(float("inf"), float("inf"))) == "NO"
    assert door.judge(0.1, answer(0.1, 0.1)) == "float ref yes"
    assert door.judge({"approx": 0.3}, answer(0.1, 0.2)) == "float ref no"
    assert door.judge({"lower": 0.2, "upper": 0.4}, answer(0.39, 0.5)) == \
        "interval ref overlaps"
    assert door.judge({"lower": 0.2, "upper": 0.4}, answer(0.41, 0.5)) == "interval ref apart"
    assert door.judge(True, answer(1.0, 1.0, comparison=">=", verdict=True)) == "yes"
    assert door.judge(True, answer(0.5, 0.5, comparison=">=", verdict=False)) == "NO"
    assert door.judge(True, answer(0.5, 1.0, comparison=">=", verdict=None)) == "undecided"
    assert door.judge(tenth, {**answer(0.0, 1.0), "certified": False}) == "uncertified"
    assert door.judge(tenth, {"status": "model_error", "error": "no"}) == "-"
    assert door.judge(None, answer(0.0, 1.0)) == "-"


# Hand values: from s=0, a reaches s=1 ("goal") with 1/2, b with 1/4; both leave s=0
# in one step.  Pmax [F goal] = 1/2, P>=1 [F s>0] holds, Rmin{"steps"} [F s>0] = 1.
PRISM = """mdp
const int K;
module m
  s : [0..3] init 0;
  [a] s=0 -> 1/2:(s'=1) + 1/2:(s'=2);
  [b] s=0 -> 1/4:(s'=1) + 3/4:(s'=3);
  [] s>0 & K>0 -> (s'=s);
endmodule
label "goal" = s=1;
rewards "steps" true : 1; endrewards
"""
PROPS = """// a comment
"pmax": Pmax=? [ F "goal" ];
"sure": P>=1 [ F s>0 ];
"steps": R{"steps"}min=? [ F s>0 ];
"cum": R{"steps"}max=? [ C<=3 ];
"""


def fake_qvbs(root: Path) -> None:
    """A QVBS-shaped folder: the PRISM family above with an instance inside the budget
    and one over it, and a PPDDL family whose JANI file is not kept."""
    tiny = root / "mdp" / "tiny"
    tiny.mkdir(parents=True)
    (tiny / "tiny.prism").write_text(PRISM)
    (tiny / "tiny.props").write_text(PROPS)
    results = [{"property": "pmax", "value": {"num": 1, "den": 2, "approx": 0.5}},
               {"property": "sure", "value": True},
               {"property": "steps", "value": 1},
               {"property": "cum", "value": 3}]
    (tiny / "index.json").write_text(json.dumps({
        "short": "tiny", "type": "mdp", "original": "PRISM",
        "properties": [{"name": "pmax", "type": "prob-reach"},
                       {"name": "sure", "type": "prob-reach"},
                       {"name": "steps", "type": "exp-reward"},
                       {"name": "cum", "type": "exp-reward-step-bounded"}],
        "files": [{"file": "tiny.jani", "original-file": ["tiny.prism", "tiny.props"],
                   "file-parameter-values": [],
                   "open-parameter-values": [
                       {"values": [{"name": "K", "value": 1}],
                        "states": [{"number": 4}], "results": results},
                       {"values": [{"name": "K", "value": 2}],
                        "states": [{"number": 5_000}], "results": results[:1]}]}]}))
    other = root / "mdp" / "planner"
    other.mkdir()
    (other / "index.json").write_text(json.dumps({
        "short": "planner", "type": "mdp", "original": "PPDDL",
        "properties": [{"name": "goal", "type": "prob-reach"}],
        "files": [{"file": "planner.3.jani", "original-file": ["domain.pddl", "p01.pddl"],
                   "open-parameter-values": [{"states": [{"number": 9}], "results": [
                       {"property": "goal", "value": {"num": 9, "den": 10}}]}]}]}))


@pytest.mark.skipif(importlib.util.find_spec("stormpy") is None,
                    reason="needs stormpy: pip install -e '.[prism]'")
def test_every_row_is_posed_through_the_door_or_has_its_reason(tmp_path: Path) -> None:
    door = _door()
    fake_qvbs(tmp_path / "q")
    lines: list[str] = []
    code = door.main_all(tmp_path / "q", tmp_path, 100, 120.0, "2G", None, "## fake",
                         say=lines.append)
    with (tmp_path / "qvbs_all.csv").open(newline="", encoding="utf-8") as f:
        rows = {(r["instance"], r["property"]): r for r in csv.DictReader(f)}
    assert len(rows) == 6 and code == 0
    pmax = rows[("tiny.1", 'Pmax=? [ F "goal" ]')]
    assert (pmax["class"], pmax["outcome"], pmax["inside"]) == ("P unbounded", "answered",
                                                                "yes")
    assert Fraction(float(pmax["lower"])) <= Fraction(1, 2) <= Fraction(float(pmax["upper"]))
    sure = rows[("tiny.1", "P>=1 [ F s>0 ]")]
    assert (sure["class"], sure["value"], sure["inside"]) == ("P qualitative", "True", "yes")
    steps = rows[("tiny.1", 'R{"steps"}min=? [ F s>0 ]')]
    assert steps["class"] == "R reach (F)" and steps["reference"] == "1"
    assert steps["outcome"] != "answered" or steps["inside"] == "yes"
    cum = rows[("tiny.1", 'R{"steps"}max=? [ C<=3 ]')]
    assert cum["class"] == "R cumulative (C<=k)"
    # today's tool answers it or refuses it with its own words; never silently nothing
    assert cum["inside"] == "yes" if cum["outcome"] == "answered" else cum["reason"]
    over = rows[("tiny.2", 'Pmax=? [ F "goal" ]')]
    assert (over["outcome"], over["reason"]) == ("not run", "over budget: 5,000 states")
    planner = rows[("planner", "goal")]
    assert planner["outcome"] == "not run" and planner["class"] == "P unbounded"
    assert planner["reason"].startswith("not readable: no model file")
    report = (tmp_path / "qvbs_all.md").read_text()
    assert str(tmp_path) not in report  # no path of the machine in the table
    total = report.split("### Per class")[1].split("| all |")[1].split("\n")[0]
    assert total.split("|")[0].strip() == "6"
