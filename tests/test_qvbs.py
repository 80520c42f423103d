"""experiments/qvbs.py on a QVBS-shaped folder built from the PRISM case studies that
stormpy ships (consensus coin2-2, csma2-2, firewire3-0.5 and two dice): each property is
posed through a model file and solved; the references are Storm's *exact* values
(rational arithmetic), computed here, and each must lie inside the certified bracket.

The script runs as a user runs it, in a subprocess; nothing of QVBS is in the repository.
"""

from __future__ import annotations

import csv
import importlib.util
import json
import os
import shutil
import subprocess
import sys
from fractions import Fraction
from pathlib import Path

import pytest

pytestmark = pytest.mark.skipif(
    importlib.util.find_spec("stormpy") is None, reason="needs stormpy: pip install -e '.[prism]'"
)

ROOT = Path(__file__).resolve().parent.parent

# family -> (stormpy's example file, {property name: PRISM property})
CASES = {
    "consensus": ("coin2-2.nm", {
        "disagree": 'Pmax=? [ F "finished"&!"all_coins_equal_0"&!"all_coins_equal_1" ]',
        "c2": 'Pmin=? [ F "finished"&"all_coins_equal_1" ]',
    }),
    "csma": ("csma2-2.nm", {
        "all_before_max": 'Pmax=? [ !"collision_max_backoff" U "all_delivered" ]',
    }),
    "firewire": ("firewire3-0.5.nm", {"leader": "Pmax=? [ F (s1=8 & s2=7) ]"}),
    "dice": ("two_dice.nm", {
        "seven": 'Pmax=? [ F "seven" ]',
        "seven_soon": 'Pmax=? [ !"two" U<=12 "seven" ]',
        "seven_by_four": "Pmax=? [ F<=14 (s1=7 & s2=7 & d1+d2=7) ]",
    }),
}
# Saved under another name in the folder: QVBS's resource-gathering ships its PRISM
# program as ``.pm`` (the other families as ``.prism`` or ``.nm``).
SAVED_AS = {"firewire": "firewire.pm"}


def storm_exact(path: Path, prop: str) -> tuple[int, int, int]:
    """``(numerator, denominator, states)`` of Storm's exact value at the initial state."""
    import stormpy

    program = stormpy.parse_prism_program(str(path))
    props = stormpy.parse_properties(prop, program)
    full = stormpy.build_model(program)
    model = stormpy.build_model[stormpy.Rational](program, props)
    value = stormpy.model_checking(model, props[0]).get_value_vector()[model.initial_states[0]]
    return int(str(value.numerator)), int(str(value.denominator)), int(full.nr_states)


def qvbs_folder(root: Path) -> dict[str, Fraction]:
    """A ``benchmarks/`` folder with one family per case; returns the references."""
    from stormpy.examples import files

    source = Path(files.prism_mdp_coin_2_2).parent
    references: dict[str, Fraction] = {}
    for family, (name, props) in CASES.items():
        folder = root / "mdp" / family
        folder.mkdir(parents=True)
        name_in_folder = SAVED_AS.get(family, name)
        shutil.copy(source / name, folder / name_in_folder)
        (folder / f"{family}.props").write_text(
            "".join(f'"{p}": {text};\n' for p, text in props.items()))
        results = []
        states = 0
        for p, text in props.items():
            num, den, states = storm_exact(folder / name_in_folder, text)
            results.append({"property": p, "value": {"approx": num / den, "num": num,
                                                     "den": den}})
            references[f"{family}.{p}"] = Fraction(num, den)
        index = {
            "short": family, "type": "mdp", "original": "PRISM",
            "properties": [{"name": p, "type": "prob-reach"} for p in props],
            "files": [{
                "file": f"{family}.jani",
                "original-file": [name_in_folder, f"{family}.props"],
                "file-parameter-values": [],
                "open-parameter-values": [{"values": [], "states": [{"number": states}],
                                           "results": results}],
            }],
        }
        (folder / "index.json").write_text(json.dumps(index))
    return references


