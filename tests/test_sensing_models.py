"""Sensors in model files and the problems they pose: ``detect = 1`` is today's route and
answer on every bundled model; key-path errors; the combinations refused by name."""

from __future__ import annotations

import dataclasses
import re
import subprocess
import sys
from pathlib import Path
from types import MappingProxyType

import pytest

from mitld_lp import ExplicitGame, Model, load_model, loads_model, synthesize
from mitld_lp.files.keys import ModelError
from mitld_lp.problem import ProblemError
from mitld_lp.sensing import Sensor
from mitld_lp.synthesis import pose

MODELS = sorted(Path(__file__).resolve().parent.parent.joinpath("models").glob("*.toml"))

GRID = """
name = "g"
spec = "D[mu] b & F(b & F[0,2] A)"
[grid]
size = [3, 1]
start = [0, 0]
[regions]
A = [[2, 0]]
[distributions]
mu = { geometric = 0.4 }
"""


@pytest.mark.parametrize("path", MODELS, ids=lambda p: p.stem)
def test_perfect_sensors_give_todays_answer(path: Path) -> None:
    model = load_model(path)
    perfect = dataclasses.replace(model, sensors=MappingProxyType(
        {e: Sensor(1.0) for e in model.distributions}))
    a, b = synthesize(model), synthesize(perfect)
    assert b.route == a.route != "sensed"
    assert (a.lower, a.upper) == (b.lower, b.upper)


def test_sensors_table_is_read() -> None:
    m = loads_model(GRID + "[sensors]\nb = { detect = 0.8 }\n")
    assert m.sensors == {"b": Sensor(0.8)}
    assert pose(m).route.name == "sensed"
    assert pose(loads_model(GRID + "[sensors]\nb = { detect = 1 }\n")).route.name == "plain"


@pytest.mark.parametrize("table, where", [
    ("b = { detect = 1.5 }", "sensors.b.detect: must be a probability in [0, 1]"),
    ("b = { detect = true }", "sensors.b.detect: must be a number"),
    ("b = { }", "sensors.b.detect: missing"),
    ("b = { detect = 0.5, colour = 1 }", "sensors.b.colour: unknown key"),
    ("c = { detect = 0.5 }", "sensors.c: not an event of the model"),
    ("b = 0.5", "sensors.b: must be a table"),
    ("b = { detect = 0.5, false_alarm = 1.0 }", "sensors.b.false_alarm: must be a probability"),
    ("b = { detect = 0.5, delay = -1 }", "sensors.b.delay: must be an integer >= 0"),
])
def test_key_path_errors(table: str, where: str) -> None:
    with pytest.raises(ModelError, match=re.escape(f"<string>: {where}")):
        loads_model(GRID + "[sensors]\n" + table + "\n")


def test_from_game_names_the_key() -> None:
    g = ExplicitGame(initial="x", transitions={"x": {"w": {"x": 1.0}}}, labels={"x": {"A"}})
    with pytest.raises(ModelError, match="sensors.b.detect"):
        Model.from_game(g, "D[geometric(0.5)] b & F(b & A)", sensors={"b": {"detect": -1}})


@pytest.mark.parametrize("extra, band, words", [
    # (a false alarm at a point law that surely happens is solved: test_false_alarms.py;
    # with a band, its worst case: test_false_alarms_band.py, with constraints, once
    # refused here, test_false_alarms_band_constrained.py)
    ('objective = "min"\nconstraints = ["P(F A) >= 0.1"]\n[sensors]\nb = { detect = 0.5 }',
     False, None),
    ('objective = "min"\nconstraints = ["P(F A) >= 0.1"]\n[sensors]\nb = { detect = 0.5 }',
     True, None),
])
def test_refused_by_name(extra: str, band: bool, words: str | None) -> None:
    """Refused by name, before any work; ``None``: no longer refused (a minimum with
    constraints and a camera, at a point law and with the law known only within a band:
    tests/test_sensed_band_keep.py checks the latter's value)."""
    head, rest = GRID.split("[grid]")
    if band:
        rest = rest.replace("geometric = 0.4", "geometric = [0.3, 0.5]")
    text = head + (extra.split("[sensors]")[0]) + "[grid]" + rest + "[sensors]" + \
        extra.split("[sensors]")[1] + "\n"
    if words is None:
        r = synthesize(loads_model(text))
        assert r.route == "sensed-constrained" and r.lower <= r.upper, (r.route, r.lower,
                                                                          r.upper)
        return
    with pytest.raises(ProblemError, match=words.replace("(", r"\(")):
        synthesize(loads_model(text))


