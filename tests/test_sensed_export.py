"""Answers of the ``sensed-constrained`` route (constraints or ``then`` with a sensor that
misses its event) exported and re-checked: Storm reads the controlled chain exactly
(``build_model_from_drn[stormpy.Rational]``) and its task probability lies inside the
answer's bracket and below the knowledge LP's optimum (tests/test_sensed_constrained.py,
written from the semantics), each constraint's probability or expected steps within its
certified bound; the saved randomised controller, run by :mod:`mitld_lp.runtime` and
``mitld-lp run``, draws what the live one draws for the same seed."""

from __future__ import annotations

import io
import json
import subprocess
import sys
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from test_sensed_constrained import PMF, SPEC, STATION, best, knowledge_lp

from mitld_lp import Model, Observation, load_controller, runtime, synthesize
from mitld_lp.cli import main
from mitld_lp.running.chain import chain_of, write_chain

stormpy = pytest.importorskip("stormpy")


def storm(path: Path, prop: str) -> Fraction:
    """Storm's exact value of ``prop`` at the initial state of the DTMC at ``path``."""
    model = stormpy.build_model_from_drn[stormpy.Rational](str(path))
    assert "DTMC" in str(model.model_type)
    result = stormpy.model_checking(model, stormpy.parse_properties(prop)[0])
    return Fraction(str(result.get_value(model.initial_states[0])))


STEPS = 'R{"steps"}=? [F "done"]'


@pytest.mark.parametrize(("constraints", "then"), [
    (["P(F wet) <= 0.1"], None),
    (["P(F wet) <= 0.25", "E(steps) <= 6"], None),
    (["E(steps) <= 3.6"], None),
    ([], "min-steps"),
], ids=["risk", "risk-and-steps", "steps", "then-min-steps"])
def test_storm_on_the_exported_chain_meets_lower_and_each_bound(constraints, then,
                                                                tmp_path) -> None:
    model = Model.from_game(STATION, SPEC, sensors={"b": {"detect": 0.5}})
    r = synthesize(model, constraints=constraints, then=then)
    assert r.route == "sensed-constrained" and r.certified
    path = write_chain(r, tmp_path / "chain.drn")
    rows = chain_of(r).matrix.sum(axis=1)  # a chain: Storm's DRN parser does not check it
    assert np.abs(rows - 1).max() < 1e-12
    task = storm(path, 'P=? [F "accept"]')
    assert Fraction(r.lower) <= task <= Fraction(r.upper)
    assert storm(path, 'P=? [F "done"]') == 1
    lp = knowledge_lp(0.5)
    limits = [("wet", "<=", c.constraint.bound) if c.constraint.kind == "prob" else
              ("steps", "<=", c.constraint.bound) for c in r.constraints]
    assert task <= Fraction(best(lp, "task", True, limits)) + Fraction(1, 10**7)
    for i, c in enumerate(r.constraints, start=1):
        got = storm(path, f'P=? [F "c{i}"]' if c.constraint.kind == "prob" else STEPS)
        assert got <= Fraction(c.certified) <= Fraction(c.constraint.bound)
    if then == "min-steps":
        assert float(storm(path, STEPS)) == pytest.approx(r.secondary, abs=1e-6)


@pytest.mark.parametrize(("constraints", "then"), [(["E(cost) <= 5.5"], None),
                                                   ([], "min-cost")])
def test_storm_on_the_chains_cost(constraints, then, tmp_path) -> None:
    """Costs (go and back 2, wait 0.5, the rest 1): the chain's reward ``cost`` is the
    controller's action's expected cost while the true task is undecided; Storm's
    expected total at most the ``E(cost)`` bound, or the ``then min-cost`` value."""
    import dataclasses
    from types import MappingProxyType

    costs = MappingProxyType({"go": 2.0, "back": 2.0, "wait": 0.5})
    model = dataclasses.replace(
        Model.from_game(STATION, SPEC, sensors={"b": {"detect": 0.5}}), costs=costs)
    r = synthesize(model, constraints=constraints, then=then)
    assert r.certified
    path = write_chain(r, tmp_path / "cost.drn")
    assert Fraction(r.lower) <= storm(path, 'P=? [F "accept"]') <= Fraction(r.upper)
    cost = storm(path, 'R{"cost"}=? [F "done"]')
    if then is None:
        (c,) = r.constraints
        assert cost <= Fraction(c.certified) <= Fraction("5.5")
        assert cost != storm(path, STEPS)  # the costs are not the steps
    else:
        assert float(cost) == pytest.approx(r.secondary, abs=1e-6)