def test_every_reference_is_inside_the_certified_bracket(tmp_path: Path) -> None:
    references = qvbs_folder(tmp_path / "benchmarks")
    assert 0.0 < min(references.values()) and max(references.values()) < 1.0
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])}
    out = tmp_path / "out"
    run = subprocess.run(
        [sys.executable, str(ROOT / "experiments" / "qvbs.py"), "--qvbs",
         str(tmp_path / "benchmarks"), "--quick", "--out", str(out)],
        capture_output=True, text=True, timeout=600, env=env, cwd=ROOT)
    assert run.returncode == 0, run.stdout + run.stderr
    with (out / "qvbs.csv").open(newline="", encoding="utf-8") as f:
        rows = {r["instance"]: r for r in csv.DictReader(f)}
    assert "Pmin" not in (out / "qvbs.md").read_text()  # none left unrun for its objective
    for name, reference in references.items():
        row = rows[name]  # Pmin (consensus.c2) included: objective = "min"
        assert row["inside"] == "yes" and row["miss"] == ""
        # the floats in full: inside exactly, as rationals, no tolerance
        assert Fraction(float(row["lower"])) <= reference <= Fraction(float(row["upper"]))
        assert float(row["reference"]) == float(reference)
    n = len(references)
    assert (f"{n} run, {n} with an exact reference: {n} inside the certified bracket "
            "exactly, 0 outside") in run.stdout
    # the model files it wrote name the PRISM file and never a copy of it
    toml = (out / "qvbs-models" / "dice.seven_soon.toml").read_text()
    assert 'spec = "!two U[0,12] seven"' in toml
    assert str(tmp_path / "benchmarks" / "mdp" / "dice" / "two_dice.nm") in toml


def _experiment(name: str):
    """The script ``experiments/<name>.py`` as a module (imported from that folder)."""
    sys.path.insert(0, str(ROOT / "experiments"))
    try:
        return importlib.import_module(name)
    finally:
        sys.path.remove(str(ROOT / "experiments"))


def _pose():
    return _experiment("qvbs")


def test_inside_means_inside_exactly() -> None:
    qvbs = _pose()
    # the float 0.1 is 0.1000000000000000055...: a point bracket [0.1, 0.1] misses 1/10
    assert not qvbs.inside_exactly(0.1, 0.1, Fraction(1, 10))
    assert qvbs.miss(0.1, 0.1, Fraction(1, 10)) == "5.6e-17"
    assert qvbs.inside_exactly(0.09999999999999999, 0.1, Fraction(1, 10))
    assert qvbs.miss(0.09999999999999999, 0.1, Fraction(1, 10)) == ""
    assert qvbs.inside_exactly(0.5, 0.5, Fraction(1, 2))  # a float that is the reference
    assert not qvbs.inside_exactly(float("nan"), 1.0, Fraction(1, 2))
    assert qvbs.exact_verdict(["1/2", "1/2"], Fraction(1, 2)) == "yes"
    assert qvbs.exact_verdict(["1/2", "3/5"], Fraction(1, 2)) == "NO"
    assert qvbs.exact_verdict("exact with b ~ poisson(2)", Fraction(1, 2)).startswith("none")


@pytest.mark.parametrize("prop, spec, labels, objective", [
    ('Pmax=? [ F "goal" ]', "F goal", {}, "max"),
    ('Pmin=? [ F<=7 "goal" ]', "F[0,7] goal", {}, "min"),
    ('Pmax=? [ !"bad" U "goal" ]', "!bad U goal", {}, "max"),
    ('Pmax=? [ !"bad" & "x" U "goal" ]', "qvbs_left U goal", {"qvbs_left": "!(b) & (x>2)"},
     "max"),
    ("Pmax=? [ F (l=4 & ip=1) ]", "F qvbs_target", {"qvbs_target": "l=4 & ip=1"}, "max"),
    ('Pmax=? [ F "goal"&"x" ]', "F qvbs_target", {"qvbs_target": "(g=1)&(x>2)"}, "max"),
    ("Pmax=? [ !(l=4 & ip=2) U t>=deadline ]", "qvbs_left U qvbs_target",
     {"qvbs_left": "!(l=4 & ip=2)", "qvbs_target": "t>=20"}, "max"),
])
def test_properties_are_posed_as_written(prop: str, spec: str, labels: dict, objective: str,
                                         ) -> None:
    qvbs = _pose()
    file_labels = {"goal": "g=1", "x": "x>2", "bad": "b"}
    posed = qvbs.pose(prop, file_labels, {"deadline": 20})
    assert posed.spec == spec and posed.objective == objective
    assert posed.labels == labels


