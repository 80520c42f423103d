"""``--json`` on every verb that answers with JSON, and one error object for all of them
(issue 41): ``{"status", "error", "exit"}`` on stdout, the reason the same as the
error line on stderr says, ``line`` and ``column`` where a formula is wrong."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from mitld_lp.cli import main

ROOT = Path(__file__).resolve().parents[1]
BUS = ROOT / "models" / "bus_grid.toml"
RISK = ROOT / "models" / "bus_risk.toml"

#: A spec wrong at line 1, column 7 (counted by hand: the ']' is missing before 'A').
BAD_SPEC = "F[0,3 A"


def _bad_formula_model(tmp_path: Path) -> Path:
    text = BUS.read_text()
    start = text.index('spec = "')
    end = text.index("\n", start)
    path = tmp_path / "bad_formula.toml"
    path.write_text(text[:start] + f'spec = "{BAD_SPEC}"' + text[end:])
    return path


def _bad_key_model(tmp_path: Path) -> Path:
    path = tmp_path / "bad_key.toml"
    path.write_text(BUS.read_text().replace("[regions]", "[region]"))
    return path


def _sweep(tmp_path: Path, model: Path) -> Path:
    path = tmp_path / "s.toml"
    path.write_text(f'name = "s"\nmodel = "{model}"\n[vary]\nepsilon = [0.01, 0.02]\n')
    return path


def _one_error(capsys: pytest.CaptureFixture[str], argv: list[str], code: int = 2
               ) -> dict[str, object]:
    """Run ``argv``: exit ``code``, one JSON object on stdout, one error line on stderr
    whose reason is the object's ``error``."""
    assert main(argv) == code
    out, err = capsys.readouterr()
    assert out.count("\n") == 1, out
    record = json.loads(out)
    assert {"status", "error", "exit"} <= set(record), record
    assert record["exit"] == code
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[-1].endswith(str(record["error"])), (lines, record)
    return record


MODEL_VERBS = {  # verb: its arguments after the model file
    "info": [],
    "solve": [],
    "simulate": ["-n", "10"],
    "export": ["--drn", "out.drn"],
    "plot": ["-o", "out.png"],
    "pareto": ["--against", "steps", "--points", "2"],
}


@pytest.mark.parametrize("verb", sorted(MODEL_VERBS))
def test_every_model_verb_says_a_bad_model_file_in_one_object(verb, tmp_path, capsys,
                                                              monkeypatch):
    monkeypatch.chdir(tmp_path)
    bad = _bad_key_model(tmp_path)
    record = _one_error(capsys, [verb, str(bad), *MODEL_VERBS[verb], "--json"])
    assert record["status"] == "model_error"
    assert "region: unknown key" in str(record["error"])
    record = _one_error(capsys, [verb, str(tmp_path / "nothing.toml"),
                                 *MODEL_VERBS[verb], "--json"])
    assert "cannot read" in str(record["error"])
    assert not (tmp_path / "out.drn").exists() and not (tmp_path / "out.png").exists()


