"""Constrained synthesis (issue 19): a hand case forcing randomisation, an occupancy LP
written here with scipy's linprog on a finite-horizon world, Storm's multi-objective
model checking on a DRN written here, Monte-Carlo runs of the randomised controller,
and the entry points (text, model file, CLI)."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import linprog

from mitld_lp.automata.joint import ACCEPTED
from mitld_lp.logic.constraints import ConstraintError, parse_constraint
from mitld_lp.model import Model, ModelError, loads_model
from mitld_lp.running.constrained_runs import run_constrained
from mitld_lp.synthesis import synthesize, synthesize_constrained
from mitld_lp.testing import two_routes_world
from mitld_lp.worlds.game import ExplicitGame

HAND = two_routes_world()  # worked by hand: safe 1/2; risky 0.9, 0.3 via a hazard


def _mix(result, state="s0"):
    return {row["action"]: row["probability"] for row in result.policy_table()
            if row["game_state"] == state}


def test_binding_risk_bound_forces_the_exact_mix():
    # P(hazard) = 0.3 lam <= 0.15 -> lam = 1/2; P(goal) = 0.9 lam + 0.5 (1 - lam) = 0.7,
    # strictly between the deterministic policies' 0.5 (safe) and 0.9 (risky, 0.3 risk).
    m = Model.from_game(HAND, "F goal")
    r = synthesize_constrained(m, ["P(F hazard) <= 0.15"])
    assert r.status == "optimal" and r.certified
    assert r.lower == pytest.approx(0.7, abs=1e-7)
    assert r.upper == pytest.approx(0.7, abs=1e-7)
    mix = _mix(r)
    assert mix["risky"] == pytest.approx(0.5, abs=1e-6)
    assert mix["safe"] == pytest.approx(0.5, abs=1e-6)
    assert r.constraints[0].value == pytest.approx(0.15, abs=1e-7)
    assert r.constraints[0].holds
    free = synthesize_constrained(m, [])
    assert free.lower == pytest.approx(0.9, abs=1e-7)


def test_infeasible_is_a_status_with_the_tightest_bound():
    m = Model.from_game(HAND, "F goal")
    r = synthesize_constrained(m, ["P(F hazard) >= 0.5"])
    assert r.status == "infeasible" and r.controller is None
    # the most hazard any policy gives is 0.3 (always risky)
    assert r.constraints[0].feasible_bound == pytest.approx(0.3, abs=1e-7)


def test_synthesize_takes_constraints_and_the_model_file_too():
    m = Model.from_game(HAND, "F goal")
    r = synthesize(m, constraints=["P(F hazard) <= 0.15"])
    assert r.lower == pytest.approx(0.7, abs=1e-7)


def test_lexicographic_keeps_the_probability_and_reports_steps():
    # Two ways to the goal: "slow" goes through a corridor of 3 steps, "fast" directly;
    # both succeed with probability 1; min-steps must pick "fast" (1 step).
    g = ExplicitGame(initial="a", transitions={
        "a": {"slow": {"c1": 1.0}, "fast": {"goal": 1.0}},
        "c1": {"go": {"c2": 1.0}}, "c2": {"go": {"goal": 1.0}},
        "goal": {"wait": {"goal": 1.0}}}, labels={"goal": {"goal"}})
    m = Model.from_game(g, "F goal")
    r = synthesize_constrained(m, [], then="min-steps")
    assert r.lower == pytest.approx(1.0, abs=1e-6)
    assert r.secondary == pytest.approx(1.0, abs=1e-6)
    assert _mix(r, "a") == {"fast": pytest.approx(1.0)}
    # a steps bound below 3 on a world with only the slow way is infeasible
    r3 = synthesize_constrained(m, ["E(steps) <= 0.5"])
    assert r3.status == "infeasible"
    assert r3.constraints[0].feasible_bound == pytest.approx(1.0, abs=1e-6)


def test_costs_weight_the_actions():
    g = ExplicitGame(initial="a", transitions={
        "a": {"slow": {"c1": 1.0}, "fast": {"goal": 1.0}},
        "c1": {"go": {"goal": 1.0}}, "goal": {"wait": {"goal": 1.0}}}, labels={"goal": {"goal"}})
    m = Model.from_game(g, "F goal")
    r = synthesize_constrained(m, [], then="min-cost", costs={"fast": 5.0})
    # fast costs 5, slow + go cost 2
    assert r.secondary == pytest.approx(2.0, abs=1e-6)
    with pytest.raises(ConstraintError, match="costs.fly"):
        synthesize_constrained(m, [], costs={"fly": 1.0})


# ----------------------------------------------------------------- scipy linprog

def _random_world(seed: int, n: int = 5):
    rng = np.random.default_rng(seed)
    trans = {}
    for s in range(n):
        acts = {}
        for a in ("a", "b"):
            succ = rng.choice(n, size=2, replace=False)
            p = rng.uniform(0.2, 0.8)
            acts[a] = {int(succ[0]): p, int(succ[1]): 1 - p}
        trans[s] = acts
    labels = {n - 1: {"goal"}, 1: {"hazard"}}
    return ExplicitGame(initial=0, transitions=trans, labels=labels,
                        proposition_names=frozenset({"goal", "hazard"})), trans, labels


def _linprog_value(trans, labels, horizon, risk, steps_bound=None):
    """max P(F[0,H] goal) s.t. P(F[0,H] hazard) <= risk (and E(steps) <= bound) by an
    occupancy LP over (time, state, goal seen, hazard seen), written independently."""
    n = len(trans)
    nodes = [(t, s, g, h) for t in range(horizon + 1) for s in range(n)
             for g in (0, 1) for h in (0, 1)]
    acts = ("a", "b")
    var = {(node, a): i for i, (node, a) in enumerate(itertools.product(nodes, acts))
           if node[0] < horizon}
    idx = {node: i for i, node in enumerate(nodes)}

    def flags(s, g, h):
        lab = labels.get(s, set())
        return int(g or "goal" in lab), int(h or "hazard" in lab)

    # can the goal still be seen from (t, s) within the horizon (graph reachability)?
    reach = {}
    for t in range(horizon, -1, -1):
        for s in range(n):
            ok = "goal" in labels.get(s, set())
            if t < horizon:
                ok = ok or any(reach[(t + 1, s2)] for a in acts for s2 in trans[s][a])
            reach[(t, s)] = ok
    a_eq = np.zeros((len(nodes), len(var)))
    b_eq = np.zeros(len(nodes))
    g0, h0 = flags(0, 0, 0)
    b_eq[idx[(0, 0, g0, h0)]] = 1.0
    final = np.zeros((len(nodes), len(var)))  # mass arriving at time H per node
    for (node, a), i in var.items():
        t, s, g, h = node
        a_eq[idx[node], i] += 1.0
        for s2, p in trans[s][a].items():
            node2 = (t + 1, s2, *flags(s2, g, h))
            if t + 1 < horizon:
                a_eq[idx[node2], i] -= p
            else:
                final[idx[node2], i] += p
    # nodes at time H have no variables: drop their rows
    keep = [idx[nd] for nd in nodes if nd[0] < horizon]
    a_eq, b_eq = a_eq[keep], b_eq[keep]
    goal_c = np.zeros(len(var))
    haz_c = np.zeros(len(var))
    steps_c = np.zeros(len(var))
    for (node, _a), i in var.items():
        t, s, g, h = node
        steps_c[i] = float(not g and reach[(t, s)])
    for nd in nodes:
        if nd[0] == horizon:
            goal_c += final[idx[nd]] * nd[2]
            haz_c += final[idx[nd]] * nd[3]
    rows, bounds = [haz_c], [risk]
    if steps_bound is not None:
        rows.append(steps_c)
        bounds.append(steps_bound)
    res = linprog(-goal_c, A_ub=np.array(rows), b_ub=bounds, A_eq=a_eq, b_eq=b_eq,
                  bounds=(0, None), method="highs")
    assert res.status in (0, 2)
    return None if res.status == 2 else -res.fun  # 2: infeasible


@pytest.mark.parametrize("seed", [1, 2, 3, 4, 5])
def test_matches_an_occupancy_lp_written_with_linprog(seed):
    game, trans, labels = _random_world(seed)
    horizon = 4
    m = Model.from_game(game, f"F[0,{horizon}] goal")
    free = synthesize_constrained(m, [f"P(F[0,{horizon}] hazard) <= 1"])
    risk = 0.5 * free.constraints[0].value  # binding: half the risk of the free optimum
    want = _linprog_value(trans, labels, horizon, risk)
    r = synthesize_constrained(m, [f"P(F[0,{horizon}] hazard) <= {risk!r}"])
    if want is None:  # no policy halves the risk: both LPs must say so
        assert r.status == "infeasible"
        return
    assert r.status == "optimal" and r.certified
    assert r.lower == pytest.approx(want, abs=1e-6)
    assert r.constraints[0].value <= risk + 1e-6
    # with an expected-steps bound too
    steps = 0.9 * free.steps
    want2 = _linprog_value(trans, labels, horizon, risk, steps)
    r2 = synthesize_constrained(m, [f"P(F[0,{horizon}] hazard) <= {risk!r}",
                                    f"E(steps) <= {steps!r}"])
    if want2 is None:
        assert r2.status == "infeasible"
        return
    assert r2.lower == pytest.approx(want2, abs=1e-6)
    assert r2.steps <= steps + 1e-6


# ----------------------------------------------------------------- Storm

BUS_PUDDLE = (Path(__file__).resolve().parent.parent / "models" / "bus_risk.toml").read_text()

def _drn(result, path):
    """The merged model as DRN: labels target (task accepted) and hazard (the first
    constraint's formula accepted), state-action reward steps (undecided states)."""
    m = result.merged
    mdp = m.mdp
    lines = ["@type: MDP", "@parameters", "", "@reward_models", "steps", "@nr_states",
             str(mdp.n_states), "@nr_choices", str(mdp.n_choices), "@model"]
    for s in range(mdp.n_states):
        labels = []
        if s == mdp.initial:
            labels.append("init")
        if m.verdicts[s, 0] == ACCEPTED:
            labels.append("target")
        if m.verdicts[s, 1] == ACCEPTED:
            labels.append("hazard")
        lines.append(f"state {s} [0] {' '.join(labels)}".rstrip())
        for k, c in enumerate(range(mdp.row_groups[s], mdp.row_groups[s + 1])):
            reward = 1 if m.undecided[s] else 0
            lines.append(f"\taction {k} [{reward}]")
            row = mdp.matrix[[c]].tocoo()
            for j, p in zip(row.col, row.data, strict=True):
                lines.append(f"\t\t{j} : {float(p)!r}")
    path.write_text("\n".join(lines) + "\n")


def _storm(path, query):
    stormpy = pytest.importorskip("stormpy")
    import stormpy.environments as env_mod

    model = stormpy.build_model_from_drn(str(path))
    env = stormpy.Environment()
    multi = env.modelchecker().multi()
    multi.precision = stormpy.Rational("1/1000000000")
    multi.precision_type = env_mod.MultiObjectivePrecisionType.ABSOLUTE
    prop = stormpy.parse_properties(query)[0]
    res = stormpy.model_checking(model, prop, environment=env)
    return res.get_value(model.initial_states[0])


@pytest.mark.parametrize("risk", [0.02, 0.05])
def test_matches_storm_multi_objective(tmp_path, risk):
    m = loads_model(BUS_PUDDLE)
    r = synthesize_constrained(m, [f"P(F puddle) <= {risk}"])
    assert r.status == "optimal" and r.certified
    _drn(r, tmp_path / "m.drn")
    want = _storm(tmp_path / "m.drn", f'multi(Pmax=? [F "target"], P<={risk} [F "hazard"])')
    assert r.lower == pytest.approx(want, abs=1e-6)
    # with an expected-steps bound (Storm: total reward of the undecided states)
    steps = round(r.steps - 0.2, 3)
    r2 = synthesize_constrained(m, [f"P(F puddle) <= {risk}", f"E(steps) <= {steps}"])
    want2 = _storm(tmp_path / "m.drn",
                   f'multi(Pmax=? [F "target"], P<={risk} [F "hazard"], R{{"steps"}}<={steps} [C])')
    assert r2.lower == pytest.approx(want2, abs=1e-6)
    assert r2.lower < r.lower - 1e-4  # the steps bound binds


# ----------------------------------------------------------------- Monte-Carlo

def test_simulated_frequencies_fall_in_their_intervals():
    m = loads_model(BUS_PUDDLE)
    r = synthesize_constrained(m, ["P(F puddle) <= 0.05", "E(steps) <= 3.9"], seed=7)
    assert r.status == "optimal" and r.certified
    stats = run_constrained(r, runs=2000, seed=11)
    # a run still open after max_steps (after the task, a randomised walk that has not
    # yet drawn its stay) could still go either way: it widens the interval
    n = stats.runs
    assert stats.unsettled <= 0.01 * n
    for i, want in ((0, r.lower), (1, r.constraints[0].value)):
        freq = stats.accepted[i] / n
        half = 4.0 * math.sqrt(want * (1 - want) / n) + stats.unsettled / n  # 4 sigma
        assert abs(freq - want) <= half, (i, freq, want)
    sd = stats.steps.std(ddof=1)
    assert abs(stats.steps.mean() - r.steps) <= 4.0 * sd / math.sqrt(n)


# ----------------------------------------------------------------- entry points

def test_model_file_constraints_and_costs():
    text = BUS_PUDDLE.replace('spec = ', 'constraints = ["P(F puddle) <= 0.05"]\nspec = ') + \
        "\n[costs]\nN = 2.0\n"
    m = loads_model(text)
    assert m.constraints == ("P(F puddle) <= 0.05",) and m.costs == {"N": 2.0}
    r = synthesize_constrained(m)
    assert r.constraints[0].constraint.bound == 0.05
    with pytest.raises(ModelError, match=r"constraints\[0\]: 'P\(F puddle\) <= 2'"):
        loads_model(text.replace("<= 0.05", "<= 2"))
    with pytest.raises(ModelError, match="costs.N: must be a finite number > 0"):
        loads_model(text.replace("N = 2.0", "N = -1"))


@pytest.mark.parametrize("text, message", [
    ("P(F hazard) < 0.1", "expected 'P(FORMULA) <= x'"),
    ("E(time) <= 3", "unknown expectation E(time)"),
    ("E(steps) >= 3", "upper bound"),
    ("P(F (hazard) <= 0.1", "1:"),
    ("P(G hazard) <= 0.1", "co-safe"),
])
def test_bad_constraints_say_what_and_where(text, message):
    with pytest.raises(ConstraintError, match=re_escape(message)):
        parse_constraint(text)


def re_escape(text):
    import re

    return re.escape(text)


def test_cli_solve_with_constraint_and_infeasible_exit(tmp_path, capsys):
    from mitld_lp.cli import main

    path = tmp_path / "m.toml"
    path.write_text(BUS_PUDDLE)
    assert main(["solve", str(path), "--constraint", "P(F puddle) <= 0.05", "-q"]) == 0
    out = capsys.readouterr().out
    assert "P(F puddle) <= 0.05" in out and "certified:    yes" in out
    assert main(["solve", str(path), "--constraint", "E(steps) <= 0.5", "-q"]) == 3
    assert "tightest feasible bound" in capsys.readouterr().out
    assert main(["solve", str(path), "--constraint", "P(F nowhere) <= 0.5", "-q"]) == 2
    assert "nowhere" in capsys.readouterr().err


def test_cli_pareto_writes_certified_points_and_refuses_to_overwrite(tmp_path, capsys):
    from mitld_lp.cli import main

    path = tmp_path / "m.toml"
    path.write_text(BUS_PUDDLE)
    csv_file, png = tmp_path / "c.csv", tmp_path / "c.png"
    args = ["pareto", str(path), "--against", "P(F puddle)", "--points", "3",
            "--csv", str(csv_file), "--plot", str(png), "-q"]
    assert main(args) == 0
    lines = csv_file.read_text().splitlines()
    assert lines[0].startswith("bound,probability_lower") and len(lines) == 4
    lows = [float(line.split(",")[1]) for line in lines[1:]]
    assert lows == sorted(lows) and all(line.endswith(",True") for line in lines[1:])
    # the least risk is 0, where the best success is 0.1856621 (Storm, experiments)
    assert float(lines[1].split(",")[0]) == pytest.approx(0.0, abs=1e-7)
    assert lows[0] == pytest.approx(0.1856621, abs=1e-6)
    assert png.read_bytes()[:4] == b"\x89PNG"
    capsys.readouterr()
    assert main(args) == 2
    assert "exists" in capsys.readouterr().err


def test_pareto_against_a_probability_whose_range_reaches_one():
    """``F (goal | !goal)`` holds on every run, so the curve's range is [1, 1]; its bounds
    (the range's points plus the curve's slack) are held at 1 and each point is the
    unconstrained optimum, 0.9 by hand (the risky route).  The slack made the bound
    1.000000001 and the curve stopped with 'a probability bound must be in [0, 1]'."""
    from mitld_lp import pareto

    points = pareto(Model.from_game(HAND, "F goal"), "P(F (goal | !goal))", 3)
    assert [p.bound for p in points] == [1.0, 1.0, 1.0]
    for p in points:
        assert p.status == "optimal" and p.certified
        assert p.lower == pytest.approx(0.9, abs=1e-7) and p.achieved == pytest.approx(1.0)


def test_cli_simulate_runs_a_model_file_with_constraints(tmp_path, capsys):
    """simulate refused a model file with constraints; it now runs the constrained
    problem's randomised controller, and its bracket is the constrained one (below the
    unconstrained 0.9244)."""
    import json

    from mitld_lp.cli import main

    path = tmp_path / "m.toml"
    path.write_text(BUS_PUDDLE.replace('spec = ', 'constraints = ["P(F puddle) <= 0.05"]\nspec = '))
    assert main(["simulate", str(path), "-n", "200", "-q", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["certified_bracket"][1] < 0.9


def test_constraints_on_a_task_with_a_safety_part_are_kept_not_misread() -> None:
    """The joint automaton reads acceptance by reaching: a task with a safety part
    (G !h | F A) would be counted as failing where it is kept.  Its end components are
    now kept: on a 3x1 line (h in the middle, A at the end) the robot satisfies the task
    either by staying clear of h (bumping the west wall) or by walking through h to A;
    by hand the optimum is 1 whatever the constraint, P(F h) = 0 when it must stay clear
    and P(F A) >= 0.5 when it must walk."""
    from mitld_lp import GridWorld, Model
    from mitld_lp.synthesis import synthesize_constrained

    world = GridWorld.make(3, 1, start=(0, 0), slip=0.0, regions={"A": [(2, 0)], "h": [(1, 0)]})
    model = Model.from_game(world, "G !h | F A")
    r = synthesize_constrained(model, ["P(F h) <= 0"])
    assert r.certified and r.lower == pytest.approx(1.0, abs=1e-7)
    assert r.constraints[0].value == pytest.approx(0.0, abs=1e-7)
    r = synthesize_constrained(model, ["P(F A) >= 0.5"])
    assert r.certified and r.lower == pytest.approx(1.0, abs=1e-7)
    assert r.constraints[0].value >= 0.5 - 1e-7
