"""The step-bounded route (mitld_lp.routes.horizon, mitld_lp.solvers.horizon):
``F[0,k] phi`` / ``psi U[0,k] phi`` on an explored world by backward induction.

Expected values are independent of the code under test: backward induction in
``fractions.Fraction`` written here (over every state, no pruning, from the decimals
of the world), Storm's exact engine on the same PRISM program, the plain route's
product for the same problem, and QVBS's published exact fraction.  Every bracket is
compared as ``Fraction(lower) <= exact <= Fraction(upper)``, no tolerance.
"""

from __future__ import annotations

import json
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from mitld_lp import load_model, synthesize
from mitld_lp.problem import ProblemError
from mitld_lp.solvers.horizon import horizon_reach
from mitld_lp.synthesis import pose

QVBS = Path("/work/shared/qvbs/mdp/resource-gathering")

# A walk to x=5 (goal): a steps +1 with 0.3, else back one; b jumps +2 with 0.5, stays
# with 0.25, falls to 0 with 0.25.  x=2 is "bad" (for the until's left side).
WALK = """mdp
module w
  x : [0..5] init 0;
  [a] x<5 -> 0.3 : (x'=min(x+1,5)) + 0.7 : (x'=max(x-1,0));
  [b] x<5 -> 0.5 : (x'=min(x+2,5)) + 0.25 : (x'=x) + 0.25 : (x'=0);
  [stay] x=5 -> true;
endmodule
label "goal" = x=5;
label "bad" = x=2;
"""
WALK_MOVES = {  # the same world, written out: state -> [[(probability, successor)]]
    x: [[(Fraction(3, 10), min(x + 1, 5)), (Fraction(7, 10), max(x - 1, 0))],
        [(Fraction(1, 2), min(x + 2, 5)), (Fraction(1, 4), x), (Fraction(1, 4), 0)]]
    for x in range(5)}
WALK_MOVES[5] = [[(Fraction(1), 5)]]


def induction(moves: dict, goal: set, allowed: set, steps: int, sense: str) -> dict:
    """Backward induction in exact arithmetic over every state."""
    v = {s: Fraction(int(s in goal)) for s in moves}
    opt = max if sense == "max" else min
    for _ in range(steps):
        v = {s: Fraction(1) if s in goal else Fraction(0) if s not in allowed else
             opt(sum((p * v[t] for p, t in row), Fraction(0)) for row in rows)
             for s, rows in moves.items()}
    return v


def arrays(moves: dict) -> tuple[np.ndarray, ...]:
    choices, branches, targets, probs = [0], [0], [], []
    for s in range(len(moves)):
        for row in moves[s]:
            targets += [t for _, t in row]
            probs += [float(p) for p, _ in row]
            branches.append(len(targets))
        choices.append(len(branches) - 1)
    return tuple(np.array(a) for a in (choices, branches, targets, probs))


def random_world(seed: int, n: int = 25) -> dict:
    rng = np.random.default_rng(seed)
    moves = {}
    for s in range(n):
        rows = []
        for _ in range(int(rng.integers(1, 4))):
            succ = rng.choice(n, int(rng.integers(1, 4)), replace=False)
            weights = [int(w) for w in rng.integers(1, 9, succ.size)]
            rows.append([(Fraction(w, sum(weights)), int(t)) for w, t in zip(weights, succ,
                                                                             strict=True)])
        moves[s] = rows
    return moves


def policy_value(moves: dict, goal: set, allowed: set, sol, steps: int, start: int) -> Fraction:
    """The exact value at ``start`` of the solution's step-dependent policy."""
    v = {s: Fraction(int(s in goal)) for s in moves}
    for left in range(1, steps + 1):
        nv = {}
        for s, rows in moves.items():
            if s in goal or s not in allowed:
                nv[s] = v[s]
                continue
            c = sol.choice(s, left)
            nv[s] = sum((p * v[t] for p, t in rows[c]), Fraction(0))
        v = nv
    return v[start]


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
@pytest.mark.parametrize("sense", ["max", "min"])
def test_bracket_holds_the_exact_induction_on_random_worlds(seed, sense):
    moves = random_world(seed)
    rng = np.random.default_rng(100 + seed)
    goal = {int(s) for s in rng.choice(25, 3, replace=False)}
    allowed = set(range(25)) - {int(s) for s in rng.choice(25, 4, replace=False)}
    g = np.array([s in goal for s in range(25)])
    a = np.array([s in allowed for s in range(25)])
    for steps in (0, 1, 3, 17):
        exact = induction(moves, goal, allowed, steps, sense)
        for start in (0, 7, 19):
            sol = horizon_reach(*arrays(moves), g, a, steps, sense, initial=start)
            lo, hi = Fraction(float(sol.lo[start])), Fraction(float(sol.hi[start]))
            assert lo <= exact[start] <= hi
            assert hi - lo <= Fraction(1, 10**10)
            # the policy guarantees the near end: at least lo for a maximum, at most hi
            # for a minimum
            kept = policy_value(moves, goal, allowed, sol, steps, start)
            assert (kept >= lo) if sense == "max" else (kept <= hi)