def test_false_alarm_refusal_says_which_case() -> None:
    """A false alarm with a law that may never happen is bracketed (the belief in
    "never" moves with every report: no finite information state;
    tests/test_false_alarms_never.py checks the bracket), with ``then`` too, on route
    sensed-constrained (tests/test_false_alarms_never_constrained.py); with a law that
    surely happens it is solved (tests/test_false_alarms.py checks the answers)."""
    sensor = "[sensors]\nb = { detect = 0.5, false_alarm = 0.1 }\n"
    # pmf [0.3, 0.3]: never with probability 1 - 0.3 - 0.3 = 0.4, by hand
    never = loads_model(GRID.replace("geometric = 0.4", "pmf = [0.3, 0.3]") + sensor)
    r = synthesize(never)
    assert r.route == "sensed" and r.lower <= r.upper
    assert any(c.name == "false alarms, law that may never happen" for c in r.checks)
    r = synthesize(never, then="min-steps")
    assert r.route == "sensed-constrained" and r.lower <= r.upper
    assert any(c.name == "false alarms, law that may never happen" for c in r.checks)
    r = synthesize(loads_model(GRID + sensor))  # geometric(0.4) surely happens
    assert r.route == "sensed" and r.certified


def test_safety_task_solved() -> None:
    """Once refused; ``G (b -> A)`` in a world that is always at ``A`` holds surely."""
    g = ExplicitGame(initial="x", transitions={"x": {"w": {"x": 1.0}}}, labels={"x": {"A"}})
    safety = Model.from_game(g, "G (b -> A)", events={"b": _geometric()},
                             sensors={"b": {"detect": 0.5}})
    r = synthesize(safety)
    assert r.route == "sensed" and r.certified and r.upper == 1.0
    assert 1.0 - r.sta.epsilon_achieved - 1e-9 <= r.lower  # the sensed bus is truncated


def _geometric():  # type: ignore[no-untyped-def]
    from mitld_lp.distributions import geometric

    return geometric(0.5)


