"""Our property reader (mitld_lp.worlds.property_parse, property_own): each form it covers
posed as written out by hand here (Storm's printing of the property, the task, the
labels defined), its refusals worded as Storm's reader's route words them, the forms it
leaves to Storm declined, its own syntax errors placed by line and column; and, where
stormpy is installed, the same posing as Storm's reader on every hand-written case of
``experiments/property_reader_check.py``."""

from __future__ import annotations

import os
import subprocess
import sys
from fractions import Fraction
from pathlib import Path

import pytest

from mitld_lp.worlds.properties import PropertyError, Query, pick, pose_property
from mitld_lp.worlds.property_own import Symbols, read_own
from mitld_lp.worlds.property_parse import Decline, PropertySyntaxError

ROOT = Path(__file__).resolve().parent.parent

# The program: ``x : [0..10]``, ``y : bool``, ``const int N;`` (open), ``const int M = 3;``,
# ``const double p = 0.5;``, ``formula near = x > M-2;``, labels goal and two.
SYMBOLS = Symbols(labels={"goal": "x = 10", "two": "(x = 2) | y"},
                  constants={"N": ("int", None), "M": ("int", "3"), "p": ("double", "0.5")},
                  variables={"x": "int", "y": "bool"},
                  formulas={"near": "x > M-2"})


def posed(text: str, constants: dict | None = None, *, chain: bool = False) -> list[Query]:
    props = read_own(SYMBOLS, text, "W", constants)
    return [pose_property(name, prop, SYMBOLS.labels, chain=chain)
            for name, prop in pick(props, None, "W")]


def one(text: str, constants: dict | None = None, **kw) -> Query:
    (query,) = posed(text, constants, **kw)
    return query


@pytest.mark.parametrize("text, shown, spec, define", [
    ('Pmax=? [F "goal"]', 'Pmax=? [F "goal"]', "F goal", {}),
    ('Pmax=? [ G !"two" ]', 'Pmax=? [G !"two"]', "G !two", {}),
    ('Pmax=? [ X x=1 ]', 'Pmax=? [X (x = 1)]', "X phi1", {"phi1": "(x = 1)"}),
    ('Pmax=? [F y]', 'Pmax=? [F (y)]', "F phi1", {"phi1": "y"}),
    ('Pmax=? [F x=3 & y]', 'Pmax=? [F ((x = 3) & y)]', "F phi1", {"phi1": "((x = 3) & y)"}),
    ('Pmax=? [F (x=1|x=2)&!y]', 'Pmax=? [F (((x = 1) | (x = 2)) & !(y))]', "F phi1",
     {"phi1": "(((x = 1) | (x = 2)) & !(y))"}),
    ('Pmax=? [F x+1 = 2*3 - (x/2)]', 'Pmax=? [F ((x + 1) = ((2 * 3) - (x / 2)))]', "F phi1",
     {"phi1": "((x + 1) = ((2 * 3) - (x / 2)))"}),
    # a state formula over labels: the labels written out in the one defined
    ('Pmax=? [F "goal" & y]', 'Pmax=? [F ("goal" & (y))]', "F phi1",
     {"phi1": "(x = 10) & (y)"}),
    ('Pmax=? [F !"goal" & ("two" | y)]', 'Pmax=? [F ((!"goal") & ("two" | (y)))]',
     "F phi1", {"phi1": "(!(x = 10)) & (((x = 2) | y) | (y))"}),
    # the expression is the longest one there: (y | x=1) & "goal"
    ('Pmax=? [F y | x=1 & "goal"]', 'Pmax=? [F ((y | (x = 1)) & "goal")]', "F phi1",
     {"phi1": "(y | (x = 1)) & (x = 10)"}),
    # | and => bind alike, left to right; & binds tighter
    ('Pmax=? [F y => x=2 | x=1]', 'Pmax=? [F ((y => (x = 2)) | (x = 1))]', "F phi1",
     {"phi1": "((y => (x = 2)) | (x = 1))"}),
    # defined constants and formulas put in; decimals as fractions; unary minus
    ('Pmax=? [F near]', 'Pmax=? [F (x > (3 - 2))]', "F phi1", {"phi1": "(x > (3 - 2))"}),
    ('Pmax=? [F x*p = 1]', 'Pmax=? [F ((x * 1/2) = 1)]', "F phi1",
     {"phi1": "((x * 1/2) = 1)"}),
    ('Pmax=? [F x = -1]', 'Pmax=? [F (x = -(1))]', "F phi1", {"phi1": "(x = -(1))"}),
    ('Pmax=? [F x=N]', 'Pmax=? [F (x = N)]', "F phi1", {"phi1": "(x = N)"}),
    ('Pmax=? [F true]', 'Pmax=? [F true]', "F true", {}),
    ('Pmax=? [ !"two" U x>=3 ]', 'Pmax=? [(!"two") U (x >= 3)]', "!two U phi1",
     {"phi1": "(x >= 3)"}),
    ('Pmax=? [ y U "goal" ]', 'Pmax=? [(y) U "goal"]', "phi1 U goal", {"phi1": "y"}),
    # step bounds: F<=k is Storm's true U<=k
    ('Pmax=? [F<=M "goal"]', 'Pmax=? [true U<=3 "goal"]', "F[0,3] goal", {}),
    ('Pmax=? [F<5 "goal"]', 'Pmax=? [true U<5 "goal"]', "F[0,4] goal", {}),
    ('Pmax=? [F[2,4] "goal"]', 'Pmax=? [true U[2, 4] "goal"]', "F[2,4] goal", {}),
    ('Pmax=? [ "two" U<=5 "goal" ]', 'Pmax=? ["two" U<=5 "goal"]', "two U[0,5] goal", {}),
    ('Pmax=? [ "two" U[1,3] "goal" ]', 'Pmax=? ["two" U[1, 3] "goal"]', "two U[1,3] goal",
     {}),
    ('filter(max, Pmax=? [F "goal"], "init")', 'Pmax=? [F "goal"]', "F goal", {}),
])
def test_each_form_is_posed_as_storm_prints_it(text, shown, spec, define):
    query = one(text)
    assert (query.text, query.spec, query.define) == (shown, spec, define)
    assert query.name == "1" and query.objective == "max" and query.comparison is None