def test_policy_beats_a_fixed_choice_where_the_optimum_is_step_dependent():
    # x=4 with one step left: a reaches 5 with 0.3, b with 0.5; the induction's policy
    # must pick b there (local index 1), and its value is the exact optimum's bracket
    g = np.array([s == 5 for s in range(6)])
    sol = horizon_reach(*arrays(WALK_MOVES), g, np.ones(6, bool), 6, "max")
    assert sol.choice(4, 1) == 1
    exact = induction(WALK_MOVES, {5}, set(range(6)), 6, "max")[0]
    assert Fraction(float(sol.lo[0])) <= exact <= Fraction(float(sol.hi[0]))


def test_work_budget_refused_before_the_work():
    from mitld_lp.solvers.horizon import HorizonTooLarge

    g = np.array([s == 5 for s in range(6)])
    with pytest.raises(HorizonTooLarge, match="MAX_WORK"):
        horizon_reach(*arrays(WALK_MOVES), g, np.ones(6, bool), 10**6, "max", max_work=1000)


def walk_prism_model(tmp_path: Path, spec: str, objective: str = "max") -> Path:
    (tmp_path / "w.prism").write_text(WALK)
    path = tmp_path / f"w_{objective}.toml"
    path.write_text(f'name = "w"\nspec = "{spec}"\nobjective = "{objective}"\n\n'
                    '[prism]\nfile = "w.prism"\n')
    return path


@pytest.mark.parametrize(("spec", "objective", "storm"), [
    ("F[0,12] goal", "max", 'Pmax=? [ F<=12 "goal" ]'),
    ("F[0,12] goal", "min", 'Pmin=? [ F<=12 "goal" ]'),
    ("!bad U[0,9] goal", "max", 'Pmax=? [ !"bad" U<=9 "goal" ]'),
    ("!bad U[0,9] goal", "min", 'Pmin=? [ !"bad" U<=9 "goal" ]'),
])
def test_route_answers_storms_exact_value_and_the_plain_routes(tmp_path, monkeypatch, spec,
                                                                objective, storm):
    pytest.importorskip("stormpy")
    from storm_exact import storm_rational

    path = walk_prism_model(tmp_path, spec, objective)
    plain = synthesize(load_model(path))  # the bound 6 x 13 is below CLAIM_FROM
    assert plain.route == "plain"
    monkeypatch.setattr("mitld_lp.routes.horizon.CLAIM_FROM", 1)
    r = synthesize(load_model(path))
    assert r.route == "horizon" and r.certified
    exact = storm_rational(tmp_path / "w.prism", storm)
    assert Fraction(r.lower) <= exact <= Fraction(r.upper)
    assert Fraction(plain.lower) <= exact <= Fraction(plain.upper)
    assert r.summary()["route"] == "horizon"


def test_policy_table_controller_and_their_refusal_past_the_budget(tmp_path, monkeypatch):
    pytest.importorskip("stormpy")
    monkeypatch.setattr("mitld_lp.routes.horizon.CLAIM_FROM", 1)
    path = walk_prism_model(tmp_path, "F[0,3] goal")
    r = synthesize(load_model(path))
    rows = r.policy_table()
    # x=4 with 1 step left: b (0.5) beats a (0.3); x=3 with 1 step left: b too
    at = {(row["game_state"]["x"], int(row["automaton_state"].split()[0])): row["action"]
          for row in rows}
    assert at[(4, 1)] == "b" and at[(3, 1)] == "b"
    assert {left for _, left in at} <= {1, 2, 3}
    c = r.controller
    c.reset()
    first = c.act(r.model.game.initial)
    assert first == at[(0, 3)]
    monkeypatch.setattr("mitld_lp.solvers.horizon.POLICY_MAX_BYTES", 0)
    refused = synthesize(load_model(path))
    assert Fraction(refused.lower) == Fraction(r.lower)  # the same bracket
    for verb in (refused.policy_table, refused.controller.reset):
        with pytest.raises(ProblemError, match="POLICY_MAX_BYTES") as err:
            verb()
        assert "bytes" in str(err.value)


