"""A band read for the robot's best law (``Settings.bands = "best"``, PRISM's
``Pmaxmax``, Storm's cooperative resolution): the certified bracket against a brute force
over the bands' corner laws written here (exact fractions), the pessimistic answer below
it on the bundled band model, Storm's cooperative value iteration on the exported
interval MDP, and the one rule of the setting on every surface."""

from __future__ import annotations

import dataclasses
import itertools
import json
from fractions import Fraction
from pathlib import Path
from types import MappingProxyType

import pytest

from mitld_lp import ExplicitGame, Model, load_model, synthesize
from mitld_lp.cli import main
from mitld_lp.cli.arguments import bands_reading
from mitld_lp.distributions import from_table, geometric
from mitld_lp.model import loads_model
from mitld_lp.problem import ProblemError, Settings
from mitld_lp.routes.robust import interval_export
from mitld_lp.solvers.robust_export import write_interval_drn
from mitld_lp.sweep import SweepError, load_sweep

MODELS = Path(__file__).resolve().parents[1] / "models"

# the robot goes left (where event a counts) or right (where b counts) once, then waits;
# the task: the event of its side comes within 3 steps
SPEC = "D[mu] a & D[nu] b & F[0,3] ((a & atL) | (b & atR))"
MU, NU = (Fraction(1, 5), Fraction(1, 2)), (Fraction(1, 10), Fraction(3, 5))


def sides() -> ExplicitGame:
    return ExplicitGame(initial="s", transitions={
        "s": {"left": {"L": 1.0}, "right": {"R": 1.0}},
        "L": {"wait": {"L": 1.0}}, "R": {"wait": {"R": 1.0}}},
        labels={"L": ["atL"], "R": ["atR"]})


def two_bands() -> Model:
    return Model.from_game(sides(), SPEC, distributions={
        "mu": from_table({"geometric": [float(x) for x in MU]}, "mu"),
        "nu": from_table({"geometric": [float(x) for x in NU]}, "nu")})


def brute_force(robot, nature) -> Fraction:
    """``robot`` over the two sides of ``nature`` over every sequence of corner laws
    (both hazards at an end of their band at each of the 3 steps): the probability that
    the side's event comes in time is ``1 - prod(1 - h_k)``."""
    def reach(side: int, corners) -> Fraction:
        miss = Fraction(1)
        for h in corners:
            miss *= 1 - h[side]
        return 1 - miss

    steps = list(itertools.product(itertools.product(MU, NU), repeat=3))
    return robot(nature(reach(side, seq) for seq in steps) for side in (0, 1))


def inside(r, exact: Fraction) -> bool:
    return Fraction(r.lower) <= exact <= Fraction(r.upper)


@pytest.mark.parametrize(("objective", "robot"), [("max", max), ("min", min)])
def test_the_best_law_of_the_bands_is_the_brute_force_over_corner_laws(objective,
                                                                      robot) -> None:
    m = two_bands()
    best = synthesize(m, bands="best", objective=objective)
    worst = synthesize(m, bands="worst", objective=objective)
    # for a maximum nature helps by maximising; for a minimum, by minimising
    nature, against = (max, min) if objective == "max" else (min, max)
    assert best.certified and worst.certified
    assert inside(best, brute_force(robot, nature))
    assert inside(worst, brute_force(robot, against))
    assert Fraction(best.upper) - Fraction(best.lower) <= Fraction(1, 10**9)
    # by hand: best max 1 - 0.4^3 on the right, best min 1 - 0.9^3 on the right; worst
    # max 1 - 0.8^3 and worst min 1 - 0.5^3 on the left: the reading changes the policy
    assert best.policy_table()[0]["action"] == "right"
    assert worst.policy_table()[0]["action"] == "left"
    summary = best.summary()
    assert summary["bands_reading"] == "best" and "guarantees nothing" in summary["message"]
    assert worst.summary()["bands_reading"] == "worst"


def test_the_pessimistic_answer_is_below_the_optimistic_on_the_bundled_band_model() -> None:
    m = load_model(MODELS / "bus_fit.toml")
    worst, best = synthesize(m), synthesize(m, bands="best")
    assert worst.certified and best.certified
    assert worst.upper < best.lower  # the band leaves this much open
    # the optimum of one law of the bands lies between (bus 2 at its band's middle)
    lo, hi = best.first_step_hazards()["b2"]
    text = (MODELS / "bus_fit.toml").read_text().replace(
        "mu1 = { geometric = [0.7, 0.9] }", "mu1 = { geometric = 0.8 }")
    text = "\n".join(f"mu2 = {{ geometric = {(lo + hi) / 2!r} }}" if line.startswith("mu2")
                     else line for line in text.splitlines())
    one = synthesize(loads_model(text, str(MODELS / "bus_fit.toml")))
    assert one.route == "plain"
    assert worst.lower <= one.upper and one.lower <= best.upper