def test_two_sensed_events_and_a_constraint_each_way(tmp_path) -> None:
    """Two buses, each seen by its own camera, a ``<=`` and a ``>=`` constraint: the
    chain's ``c1`` at most its certified bound, ``c2`` at least its (the truncated runs
    count against each: with ``c1``, without ``c2``)."""
    from test_sensing import SPEC2, TWO

    model = Model.from_game(TWO, SPEC2, sensors={"b1": {"detect": 0.5},
                                                  "b2": {"detect": 0.7}})
    r = synthesize(model, constraints=["P(F A) <= 0.2", "P(F B) >= 0.7"])
    assert r.route == "sensed-constrained" and r.certified
    path = write_chain(r, tmp_path / "two.drn")
    assert Fraction(r.lower) <= storm(path, 'P=? [F "accept"]') <= Fraction(r.upper)
    low, high = r.constraints
    assert storm(path, 'P=? [F "c1"]') <= Fraction(low.certified) <= Fraction("0.2")
    assert storm(path, 'P=? [F "c2"]') >= Fraction(high.certified) >= Fraction("0.7")


def test_the_chain_binds_where_the_constraint_binds(tmp_path) -> None:
    """The risk the chain carries is the constraint's bound, not less (the labels are
    those of the run that gets wet, not an under-count): a binding constraint."""
    model = Model.from_game(STATION, SPEC, sensors={"b": {"detect": 0.5}})
    r = synthesize(model, constraints=["P(F wet) <= 0.1"])
    wet = storm(write_chain(r, tmp_path / "c.drn"), 'P=? [F "c1"]')
    assert abs(float(wet) - 0.1) < 1e-7


def simulate_pairs(controller, other, runs: int, seed: int) -> tuple[list, int]:
    """Run the live ``controller`` on the station (the bus by ``PMF``, the sensor
    reporting it with probability 0.5 each step from its step on), asking ``other`` (a
    runtime controller) the same observations; the two action sequences per run (each
    ending with whether it drew *stay*), and how many runs drew it."""
    rng = np.random.default_rng(seed)
    out, stays = [], 0
    for k in range(runs):
        controller.reset(seed=k)
        other.reset(seed=k)
        bus = int(rng.choice(len(PMF), p=PMF)) + 1
        w, reports, reported, mine, theirs = STATION.initial, frozenset(), False, [], []
        for t in range(12):
            a = controller.act(Observation(w, reports=reports))
            b = other.act(w, (), reports)
            mine.append(a)
            theirs.append(b)
            if a is None:
                break
            succ = STATION.successors(w, a, frozenset())
            w = succ[int(rng.choice(len(succ), p=[p for _, p in succ]))][0]
            seen = not reported and t + 1 >= bus and rng.random() < 0.5
            reported = reported or seen
            reports = frozenset({"b"}) if seen else frozenset()
        stays += controller.staying
        out.append(([*mine, controller.staying], [*theirs, other.staying]))
    return out, stays


def test_the_saved_controller_draws_what_the_live_one_draws(tmp_path) -> None:
    model = Model.from_game(STATION, SPEC, sensors={"b": {"detect": 0.5}})
    r = synthesize(model, constraints=["P(F wet) <= 0.1"])
    path = r.controller.save(tmp_path / "mixed.npz")
    loaded = load_controller(path)
    assert loaded.randomised and loaded.plan.kind == "sensed-randomised"
    mixed = [d for d in loaded.plan.decisions if d is not None
             and (len(d.actions) > 1 or 0 < d.stay < 1)]
    assert mixed  # the policy draws: the same draws are no accident
    pairs, stays = simulate_pairs(r.controller, runtime.load(path), runs=300, seed=4)
    assert all(a == b for a, b in pairs) and stays > 0
    assert len({tuple(a) for a, _ in pairs}) > 3
    again, _ = simulate_pairs(loaded, runtime.load(path), runs=100, seed=5)
    assert all(a == b for a, b in again)
    # the chain of the controller read from the file is the live one's, to the bit
    live = storm(write_chain(r, tmp_path / "live.drn"), 'P=? [F "c1"]')
    assert storm(write_chain(r, tmp_path / "file.drn", controller=loaded),
                 'P=? [F "c1"]') == live