def test_command_line_refusal_exits_2(tmp_path: Path) -> None:
    model = tmp_path / "m.toml"
    never = GRID.replace("geometric = 0.4", "pmf = [0.3, 0.3]")  # may never happen
    model.write_text(never + "[sensors]\nb = { detect = 0.5, false_alarm = 0.2 }\n")
    # (bracketed with then too, tests/test_false_alarms_never_constrained.py: not exact)
    run = subprocess.run([sys.executable, "-m", "mitld_lp", "solve", str(model), "--then",
                          "min-steps", "--exact"], capture_output=True, text=True)
    assert run.returncode == 2
    assert "exact with the sensed" in run.stderr and "Traceback" not in run.stderr
    model.write_text(GRID + "[sensors]\nb = { detect = 0.5 }\n")
    run = subprocess.run([sys.executable, "-m", "mitld_lp", "solve", str(model)],
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr


@pytest.mark.parametrize("verb", [
    ["info"], ["export", "--drn", "OUT.drn"], ["plot", "--out", "OUT.png"],
])  # export --tree writes a finite-memory controller (tests/test_sensed_tree.py)
def test_verbs_that_would_drop_the_sensor_refuse(tmp_path: Path, verb: list[str]) -> None:
    model = tmp_path / "m.toml"
    model.write_text(GRID + "[sensors]\nb = { detect = 0.5 }\n")
    args = [a.replace("OUT", str(tmp_path / "out")) for a in verb]
    run = subprocess.run([sys.executable, "-m", "mitld_lp", args[0], *args[1:], str(model)],
                         capture_output=True, text=True)
    assert run.returncode == 2, run.stderr
    assert "sensor" in run.stderr and "Traceback" not in run.stderr
    assert not list(tmp_path.glob("out*"))


def test_simulate_runs_a_sensed_model_by_its_sensed_controller_only() -> None:
    """``mitld_lp.simulate`` refused a sensed model and pointed at another function;
    it now runs the sensed controller (the same runs as simulate_sensed, seed for seed),
    and still refuses a fully observed controller on a sensed model (it would hand the
    controller the hidden events) and a sensed controller on a fully observed model."""
    from mitld_lp import simulate
    from mitld_lp.sensing.observe import simulate_sensed

    sensed = loads_model(GRID + "[sensors]\nb = { detect = 0.5 }\n")
    plain_model = loads_model(GRID)
    r = synthesize(sensed)
    assert simulate(sensed, r.controller, runs=200, seed=4) == simulate_sensed(
        sensed, r.controller, runs=200, seed=4)
    plain = synthesize(plain_model)
    with pytest.raises(ValueError, match="sensed controller"):
        simulate(sensed, plain.controller, runs=10)
    with pytest.raises(ValueError, match="sensed controller"):
        simulate(plain_model, r.controller, runs=10)


def test_law_that_may_never_happen_is_solved() -> None:
    """Once refused: a world always at ``A`` satisfies ``F(b & A)`` exactly when ``b``
    happens, with probability ``0.5 + 0.3`` whatever the sensor reports."""
    g = ExplicitGame(initial="x", transitions={"x": {"w": {"x": 1.0}}}, labels={"x": {"A"}})
    m = Model.from_game(g, "D[pmf(0.5, 0.3)] b & F(b & A)", sensors={"b": {"detect": 0.5}})
    r = synthesize(m)
    assert r.route == "sensed" and r.certified
    assert r.lower - 1e-9 <= 0.8 <= r.upper + 1e-9 and r.upper - r.lower < 1e-6


def test_budgets_stop_the_information_states() -> None:
    from mitld_lp.product import ProductTooLarge

    m = loads_model(GRID + "[sensors]\nb = { detect = 0.5 }\n")
    states = synthesize(m).mdp.n_states
    with pytest.raises(ProductTooLarge, match=f"more than {states - 1:,} states"):
        synthesize(m, max_states=states - 1)
    with pytest.raises(ProductTooLarge, match="more than 10,000 bytes"):
        synthesize(m, max_memory=10_000)


def test_model_with_sensors_pickles() -> None:
    import pickle

    m = loads_model(GRID + "[sensors]\nb = { detect = 0.5 }\n")
    back = pickle.loads(pickle.dumps(m))
    assert back.sensors == {"b": Sensor(0.5)}
    assert synthesize(back).lower == synthesize(m).lower


def test_a_fully_observed_controller_names_the_observation_it_takes() -> None:
    """A sensed Observation (reports, no events) given to a fully observed controller
    raised AttributeError, then a TypeError naming the other class.  One Observation
    (issue 42): the fully observed controller refuses reports by name (it sees the events
    themselves), and anything but an observation with a TypeError naming its class."""
    from mitld_lp import Observation

    c = synthesize(loads_model(GRID)).controller
    with pytest.raises(ValueError, match=r"Observation.reports: \['b'\]: this controller "
                                         "sees the events themselves"):
        c.act(Observation((0, 0), reports={"b"}))
    with pytest.raises(TypeError, match="expected a mitld_lp.Observation.*got builtins.tuple"):
        c.act((0, 0))  # type: ignore[arg-type]