@pytest.mark.parametrize("text, objective, comparison, threshold", [
    ('Pmin=? [F "goal"]', "min", None, None),
    ('P>=0.5 [F "goal"]', "min", ">=", Fraction(1, 2)),  # every scheduler: the least
    ('P>1/2 [F "goal"]', "min", ">", Fraction(1, 2)),
    ('P<=0.3 [F "goal"]', "max", "<=", Fraction(3, 10)),
    ('P<1 [F "goal"]', "max", "<", Fraction(1)),
    ('Pmax>=0.2 [F "goal"]', "max", ">=", Fraction(1, 5)),
    ('P>=M/6 [F "goal"]', "min", ">=", Fraction(1, 2)),
])
def test_the_operator_gives_objective_and_threshold(text, objective, comparison, threshold):
    query = one(text)
    assert (query.objective, query.comparison, query.threshold) == (objective, comparison,
                                                                    threshold)


def test_thresholds_print_as_storm_prints_them():
    assert one('P>=0.5 [F "goal"]').text == 'P>=1/2 [F "goal"]'
    assert one('P>1/2 [F "goal"]').text == 'P>(1 / 2) [F "goal"]'


def test_a_properties_file_with_names_comments_and_constants():
    text = ('// the file\nconst int K;\nconst double q = 0.25;\n'
            '"reach": Pmax=? [F x=K]; // reach K\n\n'
            '"stay": Pmin=? [G x*q < 1];\nP>=1 [F "goal"];\n')
    reach, stay, third = posed(text, {"K": 2, "N": 7})
    assert (reach.name, reach.text) == ("reach", "Pmax=? [F (x = 2)]")
    assert (stay.name, stay.text) == ("stay", "Pmin=? [G ((x * 1/4) < 1)]")
    assert (third.name, third.spec, third.threshold) == ("3", "F goal", 1)
    props = read_own(SYMBOLS, text, "W", {"K": 2})
    assert [n for n, _ in pick(props, "stay", "W")] == ["stay"]
    assert [n for n, _ in pick(props, "3", "W")] == ["3"]


def test_given_constants_are_put_in():
    assert one('Pmax=? [F<=N "goal"]', {"N": 4}).spec == "F[0,4] goal"
    assert one('Pmax=? [F x=N]', {"N": 4}).text == "Pmax=? [F (x = 4)]"


def test_a_constant_of_the_properties_left_open_is_refused_by_name():
    with pytest.raises(PropertyError, match=r"^W: constants J, K have no value: give them "
                       r"with --const NAME=VALUE$"):
        read_own(SYMBOLS, "const int K; const int J;\nPmax=? [F x=K & x=J]", "W")