def test_mitld_lp_run_serves_the_saved_controller(tmp_path) -> None:
    """``mitld-lp run`` on the file answers a run's observations as the live controller
    acts on them (seed 3 both)."""
    model = Model.from_game(STATION, SPEC, sensors={"b": {"detect": 0.5}})
    r = synthesize(model, constraints=["P(F wet) <= 0.1"])
    path = r.controller.save(tmp_path / "mixed.npz")
    observations = [("mid", []), ("st", []), ("st", ["b"]), ("st", []), ("st", [])]
    lines = "".join(json.dumps({"state": s, "reports": rep}) + "\n"
                    for s, rep in observations)
    done = subprocess.run([sys.executable, "-m", "mitld_lp", "run", str(path), "--seed", "3"],
                          input=lines, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    answers = [json.loads(x)["action"] for x in done.stdout.splitlines()]
    r.controller.reset(seed=3)
    live = [r.controller.act(Observation(s, reports=frozenset(rep)))
            for s, rep in observations]
    assert answers == live and answers[0] is not None
    out = io.StringIO()  # the library's loop, the same
    assert runtime.serve(runtime.load(path, seed=3), lines.splitlines(), out) == 0
    assert [json.loads(x)["action"] for x in out.getvalue().splitlines()] == live


CAMERA = """name = "cam_small"
spec = "D[mu1] b1 & F(b1 & F[0,2] A)"
epsilon = 0.01
constraints = ["P(F puddle) <= 0.1", "E(steps) <= 5"]

[grid]
size = [3, 2]
start = [0, 0]
slip = 0.2
obstacles = []

[regions]
A = [[2, 1]]
puddle = [[1, 0]]

[distributions]
mu1 = { geometric = 0.5 }

[sensors]
b1 = { detect = 0.6 }
"""


def test_export_controller_and_chain_from_the_command_line(tmp_path, capsys) -> None:
    model = tmp_path / "camera.toml"
    model.write_text(CAMERA)
    chain, saved = tmp_path / "c.drn", tmp_path / "c.npz"
    code = main(["export", str(model), "--chain", str(chain), "--controller", str(saved),
                 "--json"])
    assert code == 0
    said = json.loads(capsys.readouterr().out)
    assert Fraction(said["lower"]) <= storm(chain, 'P=? [F "accept"]') <= Fraction(said["upper"])
    from mitld_lp import load_model

    r = synthesize(load_model(model))
    (risk, steps) = r.constraints
    assert storm(chain, 'P=? [F "c1"]') <= Fraction(risk.certified) <= Fraction("0.1")
    assert storm(chain, STEPS) <= Fraction(steps.certified) <= 5
    assert load_controller(saved).plan.kind == "sensed-randomised"
    assert main(["export", str(model), "--chain", str(tmp_path / "d.drn")]) == 0
    line = capsys.readouterr().out
    assert 'P=? [F "c1"] <= ' in line and 'R{"steps"}=? [F "done"] <= ' in line


def test_a_damaged_randomised_sensed_file_is_one_clear_error(tmp_path) -> None:
    from test_controller import rewritten, with_meta

    from mitld_lp import ControllerFileError

    model = Model.from_game(STATION, SPEC, sensors={"b": {"detect": 0.5}})
    r = synthesize(model, constraints=["P(F wet) <= 0.1"])
    good = r.controller.save(tmp_path / "good.npz")

    def inside_weighted(m: dict) -> dict:
        w = m["weights"].copy()
        w[np.flatnonzero(m["inside"])[0]] = 0.5
        return {**m, "weights": w}

    cases = {
        "weights": (lambda m: {**m, "weights": m["weights"] * 3}, "weights: not probabilities"),
        "stay": (lambda m: {**m, "stay": -m["stay"] - 1}, "stay: not probabilities"),
        "offsets": (lambda m: {**m, "offsets": m["offsets"][::-1].copy()},
                    "offsets: not a partition"),
        "choices": (lambda m: {**m, "choices": m["choices"] + 50},
                    "choices: an action number out of range"),
        "inside": (inside_weighted, "an end component's action with a weight"),
        "policy": (lambda m: {**m, "policy": np.zeros(3, dtype=np.int32)},
                   "not a controller archive"),
        "version": (lambda m: with_meta(m, version=4), "is not a controller kind of format "
                    "version 4"),
    }
    for name, (change, message) in cases.items():
        bad = rewritten(good, tmp_path / f"{name}.npz", change)
        with pytest.raises(ControllerFileError, match=message):
            load_controller(bad)
        with pytest.raises(ControllerFileError, match=message):
            runtime.load(bad)
