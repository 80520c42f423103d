"""One problem, one pipeline: every combination of task class, laws and extras is either
solved, on exactly the problem posed, or refused naming the combination; the command
line's verbs pose their problem in the same one place (mitld_lp.problem).

The expected values come from hand calculations on small worlds built here, or from a
different route to the same number (noted at each test).
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from mitld_lp import (
    ExplicitGame,
    GridWorld,
    Model,
    Observation,
    load_model,
    loads_model,
    synthesize,
)
from mitld_lp.cli import main
from mitld_lp.problem import ProblemError
from mitld_lp.report import SUMMARY_KEYS

MODELS = Path(__file__).resolve().parent.parent / "models"


def _fork() -> ExplicitGame:
    """One choice between two gambles: ``a`` reaches A w.p. 0.6 (else B), ``b`` reaches A
    w.p. 0.2 (else C); A, B, C absorbing.  By hand: Pmax(F A) = 0.6, Pmin(F A) = 0.2,
    Pmax(G !A) = 0.8, Pmin(G !A) = 0.4."""
    return ExplicitGame(
        initial="s",
        transitions={"s": {"a": {"A": 0.6, "B": 0.4}, "b": {"A": 0.2, "C": 0.8}},
                     "A": {"wait": {"A": 1.0}}, "B": {"wait": {"B": 1.0}},
                     "C": {"wait": {"C": 1.0}}},
        labels={"A": {"A"}, "B": {"B"}, "C": {"C"}})


@pytest.mark.parametrize(("spec", "objective", "expected"), [
    ("F A", "max", 0.6), ("F A", "min", 0.2), ("G !A", "max", 0.8), ("G !A", "min", 0.4),
    ("G !A | F B", "max", 0.8), ("G !A | F B", "min", 0.4),
])
def test_objective_min_and_max_by_hand(spec: str, objective: str, expected: float) -> None:
    """Pmin is the complement's maximum read back: the hand values of the fork, for a
    co-safe, a safety and an obligation task."""
    model = Model.from_game(_fork(), spec, objective=objective)
    r = synthesize(model)
    assert r.certified, r.failed_checks
    assert r.lower == pytest.approx(expected, abs=1e-9)
    assert r.upper == pytest.approx(expected, abs=1e-9)
    assert r.summary()["objective"] == objective
    # the policy plays the gamble that makes A least (most) likely
    best = "b" if (objective == "min") == (spec == "F A") else "a"
    first = int(r.lower_model.policy[r.mdp.initial])
    assert r.mdp.action_name(first) == best


@pytest.mark.parametrize(("objective", "expected"), [("max", 0.6), ("min", 0.2)])
def test_objective_min_outputs_speak_of_the_task(objective: str, expected: float,
                                                tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    """For a minimised task the policy table, the JSON's iteration record and the chain
    export showed the complement's numbers as the task's (a table value of 0.8 where
    the optimum is 0.2).  By hand on the fork: P(F A) is 0.6 at most, 0.2 at least."""
    model = Model.from_game(_fork(), "F A", objective=objective)
    r = synthesize(model)
    first = next(row for row in r.policy_table() if row["game_state"] == "s")
    assert first["value"] == pytest.approx(expected, abs=1e-9)
    it = r.summary()["iteration"]
    assert it["lower"] - 1e-9 <= expected <= it["upper"] + 1e-9
    assert r.lower <= r.upper
    # the chain export on the bundled grid made minimised: what it prints about
    # P=? [F "accept"] is what Storm computes on the file it writes
    pytest.importorskip("stormpy")
    from test_chain import storm_accept

    text = tmp_path / "grid.toml"
    text.write_text((MODELS / "bus_risk.toml").read_text().replace(
        'name = "', f'objective = "{objective}"\nname = "', 1))
    assert main(["export", str(text), "--chain", str(tmp_path / "c.drn"), "-q"]) == 0
    said = capsys.readouterr().out
    printed = float(said.split(" = ")[-1].split()[0].rstrip(":)"))
    assert storm_accept(tmp_path / "c.drn") == pytest.approx(printed, abs=1e-9)


def test_objective_min_with_a_constraint_by_hand() -> None:
    """min P(G !A) s.t. P(F B) <= 0.2: play a w.p. 1 - q with 0.4 (1 - q) <= 0.2, so
    q >= 0.5, and P(G !A) = 0.4 + 0.4 q is least at q = 0.5: 0.6 (by hand); the
    constrained LP on the complement (F A, co-safe) read back."""
    model = Model.from_game(_fork(), "G !A", objective="min")
    r = synthesize(model, constraints=["P(F B) <= 0.2"])
    assert r.route == "constrained" and r.certified
    assert r.lower == pytest.approx(0.6, abs=1e-7)
    assert r.upper == pytest.approx(0.6, abs=1e-7)
    assert r.constraints[0].value == pytest.approx(0.2, abs=1e-7)


def test_objective_in_a_model_file(tmp_path: Path) -> None:
    text = (MODELS / "bus_grid.toml").read_text().replace(
        'epsilon = 0.01', 'epsilon = 0.01\nobjective = "min"')
    path = tmp_path / "bus_min.toml"
    path.write_text(text)
    r = synthesize(load_model(path))
    top = synthesize(load_model(MODELS / "bus_grid.toml"))
    assert r.certified and r.lower <= r.upper + 1e-9
    assert r.upper <= top.lower + 1e-9  # the least can not exceed the greatest
    bad = path.with_name("bad.toml")
    bad.write_text(text.replace('objective = "min"', 'objective = "least"'))
    with pytest.raises(Exception, match="objective: must be"):
        load_model(bad)


# --------------------------------------------------------------------------- options


def test_options_are_refused_by_name_on_every_route() -> None:
    """synthesize(model, constraints=[...], method="nonsense", truncation=...) returned a
    certified answer on the constrained route; every route now refuses both."""
    model = load_model(MODELS / "bus_risk.toml")
    for extra in ({}, {"constraints": ["P(F puddle) <= 0.05"]}):
        with pytest.raises(ProblemError, match="method"):
            synthesize(model, method="nonsense", **extra)
        with pytest.raises(ProblemError, match="'nonexistent' is not an event"):
            synthesize(model, truncation={"nonexistent": 3}, **extra)
    with pytest.raises(ProblemError, match="method 'vi' with constraints"):
        synthesize(model, method="vi", constraints=["P(F puddle) <= 0.05"])
    with pytest.raises(ProblemError, match="decompose with constraints"):
        synthesize(model, decompose=True, constraints=["P(F puddle) <= 0.05"])
    with pytest.raises(ProblemError, match="solver HIGHS"):
        synthesize(model, solver="highs", constraints=["P(F puddle) <= 0.05"])


def test_constrained_route_honours_truncation_and_epsilon() -> None:
    """The constrained route takes the same truncation settings as the plain one: with
    no constraint binding, both give the same bracket (two routes, one problem)."""
    model = load_model(MODELS / "red_light.toml")
    for kwargs in ({"epsilon": 0.05}, {"truncation": {"g": 3}}, {"clock_reduction": False}):
        plain = synthesize(model, **kwargs)
        con = synthesize(model, constraints=["E(steps) <= 1000"], **kwargs)
        assert con.certified and plain.certified
        assert con.lower == pytest.approx(plain.lower, abs=1e-6)
        assert con.upper == pytest.approx(plain.upper, abs=1e-6)


# --------------------------------------------------------------------------- bands


def _bus_fit_with(tmp_path: Path, extra: str) -> Path:
    shutil.copytree(MODELS / "data", tmp_path / "data")
    path = tmp_path / "fit.toml"
    path.write_text((MODELS / "bus_fit.toml").read_text().replace(
        'epsilon = 0.01', 'epsilon = 0.01\n' + extra))
    return path


def test_bands_with_then_or_expected_steps_are_solved_not_replaced_by_a_point_law(
        capsys: pytest.CaptureFixture[str]) -> None:
    """bus_fit with --then min-steps printed a certified answer for a point law (0.9244);
    then it was refused.  Now the worst case over the bands is solved: the bracket's
    lower end is at most the robust optimum without ``then`` (a point law's optimum is
    above it), and the expected steps are the worst law's, at least the middle law's."""
    alone = synthesize(load_model(MODELS / "bus_fit.toml"))
    for argv in (["--then", "min-steps"], ["--constraint", "E(steps) <= 9"]):
        assert main(["solve", str(MODELS / "bus_fit.toml"), "-q", "--json", *argv]) == 0
        record = json.loads(capsys.readouterr().out)
        assert record["robust"] and record["certified"]
        assert record["lower"] <= alone.upper + 1e-12 < 0.92


def test_bands_with_a_constraint_in_the_model_file_are_not_a_point_law(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """bus_fit with constraints in its file printed 0.9244053 certified (the bands
    replaced by a point law; the robust answer alone is 0.9201836 there).  A constraint
    can only lower the robust optimum: the bracket's lower end is at most the robust
    answer without it."""
    path = _bus_fit_with(tmp_path, 'constraints = ["P(F[0,5] A) <= 0.5"]')
    alone = synthesize(load_model(MODELS / "bus_fit.toml"))
    assert main(["solve", str(path), "-q", "--json"]) == 0
    record = json.loads(capsys.readouterr().out)
    assert record["robust"] and record["certified"]
    assert record["lower"] <= alone.upper + 1e-9


def _bus_risk_band(hazard: str) -> Model:
    from mitld_lp import loads_model

    text = (MODELS / "bus_risk.toml").read_text()
    return loads_model(text.replace("mu1 = { geometric = 0.8 }",
                                    f"mu1 = {{ geometric = {hazard} }}"), "bus_risk_band")


def _rollouts(result, p1: float, runs: int, seed: int) -> tuple[float, float]:  # noqa: ANN001
    """Success and puddle rates of the result's controller in the grid, bus 1 arriving
    at step ~ geometric(p1) and bus 2 ~ geometric(0.3), drawn here with numpy."""
    from mitld_lp.automata.joint import ACCEPTED

    rng = np.random.default_rng(seed)
    ctrl = result.controller
    ctrl.rng = rng
    game = ctrl.game
    won = wet = 0
    for _ in range(runs):
        times = {"b1": int(rng.geometric(p1)), "b2": int(rng.geometric(0.3))}
        ctrl.reset()
        s, events = game.initial, frozenset()
        for t in range(200):
            action = ctrl.act(Observation(state=s, events=events))
            if action is None or ctrl.settled:
                break
            events = frozenset(a for a, k in times.items() if k == t + 1)
            succ = game.successors(s, action, events)
            probs = np.array([q for _, q in succ])
            s = succ[int(rng.choice(len(succ), p=probs / probs.sum()))][0]
        won += ctrl.verdicts[0] == ACCEPTED
        wet += ctrl.verdicts[1] == ACCEPTED
    return won / runs, wet / runs


def test_bands_with_a_probability_constraint_get_a_sound_bracket(tmp_path: Path) -> None:
    """Bus 1's hazard anywhere in [0.7, 0.9], the puddle's risk at most 0.05.  upper is
    the constrained optimum at the middle law (geometric(0.8), a law of the band);
    lower is at most the constrained optimum at every fixed law of the band.  The band's
    controller, run at each end of the band, succeeds at least ``lower`` and keeps the
    risk: exactly, by Storm on the controller's chain in the world of that law (rational
    arithmetic), and by runs with the buses drawn here, which must agree with Storm's
    values (4-sigma bands)."""
    from test_sensed_optimistic import storm_of

    from mitld_lp.running.chain import write_chain

    r = synthesize(_bus_risk_band("[0.7, 0.9]"), constraints=["P(F puddle) <= 0.05"])
    assert r.route == "constrained" and r.certified, r.checks
    assert r.summary()["robust"] and r.summary()["bands"]
    fixed = {p: synthesize(_bus_risk_band(str(p)), constraints=["P(F puddle) <= 0.05"])
             for p in (0.7, 0.75, 0.8, 0.85, 0.9)}
    assert r.upper == pytest.approx(fixed[0.8].upper, abs=1e-8)
    assert all(r.lower <= f.lower + 1e-9 for f in fixed.values())
    assert r.lower > 0.4  # a bracket, not a vacuous one
    assert r.constraints[0].holds and r.constraints[0].value <= 0.05 + 1e-6
    runs = 400
    for p1 in (0.7, 0.9):
        storm = storm_of(write_chain(fixed[p1], tmp_path / f"band_{p1}.drn",
                                     controller=r.controller))
        exact_success, exact_risk = float(storm("accept")), float(storm("puddle"))
        assert exact_success >= r.lower - 1e-9
        assert exact_risk <= 0.05 + 1e-9
        success, risk = _rollouts(r, p1, runs=runs, seed=int(p1 * 10))
        assert abs(success - exact_success) <= 4 * (0.25 / runs) ** 0.5
        assert abs(risk - exact_risk) <= 4 * (exact_risk * (1 - exact_risk) / runs) ** 0.5



_SLIPPERY = {"dock": [(1, 1)], "goal": [(3, 2)], "puddle": [(2, 1), (2, 0)]}
_KEPT = ["G !puddle & D[mu] b & F(b & F[0,3] goal)", "G (b -> F[0,3] goal) & D[mu] b",
         "G (b -> F[0,2] goal) & D[mu] b & G !puddle"]


@pytest.mark.parametrize("spec", _KEPT)
def test_point_laws_through_the_robust_route_keep_a_safety_part_as_the_plain_route(
        spec: str) -> None:
    """Robust acceptance of a safety part (the greatest set the robot keeps runs in
    against every nature) and the plain route's accepting end components are different
    algorithms; with a point law they must give one answer."""
    from mitld_lp.distributions.literal import from_table
    from mitld_lp.routes.robust import synthesize_robust

    world = GridWorld.make(4, 3, start=(0, 0), slip=0.2, regions=_SLIPPERY)
    m = Model.from_game(world, spec, distributions={"mu": from_table({"geometric": 0.3},
                                                                     "mu")})
    plain, robust = synthesize(m), synthesize_robust(m)
    assert plain.route == "plain" and plain.certified and robust.certified
    assert 0.05 < plain.lower < 0.95
    assert robust.lower == pytest.approx(plain.lower, abs=1e-8)
    assert robust.upper == pytest.approx(plain.upper, abs=1e-8)


@pytest.mark.parametrize("spec", _KEPT)
def test_bands_with_a_safety_part_are_solved_soundly(spec: str) -> None:
    """A band with a safety part: the robust optimum is at most the optimum at every
    fixed law of the band (the ends and inside), and the policy's worst case is
    certified."""
    from mitld_lp.distributions.literal import from_table

    world = GridWorld.make(4, 3, start=(0, 0), slip=0.2, regions=_SLIPPERY)
    r = synthesize(Model.from_game(world, spec, distributions={
        "mu": from_table({"geometric": [0.2, 0.4]}, "mu")}))
    assert r.route == "robust" and r.certified, r.failed_checks
    for p in (0.2, 0.27, 0.33, 0.4):
        fixed = synthesize(Model.from_game(world, spec, distributions={
            "mu": from_table({"geometric": p}, "mu")}))
        assert r.upper <= fixed.upper + 1e-9


# --------------------------------------------------------------------------- batches, sweeps


def test_a_batch_honours_the_constraint(tmp_path: Path,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    """A batch dropped --constraint (0.9244053 certified for both files); alone the model
    answers the constrained problem, and the batch must answer the same for each file."""
    copy = tmp_path / "copy.toml"
    shutil.copy(MODELS / "bus_risk.toml", copy)
    alone = synthesize(load_model(copy), constraints=["P(F puddle) <= 0.05"])
    assert alone.lower < 0.9  # the constraint binds (0.9244 without it)
    code = main(["solve", str(MODELS / "bus_risk.toml"), str(copy), "--json", "-q",
                 "--constraint", "P(F puddle) <= 0.05"])
    rows = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert code == 0 and len(rows) == 2
    for row in rows:
        assert row["lower"] == pytest.approx(alone.lower, abs=1e-7)
        assert row["constraints"][0]["value"] <= 0.05 + 1e-6


def test_a_batch_of_one_constrained_model_file(tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    """A batch of one model file with constraints exited 1 (KeyError: 'seconds')."""
    path = tmp_path / "risk.toml"
    path.write_text((MODELS / "bus_risk.toml").read_text().replace(
        'epsilon = 0.01', 'epsilon = 0.01\nconstraints = ["P(F puddle) <= 0.05"]'))
    code = main(["solve", str(tmp_path / "*.toml"), "-q"])
    out = capsys.readouterr().out
    assert code == 0, out
    assert "certified yes" in out


def test_a_sweep_over_a_constrained_model_file(tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    """A sweep over a model file with constraints exited 1 (KeyError: 'value'); each
    point is now the constrained problem: its row equals the library's constrained
    answer for that point's model."""
    text = (MODELS / "bus_risk.toml").read_text().replace(
        'epsilon = 0.01', 'epsilon = 0.01\nconstraints = ["P(F puddle) <= 0.05"]')
    (tmp_path / "risk.toml").write_text(text)
    sweep = tmp_path / "sweep.toml"
    sweep.write_text('name = "risk"\nmodel = "risk.toml"\n[vary]\n'
                     "distributions.mu2.geometric = [0.2, 0.5]\n")
    out = tmp_path / "risk.csv"
    code = main(["sweep", str(sweep), "-o", str(out), "-q"])
    assert code == 0, capsys.readouterr()
    import csv

    rows = list(csv.DictReader(out.open()))
    assert [r["status"] for r in rows] == ["optimal"] * 2
    for row, p in zip(rows, (0.2, 0.5), strict=True):
        point = tmp_path / f"p{p}.toml"
        point.write_text(text.replace("mu2 = { geometric = 0.3 }",
                                      f"mu2 = {{ geometric = {p} }}"))
        alone = synthesize(load_model(point))
        assert alone.route == "constrained"
        assert float(row["lower"]) == pytest.approx(alone.lower, abs=1e-9)


