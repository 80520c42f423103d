"""``mitld-lp solve a.toml b.toml 'pattern*.toml'``: one line per model, JSON lines with
``--json``; a failing model is its line and the exit status says something failed."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from mitld_lp.cli import main

MODELS = Path(__file__).resolve().parent.parent / "models"


@pytest.fixture()
def folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    for name in ("bus_grid.toml", "red_light.toml"):
        shutil.copy(MODELS / name, tmp_path / name)
    return tmp_path


def _single(capsys, name: str) -> dict:
    assert main(["solve", name, "--json", "-q"]) == 0
    return json.loads(capsys.readouterr().out)


def test_a_batch_gives_each_model_the_line_solve_gives_it_alone(folder, capsys):
    alone = {name: _single(capsys, name) for name in ("bus_grid.toml", "red_light.toml")}
    assert main(["solve", "bus_grid.toml", "red_light.toml", "--json", "-q"]) == 0
    lines = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert [line["file"] for line in lines] == ["bus_grid.toml", "red_light.toml"]
    for line in lines:
        for key in ("lower", "upper", "certified", "states", "status", "model"):
            assert line[key] == alone[line["file"]][key]


def test_a_pattern_the_shell_did_not_expand(folder, capsys):
    assert main(["solve", "*.toml", "bus_grid.toml", "-q"]) == 0  # bus_grid once
    out = capsys.readouterr().out.splitlines()
    assert len(out) == 2
    # Storm's 0.9244053 (README), the bracket printed outward to 7 decimals around it
    assert out[0].startswith("bus_grid.toml: [0.9244052, 0.9244053] certified yes")
    assert out[1].startswith("red_light.toml: [")


def test_a_failing_model_is_its_line_and_the_exit_status_says_so(folder, capsys):
    (folder / "bad.toml").write_text((folder / "bus_grid.toml").read_text()
                                     .replace("slip = 0.1", "slip = 0.7"))
    code = main(["solve", "bad.toml", "bus_grid.toml", "nothing*.toml", "--json", "-q"])
    assert code == 2
    captured = capsys.readouterr()
    assert captured.err.strip().splitlines() == [
        "mitld-lp: error: 2 of 3 models could not be read or posed (see their lines)"]
    lines = [json.loads(line) for line in captured.out.splitlines()]
    assert [(x["file"], x["status"]) for x in lines] == [
        ("bad.toml", "model_error"), ("bus_grid.toml", "optimal"),
        ("nothing*.toml", "model_error")]
    assert lines[0]["error"] == "grid.slip: must be in [0, 0.5], got 0.7"
    assert lines[2]["error"] == "no file matches this pattern"
    assert lines[1]["certified"] is True


def test_a_budget_stop_in_a_batch_exits_3(folder, capsys):
    code = main(["solve", "bus_grid.toml", "red_light.toml", "--max-states", "60", "-q"])
    captured = capsys.readouterr()
    out = captured.out.splitlines()
    assert code == 3
    assert captured.err == ("mitld-lp: stopped: 1 of 2 models without a certified answer "
                            "(see their lines)\n")
    assert out[0].startswith("bus_grid.toml: budget: ")
    assert out[1].startswith("red_light.toml: [")  # 55 states: within the budget


def test_policy_takes_one_model(folder, capsys):
    assert main(["solve", "bus_grid.toml", "red_light.toml", "--policy", "p.csv"]) == 2
    assert "--policy writes the policy of one model" in capsys.readouterr().err
    assert not (folder / "p.csv").exists()
