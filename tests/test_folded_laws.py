"""A spec whose text simplifies keeps every distribution binding the text made.

The parser folds constants (``D[mu] e & false`` is ``false``), which used to drop the
``D[mu] e`` with it: the event ``e`` was then "neither a region nor an event" where the
text used it elsewhere, and a model file's ``mu`` was "defined but not used".  Each case
runs through the file loader, the library (``Model.from_game`` + ``synthesize``) and the
command line's ``check``.

The world: a 3x1 corridor, start (0, 0), A at (2, 0), slip 0.1.  A move east reaches the
next cell with probability 1 - 2 * 0.1 = 0.8 and otherwise slips into a wall (stays), so
the robot is at A at step 2 with probability 0.8^2 = 0.64 and never before step 2.
"""

from __future__ import annotations

import json
import re

import pytest

from mitld_lp import GridWorld, Model, ModelError, loads_model, synthesize
from mitld_lp.cli import main
from mitld_lp.distributions import pmf
from mitld_lp.logic import FragmentError, check

WORLD = GridWorld.make(3, 1, start=(0, 0), slip=0.1, regions={"A": [(2, 0)]})
AT_A_AT_STEP_2 = 0.8 * 0.8

FILE = """
name = "folded"
spec = "{spec}"
[grid]
size = [3, 1]
start = [0, 0]
slip = 0.1
[regions]
A = [[2, 0]]
[distributions]
mu1 = {{ pmf = [0.5, 0.5] }}
"""

# spec (with the named law mu1 = pmf(0.5, 0.5) for e1), its events, its optimum by hand
CASES = [
    # e1 comes at step 1 or 2 (1/2 each); A can be reached at step 2 only: 0.5 * 0.64.
    ("(D[mu1] e1 & false) | F(e1 & A)", {"e1"}, 0.5 * AT_A_AT_STEP_2),
    # F(e1 & false) is false: the first disjunct goes, the task is F[0,2] A.
    ("(D[mu1] e1 & F(e1 & false)) | F[0,2] A", {"e1"}, AT_A_AT_STEP_2),
    ("D[mu1] e1 & false", {"e1"}, 0.0),
    ("F(false) & D[mu1] e1", {"e1"}, 0.0),
    ("true | D[mu1] e1", {"e1"}, 1.0),
    ("F[0,2] A | X G[0,1] (D[mu1] e1 & false)", {"e1"}, AT_A_AT_STEP_2),
    ("F(e1 & A) & (true | X (D[mu1] e1 & F[0,1] A))", {"e1"}, 0.5 * AT_A_AT_STEP_2),
]


@pytest.mark.parametrize(("spec", "events", "value"), CASES)
def test_file_loader_keeps_the_bindings(spec: str, events: set[str], value: float) -> None:
    model = loads_model(FILE.format(spec=spec))
    assert set(model.distributions) == events
    assert list(model.distributions["e1"].pmf([1, 2, 3])) == [0.5, 0.5, 0.0]
    result = synthesize(model)
    assert result.certified
    assert result.lower - 1e-7 <= value <= result.upper + 1e-7


@pytest.mark.parametrize(("spec", "events", "value"), CASES)
def test_library_keeps_the_bindings(spec: str, events: set[str], value: float) -> None:
    model = Model.from_game(WORLD, spec, distributions={"mu1": pmf([0.5, 0.5])})
    assert set(model.events) == events
    result = synthesize(model)
    assert result.certified
    assert result.lower - 1e-7 <= value <= result.upper + 1e-7


@pytest.mark.parametrize(("spec", "events", "value"), CASES)
def test_check_lists_the_folded_events(
    spec: str, events: set[str], value: float, capsys: pytest.CaptureFixture[str]
) -> None:
    del value
    assert main(["check", "--json", spec]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["events"] == {e: "mu1" for e in events}
    assert main(["check", spec]) == 0
    assert "events:    e1 ~ mu1" in capsys.readouterr().out


def test_inline_law_of_the_issue_through_check(capsys: pytest.CaptureFixture[str]) -> None:
    spec = "(D[pmf(0.5, 0.5)] e1 & false) | F(e1 & A)"
    assert main(["check", spec]) == 0
    assert "events:    e1 ~ pmf(0.5, 0.5)" in capsys.readouterr().out
    result = synthesize(Model.from_game(WORLD, spec))
    assert result.lower - 1e-7 <= 0.5 * AT_A_AT_STEP_2 <= result.upper + 1e-7


@pytest.mark.parametrize(
    ("spec", "why"),
    [
        # the text puts the law under negation, even though the negated part folds away
        ("F(e1 & A) & !(D[mu1] e1 & false)", "under negation (in !(D[mu1] e1 & false))"),
        ("F(e1 & A) & ((D[mu1] e1 -> false) | true)", "under negation"),
        # two laws for one event, one of them folded away
        ("(D[mu1] e1 & false) | D[geometric(0.5)] e1", "already has the distribution"),
        ("(D[mu1] (e1 & A) & false) | F A", "directly to an event proposition"),
    ],
)
def test_folded_laws_are_still_checked(spec: str, why: str) -> None:
    with pytest.raises(FragmentError) as info:
        check(spec)
    assert re.match(r"1:\d+: ", str(info.value)) and why in str(info.value)
    with pytest.raises(ModelError, match="spec: 1:"):
        loads_model(FILE.format(spec=spec))
    assert main(["check", spec]) == 2