@pytest.mark.parametrize("text, message", [
    ('P=? [F "goal"]', r"P=\? without min or max is refused: on an MDP the probability "
                       r"depends on the scheduler"),
    ('Pmax=? [F "nope"]', r"label 'nope' is not defined \(labels: goal, two\)"),
    ('Pmax=? [F "init"]', r"Storm's label \"init\" is refused"),
    ('Pmax=? [F<=2.5 "goal"]', r"the bound 'U<=5/2' is refused: a step bound must be a "
                               r"non-negative integer"),
    ('Pmax=? [F[3,1] "goal"]', r"the bound 'U\[3, 1\]' is refused: the interval is empty"),
    ('Pmax=? [F<0 "goal"]', r"the bound 'U<0' is refused: no step is below 0"),
    ('Pmax=? [F<=N "goal"]', r"the bound 'U<=N' is refused: 'N' is not a number"),
    ('Pmax=? [ y ]', r"a state formula where a path formula belongs is refused"),
])
def test_refusals_are_worded_as_before(text, message):
    with pytest.raises(PropertyError, match=message):
        one(text)


def test_p_without_min_or_max_on_a_chain_is_its_one_value():
    assert one('P=? [F "goal"]', chain=True).objective == "max"


@pytest.mark.parametrize("text", [
    'R{"r"}min=? [F "goal"]', 'Tmin=? [F "goal"]', 'S=? ["goal"]', 'LRAmax=? ["goal"]',
    'multi(Pmax=? [F y], Pmax=? [F "goal"])', 'Pmax=? [F "goal" & F y]',
    'Pmax=? [F F y]', 'Pmax=? [F y U "goal"]', 'Pmax=? [F^{rew{"r"}<=3} "goal"]',
    'Pmax=? [F>=3 "goal"]', 'Pmax=? [G<=3 y]', 'filter(forall, P>=1 [F "goal"])',
    'filter(max, Pmax=? [F y], y)', 'Pmax=? [F x = min(3, x)]', 'Pmax=? [F y ? x=1 : x=2]',
    'Pmax=? [F x^2 = 4]', 'Pmax=? [F y <=> y]', 'Pmax=? [F zz]', 'Pmax=? [F x]',
    'Pmax=? [F Pmax>=1 [F y]]', 'Pmax=? [y W "goal"]', '/* c */ Pmax=? [F y]',
    'Pmax=? [F y]; Rmin=? [F "goal"]', 'const int x = 2; Pmax=? [F y]',
])
def test_other_forms_are_left_to_storms_reader(text):
    with pytest.raises(Decline):
        read_own(SYMBOLS, text, "W", {"N": 3})


@pytest.mark.parametrize("text, place", [
    ('Pmax=? [F "goal"', "W:1:17:"),
    ('Pmax=? [F "goal"];\n"b": Pmin=? [F ]', "W:2:16:"),
    ('Pmax=? ', "W:1:8:"),
    ('"a": Pmax=? [F "goal"] Pmin=? [F y]', "W:1:24:"),
])
def test_syntax_errors_name_line_and_column(text, place):
    with pytest.raises(PropertySyntaxError) as err:
        read_own(SYMBOLS, text, "W")
    assert str(err.value).startswith(f"{place} property parse error: expecting")


def test_the_reader_does_not_import_stormpy():
    code = ("import sys\nfrom mitld_lp.worlds.property_own import Symbols, read_own\n"
            "from mitld_lp.worlds.properties import pose_property\n"
            "s = Symbols({'goal': 'x = 1'}, {}, {'x': 'int'})\n"
            "(p,) = read_own(s, 'Pmax=? [F \"goal\" & x<3]', 'W')\n"
            "print(pose_property('1', p, s.labels).spec)\n"
            "print(sorted(m for m in sys.modules if m.split('.')[0] == 'stormpy'))\n")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env=env, cwd=ROOT, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines() == ["F phi1", "[]"]


def test_the_same_posing_as_storms_reader_on_the_hand_written_cases(tmp_path):
    pytest.importorskip("stormpy")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run([sys.executable, str(ROOT / "experiments" /
                                               "property_reader_check.py"),
                           "--quick", "--out", str(tmp_path)],
                          capture_output=True, text=True, env=env, cwd=ROOT, timeout=600)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    last = done.stdout.strip().splitlines()[-1]
    own, declined, different = (int(w) for w in last.replace(",", "").split()[1::2])
    assert different == 0 and own >= 100 and declined >= 30