def test_storms_cooperative_value_is_inside_the_optimistic_bracket(tmp_path: Path) -> None:
    stormpy = pytest.importorskip("stormpy")
    # one band (one ambiguous event a choice: the interval DRN is exactly our model)
    m = Model.from_game(sides(), SPEC, distributions={
        "mu": from_table({"geometric": [0.2, 0.5]}, "mu"), "nu": geometric(0.35)})
    best = synthesize(m, bands="best")
    imdp, target = interval_export(m)
    path = write_interval_drn(imdp, target, tmp_path / "sides.drn")
    model = stormpy.build_model_from_drn[stormpy.Interval](str(path))
    prop = stormpy.parse_properties('Pmax=? [F "target"]')[0]
    env = stormpy.Environment()
    env.solver().min_max().precision = stormpy.Rational("1/1000000000000")

    def storm(mode: str) -> float:
        return float(stormpy.model_checking(
            model, prop, environment=env,
            uncertainty_resolution_mode=getattr(stormpy.UncertaintyResolutionMode, mode),
        ).get_value(0))

    cooperative = storm("COOPERATIVE")
    assert best.lower - 1e-9 <= cooperative <= best.upper + 1e-9
    assert cooperative == pytest.approx(1 - 0.5**3, abs=1e-9)  # left, mu's best end
    assert storm("ROBUST") == pytest.approx(synthesize(m).lower, abs=1e-9)
    assert storm("ROBUST") < cooperative - 0.1


def test_a_sensor_with_the_best_law_is_solved_on_the_sensed_routes() -> None:
    # constraints with the best law are solved (tests/test_optimistic_constrained.py), a
    # sensor with it too (tests/test_sensed_optimistic.py): never by a fully observed route
    from mitld_lp.sensing import Sensor

    sensed = Model.from_game(sides(), SPEC, distributions={
        "mu": from_table({"geometric": [float(x) for x in MU]}, "mu"),
        "nu": from_table({"geometric": [float(x) for x in NU]}, "nu")},
        sensors={"a": Sensor(0.5)})
    r = synthesize(sensed, bands="best")
    assert r.part.observation_based and r.summary()["bands_reading"] == "best"
    assert r.upper <= synthesize(dataclasses.replace(sensed, sensors=MappingProxyType({})),
                                 bands="best").upper + 1e-12
    # point laws: the one law of each is both its best and its worst
    m = Model.from_game(sides(), SPEC, distributions={"mu": geometric(0.3),
                                                      "nu": geometric(0.4)})
    assert synthesize(m, bands="best").lower == synthesize(m).lower


MODEL = """\
name = "wait_for_b"
spec = "D[mu] b & F[0,2] (b & !A)"
grid = { size = [2, 2], start = [0, 0] }
regions = { A = [[1, 1]] }
distributions = { mu = { geometric = [0.3, 0.6] } }
"""


@pytest.mark.parametrize(("value", "accepted"), [("worst", True), ("best", True),
                                                 ("Best", False), ("", False),
                                                 ("pessimistic", False), (1, False),
                                                 (True, False)])
def test_every_surface_applies_the_one_rule(tmp_path: Path, value, accepted) -> None:
    said = "must be 'worst' or 'best'"
    try:
        Settings(bands=value).checked()
        library = True
    except ProblemError as exc:
        assert str(exc).startswith(f"bands: {said}")
        library = False
    (tmp_path / "wait.toml").write_text(MODEL)
    sweep = tmp_path / "s.toml"
    toml = json.dumps(value) if not isinstance(value, bool) else "true"
    sweep.write_text('name = "s"\nmodel = "wait.toml"\n[vary]\nepsilon = [0.01]\n'
                     f"[solve]\nbands = {toml}\n")
    try:
        loaded = load_sweep(sweep)
        assert loaded.settings.bands == value
        # a sweep read optimistically is another sweep: its results are not reused
        assert ("bands" in loaded.settings.identity()) is (value == "best")
        swept = True
    except SweepError as exc:
        assert "solve.bands" in str(exc) and said in str(exc)
        swept = False
    assert library is accepted and swept is accepted
    if isinstance(value, str):
        try:
            bands_reading(value)
            command = True
        except Exception as exc:  # argparse.ArgumentTypeError
            assert said in str(exc)
            command = False
        assert command is accepted