@pytest.mark.parametrize("verb", sorted(MODEL_VERBS))
def test_every_model_verb_places_a_bad_formula(verb, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    record = _one_error(capsys, [verb, str(_bad_formula_model(tmp_path)),
                                 *MODEL_VERBS[verb], "--json"])
    assert record["status"] == "model_error"
    assert (record["line"], record["column"]) == (1, 7)
    assert "spec: 1:7:" in str(record["error"])


@pytest.mark.parametrize("verb", ["check", "dta"])
def test_the_formula_verbs_place_a_bad_formula(verb, capsys):
    record = _one_error(capsys, [verb, BAD_SPEC, "--json"])
    assert record["status"] == "model_error"
    assert (record["line"], record["column"]) == (1, 7)
    assert ("supported" in record) is (verb == "check")  # check's own answer field
    if verb == "check":
        assert record["supported"] is False


def test_a_batch_line_is_the_error_object_with_its_file(tmp_path, capsys):
    bad, formula = _bad_key_model(tmp_path), _bad_formula_model(tmp_path)
    assert main(["solve", str(BUS), str(bad), str(formula), "--json", "-q"]) == 2
    lines = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert [r["file"] for r in lines] == [str(BUS), str(bad), str(formula)]
    assert lines[0]["certified"] is True
    for r in lines[1:]:
        assert (r["status"], r["exit"], r["certified"]) == ("model_error", 2, False)
    # the single-model object and the batch's line say the same
    assert main(["solve", str(bad), "--json", "-q"]) == 2
    alone = json.loads(capsys.readouterr().out)
    assert alone["error"] == f"{bad}: {lines[1]['error']}"
    assert alone["status"] == lines[1]["status"] and alone["exit"] == lines[1]["exit"]


def test_a_sweep_says_a_bad_sweep_file_and_a_bad_base_model(tmp_path, capsys,
                                                            monkeypatch):
    monkeypatch.chdir(tmp_path)
    record = _one_error(capsys, ["sweep", str(_sweep(tmp_path, _bad_formula_model(tmp_path))),
                                 "--json"])
    assert record["status"] == "model_error" and "spec: 1:7:" in str(record["error"])
    broken = tmp_path / "broken.toml"
    broken.write_text('name = "b"\nmodel = "x.toml"\n[vary]\nepsilon = 3\n')
    record = _one_error(capsys, ["sweep", str(broken), "--json"])
    assert record["status"] == "model_error"
    assert not list(tmp_path.glob("*.csv"))  # nothing written


def test_arguments_budgets_and_refusals_have_their_status(tmp_path, capsys):
    record = _one_error(capsys, ["solve", str(BUS), "--epsilon", "2", "--json"])
    assert record["status"] == "usage_error"  # argparse's error, --json read from argv
    record = _one_error(capsys, ["info", str(BUS), "--max-memory", "10K", "--json", "-q"], 3)
    assert record["status"] == "budget" and "memory" in str(record["error"])
    record = _one_error(capsys, ["solve", str(RISK), "--constraint", "P(G F puddle) <= 0.1",
                                 "--json", "-q"])
    assert record["status"] == "model_error"


def test_the_answers_of_the_new_json_verbs(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["dta", "F[0,1] a", "--json"]) == 0
    dta = json.loads(capsys.readouterr().out)
    # F[0,1] a by hand: wait for a (start), a seen (accept), one step gone, too late
    assert dta["states"] == 4 and dta["atoms"] == ["a"]
    tags = {tuple(s["tags"]) for s in dta["automaton"]}
    assert tags == {("initial",), ("accepting",), (), ("rejecting",)}
    start = dta["automaton"][dta["initial"]]
    assert sorted(t["guard"] for t in start["transitions"]) == ["!a", "a"]

    assert main(["export", str(BUS), "--drn", "b.drn", "--controller", "c.npz",
                 "--json", "-q"]) == 0
    export = json.loads(capsys.readouterr().out)
    assert export["files"] == {"controller": "c.npz", "drn": "b.drn"}
    assert export["certified"] is True and (tmp_path / "b.drn").is_file()

    assert main(["plot", str(BUS), "-o", "p.png", "--size", "300x200", "--json",
                 "-q"]) == 0
    assert json.loads(capsys.readouterr().out) == {"files": {"out": "p.png"},
                                                   "size": [300, 200]}

    assert main(["pareto", str(RISK), "--against", "steps", "--points", "2", "--json",
                 "-q"]) == 0
    curve = json.loads(capsys.readouterr().out)
    assert curve["files"] == {} and len(curve["points"]) == 2
    assert curve["points"][0]["bound"] <= curve["points"][1]["bound"]
    assert all(p["lower"] <= p["upper"] for p in curve["points"])


def test_a_sweep_summary_in_json(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["sweep", str(_sweep(tmp_path, BUS)), "-o", "r.csv", "--json", "-q"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["sweep"] == "s" and summary["points"] == 2 and summary["solved"] == 2
    assert summary["certified"] == 2 and summary["failures"] == []
    assert summary["files"] == {"results": "r.csv"}
    rows = (tmp_path / "r.csv").read_text().splitlines()
    assert len(rows) == 3  # the header and one row a point
    assert main(["sweep", str(_sweep(tmp_path, BUS)), "-o", "r.csv", "--json", "-q"]) == 0
    again = json.loads(capsys.readouterr().out)
    assert (again["solved"], again["reused"]) == (0, 2)
