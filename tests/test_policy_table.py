"""The policy as data: ``policy_table``, its CSV / JSON files, ``solve --policy``, and a
short ``repr``.  Expected values are worked by hand."""

from __future__ import annotations

import csv
import json
import re
from fractions import Fraction
from html import escape
from pathlib import Path

import pytest

from mitld_lp import GridWorld, Model, synthesize
from mitld_lp.cli import main
from mitld_lp.testing import reference_product

MODELS = Path(__file__).resolve().parent.parent / "models"
SPEC = "D[pmf(0.2, 0.3, 0.4)] b & F(b & F[0,0] A)"


@pytest.fixture(scope="module")
def corridor():
    # 3x1 corridor, no slip, A at the east end; the event comes at step 1, 2, 3 with
    # 0.2, 0.3, 0.4 (never with 0.1) and the robot must stand on A at that very step.
    world = GridWorld.make(3, 1, start=(0, 0), regions={"A": [(2, 0)]})
    return synthesize(Model.from_game(world, SPEC))


def _row(rows, game_state, clock):
    found = [r for r in rows if r["game_state"] == game_state and r["clock"] == clock
             and r["pending"] == ["b"]]
    assert len(found) == 1, rows
    return found[0]


def test_rows_carry_the_hand_worked_values(corridor):
    rows = corridor.policy_table()
    first = _row(rows, (0, 0), 0)
    # Walk east: on A from step 2, so success iff K in {2, 3}: 0.3 + 0.4.
    assert first["action"] == "E"
    assert first["value"] == pytest.approx(0.7, abs=1e-9)
    # On A after two steps, event still pending: it comes at step 3 with the hazard
    # P(K = 3 | K > 2) = 0.4 / (1 - 0.2 - 0.3).  N, S and E all leave the one-row grid,
    # which keeps the robot on A; only W loses.
    on_a = _row(rows, (2, 0), 2)
    assert on_a["value"] == pytest.approx(0.4 / 0.5, abs=1e-9)
    assert on_a["action"] in {"N", "S", "E"}
    assert "b" in on_a["automaton_state"]
    assert set(first) == {"game_state", "automaton_state", "pending", "clock", "action",
                          "value", "accepting_component"}


def test_csv_and_json_files_round_trip(corridor, tmp_path):
    rows = corridor.policy_table()
    as_csv = corridor.write_policy(tmp_path / "p.csv")
    with as_csv.open(newline="") as handle:
        back = list(csv.DictReader(handle))
    assert len(back) == len(rows)
    assert [float(r["value"]) for r in back] == [r["value"] for r in rows]
    assert back[0]["game_state"] == str(rows[0]["game_state"])
    as_json = corridor.write_policy(tmp_path / "p.json")
    assert [r["action"] for r in json.loads(as_json.read_text())] == [r["action"] for r in rows]
    with pytest.raises(FileExistsError):
        corridor.write_policy(as_csv)
    with pytest.raises(ValueError, match="suffix"):
        corridor.write_policy(tmp_path / "p.txt")


def test_repr_and_html_say_the_hand_worked_answer(corridor):
    # the sizes from the state-at-a-time reference construction; the bracket by hand:
    # the event comes at step 2 or 3 (0.3 + 0.4) when the robot has just reached A, and
    # the law's tail (0.1: never) has a constant hazard, so nothing is truncated
    reference = reference_product(corridor.model.game, corridor.sta)
    text = repr(corridor)
    assert len(text) < 200
    fields = dict(re.findall(r"(\w+)=([^,)]+)", text))
    # printed outward (the lower end rounded down, the upper up): the exact 7/10 inside
    assert Fraction(fields["lower"]) <= Fraction(7, 10) <= Fraction(fields["upper"])
    assert Fraction(fields["upper"]) - Fraction(fields["lower"]) <= Fraction(2, 10**7)
    assert fields["certified"] == "True" and fields["status"] == "'optimal'"
    assert int(fields["states"]) == reference.n_states
    page = corridor._repr_html_()
    rows = dict(re.findall(r"<tr><th[^>]*>(.*?)</th><td>(.*?)</td></tr>", page))
    assert rows["spec"] == escape(str(corridor.model.spec)) and "&amp;" in rows["spec"]
    # the certified bounds straddle 7/10 by less than a unit of the 7th decimal, which
    # printing outward shows: the printed bracket contains the certified one
    assert rows["optimum in"] == "[0.6999999, 0.7000001]"
    assert rows["certified"] == "yes" and rows["epsilon achieved"] == "0"
    # two automaton states: the task pending, and accepted (an eventuality never fails)
    assert rows["sizes"] == (f"2 automaton states, {reference.n_states} states, "
                             f"{reference.n_transitions} transitions")


def test_solve_writes_the_policy_file(tmp_path, capsys):
    out = tmp_path / "policy.csv"
    assert main(["solve", str(MODELS / "bus_grid.toml"), "--policy", str(out), "--json",
                 "-q"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["policy_file"] == str(out) and summary["model"] == "bus_grid"
    with out.open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    start = [r for r in rows if r["game_state"] == "(0, 0)" and r["clock"] == "0"
             and r["pending"] == "b1 b2"]
    assert len(start) == 1 and float(start[0]["value"]) == pytest.approx(0.9244053, abs=1e-6)
    # an existing file needs --force; a wrong suffix is refused before any work
    assert main(["solve", str(MODELS / "bus_grid.toml"), "--policy", str(out), "-q"]) == 2
    assert main(["solve", str(MODELS / "bus_grid.toml"), "--policy",
                 str(tmp_path / "p.txt"), "-q"]) == 2


def test_a_saved_controller_acts_as_the_original(corridor, tmp_path):
    from mitld_lp import Controller, Observation

    path = corridor.controller.save(tmp_path / "robot.ctl")
    back = Controller.load(path)
    # Drive both through the same observed run: walk east, the event at step 2.
    run = [Observation((0, 0)), Observation((1, 0)), Observation((2, 0), frozenset({"b"}))]
    original = corridor.controller
    original.reset()
    assert [original.act(o) for o in run] == [back.act(o) for o in run]
    assert back.status is original.status and back.status.value == "accepted"
    with pytest.raises(FileExistsError):
        corridor.controller.save(path)
    junk = tmp_path / "junk.ctl"
    junk.write_bytes(b"not a controller")
    with pytest.raises(ValueError, match="cannot load the controller"):
        Controller.load(junk)


def test_a_result_pickles_and_its_controller_still_acts(corridor):
    import pickle

    from mitld_lp import Observation

    back = pickle.loads(pickle.dumps(corridor))
    assert back.lower == corridor.lower and back.model.name == corridor.model.name
    assert back.policy_table() == corridor.policy_table()
    back.controller.reset()
    assert back.controller.act(Observation((0, 0))) == "E"