def test_the_command_line_reads_the_bands_and_says_which_reading(tmp_path: Path,
                                                                 capsys) -> None:
    path = tmp_path / "wait.toml"
    path.write_text(MODEL)
    answers = {}
    for reading in ("worst", "best"):
        assert main(["solve", str(path), "--bands", reading, "--json"]) == 0
        answers[reading] = json.loads(capsys.readouterr().out)
        assert answers[reading]["bands_reading"] == reading
    # by hand: two chances, hazard 0.3 at worst, 0.6 at best
    for reading, value in (("worst", 1 - 0.7**2), ("best", 1 - 0.4**2)):
        assert answers[reading]["lower"] == pytest.approx(value, abs=1e-9)
    assert main(["solve", str(path), "--bands", "best"]) == 0
    out = capsys.readouterr().out
    assert "best case over the bands (Pmaxmax)" in out and "guarantees nothing" in out
    (tmp_path / "again.toml").write_text(MODEL)  # a batch says it on each line
    assert main(["solve", str(path), str(tmp_path / "again.toml"), "--bands", "best"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 2 and all("best law of the bands: Pmaxmax" in x for x in lines)
    assert main(["solve", str(path), "--bands", "most"]) == 2
    assert "--bands" in capsys.readouterr().err
    assert main(["simulate", str(path), "--bands", "best", "--runs", "200", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["certified_bracket"][0] == pytest.approx(
        answers["best"]["lower"])
    # an optimistic controller's chain is a plain one, at nature's chosen law (an interval
    # chain would claim a worst case): Storm gives the best law's value, 1 - 0.4^2
    assert main(["export", str(path), "--bands", "best", "--chain",
                 str(tmp_path / "c.drn"), "--json"]) == 0
    said = json.loads(capsys.readouterr().out)
    assert said["chain_accept"] == pytest.approx(1 - 0.4**2, abs=1e-9)
    assert storm_exact(tmp_path / "c.drn") == Fraction(1) - Fraction(2, 5) ** 2


def storm_exact(path: Path) -> Fraction:
    """Storm's exact ``P=? [F "accept"]`` on the plain chain at ``path``."""
    stormpy = pytest.importorskip("stormpy")
    model = stormpy.build_model_from_drn[stormpy.Rational](str(path))
    assert "DTMC" in str(model.model_type)
    result = stormpy.model_checking(model, stormpy.parse_properties('P=? [F "accept"]')[0])
    return Fraction(str(result.get_value(model.initial_states[0])))


SAFE_GRID = """name = "walk"
spec = "{spec}"
objective = "{objective}"
[grid]
size = [4, 3]
start = [0, 0]
slip = 0.2
obstacles = []
[regions]
goal = [[3, 2]]
puddle = [[2, 1], [2, 0]]
[distributions]
mu = {{ geometric = [0.2, 0.4] }}
"""


@pytest.mark.parametrize("spec", ["D[mu] b & F(b & F[0,3] goal)",
                                  "G !puddle & D[mu] b & F(b & F[0,3] goal)"])
@pytest.mark.parametrize("objective", ["max", "min"])
def test_the_optimistic_chain_at_natures_law_is_inside_the_bracket(
        tmp_path: Path, spec: str, objective: str) -> None:
    """The plain chain of an optimistic answer (nature's chosen law found again from the
    policy's values) is worth, exactly by Storm, at least the answer's claim and at most
    the optimistic optimum: co-safe and obligation tasks, maximised and minimised."""
    from mitld_lp.files import drn
    from mitld_lp.running.chain import chain_drn
    from mitld_lp.running.optimistic_chain import optimistic_chain_of, optimistic_claim

    path = tmp_path / "walk.toml"
    path.write_text(SAFE_GRID.format(spec=spec, objective=objective))
    r = synthesize(load_model(path), bands="best")
    assert r.certified
    out = drn.write(chain_drn(optimistic_chain_of(r)), tmp_path / "c.drn")
    value = storm_exact(out)
    claim, _ = optimistic_claim(r)
    assert Fraction(claim) <= value
    if r.complemented:  # "accept" marks the runs that fail the task
        assert value <= Fraction(r.complement[1])
    else:
        assert value <= Fraction(r.upper)