def test_not_claimed_with_exact_constraints_or_an_event(tmp_path, monkeypatch):
    pytest.importorskip("stormpy")
    monkeypatch.setattr("mitld_lp.routes.horizon.CLAIM_FROM", 1)
    path = walk_prism_model(tmp_path, "F[0,12] goal")
    model = load_model(path)
    assert pose(model).route.name == "horizon"
    assert pose(model, ["P(F bad) <= 0.5"]).route.name != "horizon"
    event = walk_prism_model(tmp_path, "D[geometric(0.5)] e & F[0,12] goal")
    assert pose(load_model(event)).route.name != "horizon"
    unbounded = walk_prism_model(tmp_path, "F goal")
    assert pose(load_model(unbounded)).route.name == "plain"


def test_a_world_explored_on_the_fly_keeps_the_product(tmp_path):
    # a PRISM grid explored up to the horizon (explore = "auto"), 401 x 401 states with
    # F[0,10]: the bound 1.77M is past CLAIM_FROM, but the world is not a table
    pytest.importorskip("stormpy")
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments"))
    import bench_explore

    _, model = bench_explore.write_grid(tmp_path, 401)
    r = synthesize(load_model(model))
    assert r.route == "plain"
    assert r.mdp.n_states < 1000  # the few states within the horizon, not the world


@pytest.mark.skipif(not (QVBS / "index.json").is_file(), reason="needs the QVBS checkout")
def test_resource_gathering_200_15_15_holds_qvbs_exact_value(tmp_path):
    pytest.importorskip("stormpy")
    index = json.loads((QVBS / "index.json").read_text())
    ref = next(r["value"] for v in index["files"][0]["open-parameter-values"]
               if [p["value"] for p in v["values"]] == [200, 15, 15]
               for r in v["results"] if r["property"] == "prgoldgem")
    exact = Fraction(int(ref["num"]), int(ref["den"]))
    path = tmp_path / "rg.toml"
    path.write_text('name = "rg"\nspec = "F[0,200] success"\n\n[prism]\nfile = '
                    f'"{QVBS / "resource-gathering.pm"}"\nconstants = {{ B = 200, '
                    'GOLD_TO_COLLECT = 15, GEM_TO_COLLECT = 15 }\n')
    r = synthesize(load_model(path))
    assert r.route == "horizon" and r.certified
    assert Fraction(r.lower) <= exact <= Fraction(r.upper)


def test_a_memory_budget_drops_the_policy_by_name_not_the_answer(tmp_path, monkeypatch):
    pytest.importorskip("stormpy")
    monkeypatch.setattr("mitld_lp.routes.horizon.CLAIM_FROM", 1)
    path = walk_prism_model(tmp_path, "F[0,12] goal")
    whole = synthesize(load_model(path))
    tight = synthesize(load_model(path), max_memory=2)  # one byte for the policy
    assert (tight.lower, tight.upper) == (whole.lower, whole.upper)
    with pytest.raises(ProblemError, match="max_memory"):
        tight.policy_table()


def test_work_past_the_budget_is_refused_at_pose(tmp_path, monkeypatch):
    pytest.importorskip("stormpy")
    monkeypatch.setattr("mitld_lp.routes.horizon.CLAIM_FROM", 1)
    monkeypatch.setattr("mitld_lp.solvers.horizon.MAX_WORK", 10)
    with pytest.raises(ProblemError, match="MAX_WORK"):
        pose(load_model(walk_prism_model(tmp_path, "F[0,12] goal")))


def test_a_policy_table_past_max_states_rows_is_refused_by_name(tmp_path, monkeypatch):
    pytest.importorskip("stormpy")
    monkeypatch.setattr("mitld_lp.routes.horizon.CLAIM_FROM", 1)
    path = walk_prism_model(tmp_path, "F[0,12] goal")
    r = synthesize(load_model(path), max_states=3)
    with pytest.raises(ProblemError, match="max_states"):
        r.policy_table()
    r.controller.reset()
    assert r.controller.act(r.model.game.initial) in ("a", "b")  # the policy is kept