# --------------------------------------------------------------------------- other verbs


@pytest.mark.parametrize("verb", [["export", "--drn", "x.drn"], ["info"]])
def test_verbs_that_take_no_constraints_refuse_a_constrained_model(
        verb: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """export wrote the unconstrained model of a file with constraints and exited 0."""
    path = tmp_path / "risk.toml"
    path.write_text((MODELS / "bus_risk.toml").read_text().replace(
        'epsilon = 0.01', 'epsilon = 0.01\nconstraints = ["P(F puddle) <= 0.05"]'))
    argv = [verb[0], str(path), *[str(tmp_path / v) if v.endswith(".drn") else v
                                  for v in verb[1:]], "-q"]
    assert main(argv) == 2
    assert f"{verb[0]}: the model has constraints" in capsys.readouterr().err
    assert not (tmp_path / "x.drn").exists()


def test_simulate_runs_the_constrained_controller(capsys: pytest.CaptureFixture[str]) -> None:
    """simulate took no --constraint; it now runs the randomised controller of the
    constrained problem, and its estimate agrees with the certified value."""
    code = main(["simulate", str(MODELS / "bus_risk.toml"), "--constraint",
                 "P(F puddle) <= 0.05", "-n", "1500", "--seed", "3", "--json", "-q"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0
    lo, hi = out["certified_bracket"]
    assert lo < 0.9  # the constrained problem's value, not the unconstrained 0.9244
    assert out["ci95"][0] - 0.01 <= hi and out["ci95"][1] + 0.01 >= lo


# --------------------------------------------------------------------------- one schema


def test_one_json_schema_on_every_route(capsys: pytest.CaptureFixture[str]) -> None:
    for argv in (["solve", str(MODELS / "bus_grid.toml")],
                 ["solve", str(MODELS / "bus_fit.toml")],
                 ["solve", str(MODELS / "bus_risk.toml"), "--constraint",
                  "P(F puddle) <= 0.05"]):
        assert main([*argv, "--json", "-q"]) == 0
        record = json.loads(capsys.readouterr().out)
        assert tuple(record) == SUMMARY_KEYS


# --------------------------------------------------------------------------- optimal everywhere


def _optimal_values(r) -> np.ndarray:  # noqa: ANN001 - a Result of the plain route
    """Value iteration written here: the least fixed point of V = max_c P(c) V with V = 1
    on the result's reachability target (its accepting end components), 20,000 sweeps
    from 0 on a product of 69 states."""
    mdp, goal = r.mdp, r.acceptance.goal
    v = goal.astype(float)
    for _ in range(20_000):
        nxt = np.maximum.reduceat(mdp.matrix @ v, mdp.row_groups[:-1])
        nxt[goal] = 1.0
        if np.max(np.abs(nxt - v)) < 1e-13:
            break
        v = nxt
    return v


@pytest.mark.parametrize("deadline", [3, 5, 6, 7])
def test_obligation_policy_optimal_everywhere_when_the_start_is_decided(deadline: int) -> None:
    """G (dock -> F[0,5] goal) on a 5x4 grid answered [1, 1] and certified: NO (the start
    is decided by graph analysis, no LP was solved, the policy elsewhere was left 0.17
    below optimal).  Now certified, and the policy's values equal value iteration's in
    every state."""
    world = GridWorld.make(5, 4, start=(0, 0), slip=0.1,
                           regions={"dock": [(2, 1)], "goal": [(4, 3)]})
    r = synthesize(Model.from_game(world, f"G (dock -> F[0,{deadline}] goal)"))
    assert r.certified, r.failed_checks
    assert r.lower == pytest.approx(1.0) and r.upper == pytest.approx(1.0)
    best = _optimal_values(r)
    assert np.max(np.abs(r.lower_model.policy_values - best)) < 1e-6


def test_a_failed_check_is_reported_once_when_nothing_is_truncated() -> None:
    world = GridWorld.make(3, 1, start=(0, 0), regions={"A": [(2, 0)]})
    r = synthesize(Model.from_game(world, "F A"))
    assert r.upper_model is r.lower_model
    assert len(r.failed_checks) == len({c.name for c in r.failed_checks})


# --------------------------------------------------------------------------- safety + constraints


def test_a_minimum_of_zero_with_a_constraint_is_certified_as_zero() -> None:
    """min P(G (b -> F[0,2] goal)) s.t. P(F puddle) <= 0.2 on a slippery 3x2 grid: the
    unconstrained minimum is 0 (the plain route, on the task's own automaton), so the
    constrained one is at least 0, and the returned policy's value is 0 (the
    constrained route's exact evaluation of its chain).  The constrained route reads the
    minimum back from the complement's maximum, whose LP upper bound is 1 + 2.4e-11: the bracket was
    [-2.35e-11, 0], outside [0, 1] and failing the precision check (no relative width
    holds a value of 0)."""
    world = GridWorld.make(3, 2, start=(0, 0), slip=0.2,
                           regions={"goal": [(2, 1)], "puddle": [(1, 0)]})
    from mitld_lp.distributions import from_table

    model = Model.from_game(world, "G (b -> F[0,2] goal)", objective="min", epsilon=0.05,
                            events={"b": from_table({"geometric": 0.4}, "mu")})
    plain = synthesize(model)
    assert plain.route != "constrained" and plain.upper == 0.0
    r = synthesize(model, constraints=["P(F puddle) <= 0.2"])
    assert r.route == "constrained" and r.certified, r.checks
    assert (r.lower, r.upper) == (0.0, 0.0)
    assert r.constraints[0].value <= 0.2 + 1e-9


def test_one_minus_keeps_a_probability_bracket_in_the_unit_interval() -> None:
    """``one_minus`` by hand: [1 - upper, 1 - lower] outward, clipped to [0, 1]."""
    from fractions import Fraction

    from mitld_lp.solvers.rounding import one_minus

    assert one_minus(1.0, 1.0 + 2.4e-11) == (0.0, 0.0)
    assert one_minus(-1e-12, 0.0) == (1.0, 1.0)
    lo, hi = one_minus(0.3, 0.7)
    assert Fraction(lo) <= 1 - Fraction(0.7) <= 1 - Fraction(0.3) <= Fraction(hi)
    assert hi - lo < 1e-15 + 0.4


def _gamble() -> ExplicitGame:
    """``safe`` stays clear of h for ever; ``go`` reaches g w.p. 0.7, else h."""
    return ExplicitGame(
        initial="s",
        transitions={"s": {"safe": {"s1": 1.0}, "go": {"h": 0.3, "g": 0.7}},
                     "s1": {"wait": {"s1": 1.0}}, "h": {"wait": {"h": 1.0}},
                     "g": {"wait": {"g": 1.0}}},
        labels={"h": {"h"}, "g": {"g"}})


def test_a_safety_task_with_a_constraint_by_hand() -> None:
    """max P(G !h) s.t. P(F g) >= 0.5: play go w.p. q >= 5/7, P(G !h) = 1 - 0.3 q, so
    1 - 0.3 * 5/7 (by hand); the controller's runs agree within their 4-sigma band."""
    from mitld_lp.running.constrained_runs import run_constrained

    r = synthesize(Model.from_game(_gamble(), "G !h"), constraints=["P(F g) >= 0.5"])
    assert r.route == "constrained" and r.certified, r.checks
    want = 1 - 0.3 * 5 / 7
    assert r.lower == pytest.approx(want, abs=1e-7)
    assert r.upper == pytest.approx(want, abs=1e-7)
    runs = run_constrained(r, runs=4000, seed=3)
    sigma = (want * (1 - want) / runs.runs) ** 0.5
    assert abs(runs.accepted[0] / runs.runs - want) < 4 * sigma
    assert abs(runs.accepted[1] / runs.runs - 0.5) < 4 * (0.25 / runs.runs) ** 0.5


def _joint_drn(result, path: Path) -> None:  # noqa: ANN001 - a Result of the constrained route
    """The product of the world with the joint automaton (before any merging) as DRN,
    labelled ``rejected`` (the task's automaton rejected) and ``c1`` (the first
    constraint's formula accepted)."""
    from mitld_lp.automata.joint import ACCEPTED, REJECTED
    from mitld_lp.product import ProductState

    mdp, joint = result.mdp, result.joint
    lines = ["@type: MDP", "@parameters", "", "@reward_models", "", "@nr_states",
             str(mdp.n_states), "@nr_choices", str(mdp.n_choices), "@model"]
    for s in range(mdp.n_states):
        rec = mdp.states[s]
        labels = ["init"] if s == mdp.initial else []
        if isinstance(rec, ProductState):
            v = joint.verdicts[rec.automaton]
            labels += ["rejected"] * (v[0] == REJECTED) + ["c1"] * (v[1] == ACCEPTED)
        lines.append(f"state {s} {' '.join(labels)}".rstrip())
        for k, c in enumerate(range(mdp.row_groups[s], mdp.row_groups[s + 1])):
            lines.append(f"\taction {k}")
            row = mdp.matrix[[c]].tocoo()
            lines += [f"\t\t{j} : {float(p)!r}" for j, p in zip(row.col, row.data,
                                                                  strict=True)]
    path.write_text("\n".join(lines) + "\n")


@pytest.mark.parametrize(("spec", "constraint", "query"), [
    ("G !puddle", "P(F[0,8] goal) >= 0.5", 'P>=0.5 [F "c1"]'),
    ("G (dock -> F[0,4] goal) & G !puddle", "P(F[0,8] goal) >= 0.5", 'P>=0.5 [F "c1"]'),
    ("G (dock -> F[0,4] goal) & G !puddle", "P(F dock) >= 0.5", 'P>=0.5 [F "c1"]'),
])
def test_safety_with_a_constraint_matches_storms_multi_objective_engine(
        tmp_path: Path, spec: str, constraint: str, query: str) -> None:
    """Safety tasks (one timed) with a co-safe constraint that binds, on a slippery grid:
    Storm's multi-objective engine on the joint product (G !rejected is the acceptance
    of a safety automaton) gives the same optimum."""
    stormpy = pytest.importorskip("stormpy")
    import stormpy.environments as env_mod

    world = GridWorld.make(4, 3, start=(0, 0), slip=0.2,
                           regions={"dock": [(1, 1)], "goal": [(3, 2)],
                                    "puddle": [(2, 1), (2, 0)]})
    r = synthesize(Model.from_game(world, spec), constraints=[constraint])
    assert r.route == "constrained" and r.certified, r.checks
    _joint_drn(r, tmp_path / "joint.drn")
    model = stormpy.build_model_from_drn(str(tmp_path / "joint.drn"))
    env = stormpy.Environment()
    multi = env.modelchecker().multi()
    multi.precision = stormpy.Rational("1/1000000000")
    multi.precision_type = env_mod.MultiObjectivePrecisionType.ABSOLUTE
    prop = stormpy.parse_properties(f'multi(Pmax=? [G !"rejected"], {query})')[0]
    want = stormpy.model_checking(model, prop, environment=env).get_value(
        model.initial_states[0])
    assert 0.05 < want < 0.999  # a constraint that binds
    assert r.lower == pytest.approx(want, abs=1e-6)
    assert r.constraints[0].value >= 0.5 - 1e-6


# --------------------------------------------------------------------------- the whole matrix


_TASKS = {  # class -> (spec, whether the event is asked for by D[mu] b in the spec)
    "co-safe": ("D[mu] b & F(b & F[0,3] goal)", True),
    "safety": ("G (b -> F[0,3] goal)", False),
    "obligation": ("G !puddle & D[mu] b & F(b & F[0,3] goal)", True),
}


def _laws() -> dict[str, tuple[object, list[object]]]:
    """law kind -> (the law, point laws within it): a point law, a band, a fit from 40
    arrival times drawn here (its band over the 95% interval of p)."""
    from mitld_lp import fit_law
    from mitld_lp.distributions.literal import from_table

    def geo(p: float) -> object:
        return from_table({"geometric": p}, "mu")

    fit = fit_law(np.random.default_rng(0).geometric(0.3, 40))
    (par,) = fit.parameters
    return {
        "point": (geo(0.3), [geo(0.3)]),
        "band": (from_table({"geometric": [0.2, 0.4]}, "mu"), [geo(p) for p in (0.2, 0.3, 0.4)]),
        "fitted": (fit.band, [geo(p) for p in (par.lo, 0.5 * (par.lo + par.hi), par.hi)]),
    }


def _model(task: str, law: object) -> Model:
    spec, asks = _TASKS[task]
    world = GridWorld.make(4, 3, start=(0, 0), slip=0.2, regions=_SLIPPERY)
    if asks:
        return Model.from_game(world, spec, distributions={"mu": law})
    return Model.from_game(world, spec, events={"b": law})


_EXTRAS = {"none": {}, "constraints": {"constraints": ["P(F puddle) <= 0.3"]},
           "then": {"then": "min-steps"}}


@pytest.mark.parametrize("task", sorted(_TASKS))
@pytest.mark.parametrize("law", ["point", "band", "fitted"])
@pytest.mark.parametrize("extra", sorted(_EXTRAS))
def test_every_cell_of_the_composition_matrix(task: str, law: str, extra: str) -> None:
    """Each cell is solved within the bounds of an independent route, or refused naming
    the combination.  The independent route is the same problem at point laws of the
    band, solved on its own: the robust (constrained) optimum is at most the optimum at
    any of them, and with a point law the robust route (another algorithm) agrees; a
    constraint or a lexicographic second objective can only lower the optimum."""
    the_law, points = _laws()[law]
    model = _model(task, the_law)
    kwargs = _EXTRAS[extra]
    r = synthesize(model, **kwargs)
    assert r.certified, r.summary()["failed_checks"]
    assert -1e-9 <= r.lower <= r.upper + 1e-9 <= 1 + 2e-9
    at_points = [synthesize(_model(task, p), **kwargs) for p in points]
    free = [synthesize(_model(task, p)) for p in points]
    for fixed, alone in zip(at_points, free, strict=True):
        assert r.lower <= fixed.upper + 1e-9  # no bracket claims more than a law allows
        assert fixed.lower <= alone.upper + 1e-9  # extras only lower the optimum
    if law == "point" and extra == "none":
        from mitld_lp.routes.robust import synthesize_robust

        other = synthesize_robust(model)
        assert other.lower == pytest.approx(r.lower, abs=1e-8)
    if extra == "constraints":
        assert all(c.holds for c in r.constraints)
    if extra == "then":
        assert r.lower >= synthesize(model).lower - 1e-5


@pytest.mark.parametrize("task", sorted(_TASKS))
@pytest.mark.parametrize("extra", ["constraints", "then"])
def test_the_best_law_with_constraints_or_then_bounds_every_law_of_the_band(
        task: str, extra: str) -> None:
    """``bands = "best"`` with an extra: each point law of the band is a law nature may
    pick, so its optimum (another route) is at most the optimistic ``upper``; the
    pessimistic answer's ``lower`` too; the constraints hold at the law chosen."""
    the_law, points = _laws()["band"]
    kwargs = _EXTRAS[extra]
    best = synthesize(_model(task, the_law), bands="best", **kwargs)
    assert best.certified, best.summary()["failed_checks"]
    assert best.summary()["bands_reading"] == "best"
    for p in points:
        assert synthesize(_model(task, p), **kwargs).lower <= best.upper + 1e-9
    assert synthesize(_model(task, the_law), **kwargs).lower <= best.upper + 1e-9
    assert best.lower <= synthesize(_model(task, the_law), bands="best").upper + 1e-9
    if extra == "constraints":
        assert all(c.holds for c in best.constraints)


_GRID_FILE = """name = "walk"
spec = "G !puddle & D[mu] b & F(b & F[0,3] goal)"
{extra}
[grid]
size = [4, 3]
start = [0, 0]
slip = 0.2
obstacles = []
[regions]
goal = [[3, 2]]
puddle = [[2, 1], [2, 0]]
dock = [[1, 1]]
[distributions]
mu = {{ geometric = {law} }}
"""


@pytest.mark.parametrize("law", ["0.3", "[0.2, 0.4]"])
@pytest.mark.parametrize("extra", ["", 'constraints = ["P(F puddle) <= 0.3"]'])
def test_every_verb_on_every_kind_of_model_file(tmp_path: Path, law: str, extra: str,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    """Each verb on a model file with a point law or a band, with or without constraints:
    done (0, or 3 with a status), or refused by one line naming the combination (2);
    never an internal error, never a file written for a refused combination."""
    path = tmp_path / "walk.toml"
    path.write_text(_GRID_FILE.format(extra=extra, law=law))
    sweep = tmp_path / "sweep.toml"
    sweep.write_text('name = "walk"\nmodel = "walk.toml"\n[vary]\nepsilon = [0.01, 0.02]\n')
    verbs = {
        "solve": ["solve", str(path)],
        "simulate": ["simulate", str(path), "-n", "50"],
        "export": ["export", str(path), "--drn", str(tmp_path / "out.drn")],
        "plot": ["plot", str(path), "-o", str(tmp_path / "out.png")],
        "pareto": ["pareto", str(path), "--against", "P(F puddle)", "--points", "2",
                   "--csv", str(tmp_path / "out.csv")],
        "sweep": ["sweep", str(sweep), "-o", str(tmp_path / "out_sweep.csv")],
    }
    for verb, argv in verbs.items():
        code = main([*argv, "-q"])
        err = capsys.readouterr().err
        assert code in (0, 2, 3), (verb, code, err)
        if code == 2:
            assert err.count("\n") == 1 and ("constraints" in err or "band" in err), (verb, err)
            written = [a for a in argv if a.startswith(str(tmp_path / "out"))]
            assert not any(Path(w).exists() for w in written), verb
        if verb in ("solve", "sweep"):
            assert code == 0, (verb, err)


def test_a_constrained_policy_table_names_prism_states_by_their_variables(
        tmp_path: Path) -> None:
    """The constrained route's policy table wrote a PRISM world's states as raw tuples;
    it writes them by variable, as the plain table and mitld-lp run do."""
    pytest.importorskip("stormpy")
    from mitld_lp import load_model

    (tmp_path / "w.prism").write_text(
        "mdp\nmodule m\n  x : [0..3] init 0;\n"
        "  [safe] x=0 -> (x'=1);\n  [go] x=0 -> 0.3:(x'=2) + 0.7:(x'=3);\n"
        "  [wait] x>0 -> true;\nendmodule\nlabel \"h\" = x=2;\nlabel \"g\" = x=3;\n")
    (tmp_path / "w.toml").write_text('name = "w"\nspec = "F g"\n'
                                     'constraints = ["P(F h) <= 0.1"]\n'
                                     '[prism]\nfile = "w.prism"\n')
    r = synthesize(load_model(tmp_path / "w.toml"))
    assert r.route == "constrained" and r.certified
    assert r.lower == pytest.approx(0.7 * 0.1 / 0.3, abs=1e-7)  # go w.p. 1/3: P(h) = 0.1
    rows = r.policy_table()
    assert rows and all(isinstance(row["game_state"], dict) and set(row["game_state"]) == {"x"}
                        for row in rows)


def test_one_status_vocabulary_on_every_route() -> None:
    """The constrained route answered with bare strings where the others used Status;
    every route's status is now a Status member (each also its string)."""
    from mitld_lp.solvers.result import Status

    risk = load_model(MODELS / "bus_risk.toml")
    results = [synthesize(load_model(MODELS / "bus_grid.toml")),
               synthesize(load_model(MODELS / "bus_fit.toml")),
               synthesize(risk, constraints=["P(F puddle) <= 0.05"]),
               synthesize(risk, constraints=["P(F puddle) <= 0.05", "P(F puddle) >= 0.5"])]
    assert [r.route for r in results] == ["plain", "robust", "constrained", "constrained"]
    assert all(isinstance(r.status, Status) for r in results)
    assert [r.status for r in results] == [Status.OPTIMAL] * 3 + [Status.INFEASIBLE]
    assert results[2].status == "optimal" and f"{results[3].status}" == "infeasible"


def test_one_result_type_and_one_wiring_on_every_route() -> None:
    """Three routes returned three classes (SynthesisResult, RobustResult,
    ConstrainedResult) with checks as records on two and bare tuples on the third, and
    each route wired its own stages (the constrained one timed them as "build").  Now:
    one type, the checks as records whose conjunction is ``certified``, the same stage
    timings, and the policy table of each route as the route's policy says: a
    deterministic one row per state, a randomised one summing to 1 per state."""
    from collections import defaultdict

    from mitld_lp import Result
    from mitld_lp.checks import Check

    risk = load_model(MODELS / "bus_risk.toml")
    fit = load_model(MODELS / "bus_fit.toml")
    results = [synthesize(load_model(MODELS / "bus_grid.toml")), synthesize(fit),
               synthesize(risk, constraints=["P(F puddle) <= 0.05"]),
               synthesize(fit, constraints=["P(F[0,5] A) <= 0.5"])]
    assert [r.route for r in results] == ["plain", "robust", "constrained", "constrained"]
    for r in results:
        assert type(r) is Result
        assert r.checks and all(isinstance(c, Check) for c in r.checks)
        assert r.certified == all(c.passed for c in r.checks)
        assert r.failed_checks == tuple(c for c in r.checks if not c.passed)
        assert {"automaton", "product", "solve"} <= set(r.timings)
        assert 0.0 <= r.lower <= r.upper + 1e-9 <= 1.0 + 1e-9
        assert tuple(r.summary()) == SUMMARY_KEYS
    plain, robust, point, band = results
    assert robust.bands and band.bands and not plain.bands and not point.bands
    assert band.first_step_hazards() == robust.first_step_hazards()
    for r in (plain, robust):  # deterministic: one row per undecided state
        rows = r.policy_table()
        assert len({(str(x["game_state"]), x["automaton_state"], tuple(x["pending"]),
                     x["clock"]) for x in rows}) == len(rows)
    for r in (point, band):  # randomised: each state's probabilities sum to 1
        total: dict[tuple, float] = defaultdict(float)
        for x in r.policy_table():
            key = (str(x["game_state"]), str(x["automaton_state"]), tuple(x["pending"]),
                   x["clock"])
            total[key] += x["probability"]
        assert total and all(v == pytest.approx(1.0, abs=1e-6) for v in total.values())


def test_library_refusals_name_what_the_caller_gave() -> None:
    """An unknown solver returned status 'failed' on the plain route (the command line
    refused it); pareto with then= leaked a TypeError, and on a model with sensors its
    refusal named a constraint the caller never gave."""
    from mitld_lp import pareto

    grid = load_model(MODELS / "bus_grid.toml")
    with pytest.raises(ProblemError, match="solver: unknown or not installed LP solver 'NOPE'"):
        synthesize(grid, solver="NOPE")
    with pytest.raises(ProblemError, match="pareto: the curve poses its own constraint"):
        pareto(grid, against="steps", then="min-cost")
    # (the curve with sensors is solved now: tests/test_sensed_constrained.py, with false
    # alarms at a point law and under a band too; with false alarms on a world whose
    # moves react to the sensed event at a law that may never happen, once refused here,
    # each point is bracketed: tests/test_sensing_reacting_never.py)
    corridor = MODELS / "corridor.toml"
    text = corridor.read_text().replace("door = { poisson = 2 }", "door = { pmf = [0.3, 0.3] }")
    sensed = loads_model(text + "\n[sensors]\nopened = { detect = 0.5, "
                         "false_alarm = 0.1 }\n", source=corridor)
    points = pareto(sensed, against="steps", points=3)
    assert all(p.status.has_solution and p.achieved <= p.bound + 1e-7 for p in points)