@pytest.mark.parametrize("prop", [
    'R{"time"}min=? [ F "done" ]',
    'Pmin=? [ F^{rew{"time"}<=50} "done" ]',
    'Pmax=? [ G "safe" ]',
    'Pmax=? [ F "nope" & "goal" ]',
])
def test_properties_a_task_does_not_express_are_refused(prop: str) -> None:
    qvbs = _pose()
    with pytest.raises(qvbs.NotPosed):
        qvbs.pose(prop, {"goal": "g=1", "safe": "s"}, {})


def test_bench_qvbs_measures_ours_and_storm_on_the_same_instances(tmp_path: Path) -> None:
    """experiments/bench_qvbs.py --quick: every row's bracket holds Storm's exact value,
    Storm's sound checks on our DRN agree with our product's optimum, and Storm's run on
    the PRISM file as published finds the exact value too."""
    references = qvbs_folder(tmp_path / "benchmarks")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])}
    out = tmp_path / "out"
    run = subprocess.run(
        [sys.executable, str(ROOT / "experiments" / "bench_qvbs.py"), "--qvbs",
         str(tmp_path / "benchmarks"), "--quick", "--no-cases", "--out", str(out)],
        capture_output=True, text=True, timeout=600, env=env, cwd=ROOT)
    assert run.returncode == 0, run.stdout + run.stderr
    with (out / "bench_qvbs.csv").open(newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 2
    for row in rows:
        reference = references[row["instance"]]
        assert float(row["value"]) - 1e-8 <= reference <= float(row["upper"]) + 1e-8
        assert row["certified"] == "True" and row["storm_agrees"] == "True"
        assert abs(float(row["storm_prism_value"]) - reference) < 1e-6
        assert float(row["solve_cpu"]) > 0 and float(row["storm_check_cpu"]) >= 0
        # the process outside the solve, each part beside its peer
        assert 0 <= float(row["load_cpu"]) <= float(row["whole_cpu"])
        assert 0 <= float(row["product_cpu"]) <= float(row["whole_cpu"])
        assert 0 < float(row["storm_build_cpu"]) <= float(row["storm_prism_cpu"])
    text = (out / "bench_qvbs.md").read_text()
    assert "no such instance was run" in text  # the quick instances are all small


def test_a_step_bound_left_open_in_the_program_is_posed_with_its_value(tmp_path: Path,
                                                                       ) -> None:
    """QVBS's resource-gathering asks ``Pmax=? [F<=B "success"]`` with ``B`` an open
    constant of the PRISM program: the bound is the instance's value of ``B``, and the
    model file gives ``B`` to the program too."""
    folder = tmp_path / "benchmarks" / "mdp" / "walk"
    folder.mkdir(parents=True)
    (folder / "walk.pm").write_text(
        "mdp\nconst int B;\nmodule m\n  x : [0..3] init 0;\n"
        "  [] x<3 -> 0.5:(x'=x+1) + 0.5:(x'=x);\nendmodule\nlabel \"done\" = x=3;\n")
    (folder / "walk.prctl").write_text('"reach": Pmax=? [F<=B "done"];\n')
    (folder / "index.json").write_text(json.dumps({
        "short": "walk", "type": "mdp", "original": "PRISM",
        "properties": [{"name": "reach", "type": "prob-reach-step-bounded"}],
        "files": [{"file": "walk.jani", "original-file": ["walk.pm", "walk.prctl"],
                   "file-parameter-values": [],
                   "open-parameter-values": [{
                       "values": [{"name": "B", "value": 5}], "states": [{"number": 4}],
                       "results": [{"property": "reach", "value": 0.5}]}]}]}))
    bench_qvbs = _experiment("bench_qvbs")
    work = tmp_path / "work"
    work.mkdir()
    found, skipped = bench_qvbs.jobs(tmp_path / "benchmarks", 0, 100, ("walk",), work)
    assert skipped == [] and len(found) == 1
    text = Path(found[0][1]["model"]).read_text()
    assert 'spec = "F[0,5] done"' in text
    assert "B = 5" in text
