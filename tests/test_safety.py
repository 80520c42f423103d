"""Safety and obligation tasks: values against Storm's LTL model checker on a PRISM grid
written here, against a brute force written differently (greatest fixpoint of the
almost-surely-safe cells, max reachability of them by an LP through scipy, backward
induction over the deadline), against closed forms, and the controller that keeps the
safety part forever."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy.optimize import linprog

from mitld_lp import GridWorld, Model, synthesize
from mitld_lp.solvers.accepting import escapes

# --------------------------------------------------------------------------- closed forms


def _cross(slip: float) -> GridWorld:
    """A 3x3 grid whose corners are walls: the goal is the centre (1, 1) between two
    hazards (1, 0) and (1, 2); the robot starts at (0, 1).  At the centre every move
    slips into a hazard with probability at least 2*slip; at (0, 1) and (2, 1) a move
    into the wall stays put with probability 1 (the corners bounce the slips)."""
    return GridWorld.make(3, 3, start=(0, 1), slip=slip,
                          obstacles=[(0, 0), (0, 2), (2, 0), (2, 2)],
                          regions={"goal": [(1, 1)], "hazard": [(1, 0), (1, 2)]})


@pytest.mark.parametrize("slip", [0.1, 0.25])
def test_hazard_next_to_the_goal_closed_form(slip: float) -> None:
    """Reaching the centre is safe (E: it gets there or bounces back); leaving it costs
    a slip into a hazard with probability 2*slip, and the robot cannot stay there.  So
    P(G !hazard & F goal) = 1 - 2*slip; with the deadline k the goal is reached in
    time with probability 1 - (2*slip)^k, hence (1 - (2 slip)^k)(1 - 2 slip)."""
    world = _cross(slip)
    r = synthesize(Model.from_game(world, "G !hazard & F goal"))
    assert r.certified
    assert r.lower == pytest.approx(1 - 2 * slip, abs=1e-9)
    assert r.upper == pytest.approx(1 - 2 * slip, abs=1e-9)
    k = 3
    r = synthesize(Model.from_game(world, f"G !hazard & F[0,{k}] goal"))
    assert r.certified
    assert r.lower == pytest.approx((1 - (2 * slip) ** k) * (1 - 2 * slip), abs=1e-9)
    assert r.upper == pytest.approx(r.lower, abs=1e-9)
    # staying safe alone: hold still against a wall at (0, 1)
    assert synthesize(Model.from_game(world, "G !hazard")).lower == pytest.approx(1.0, abs=1e-12)


def test_staying_safe_forever_impossible_gives_zero_certified() -> None:
    """A corridor between two hazard rows: every move of every cell slips (or goes) into
    a hazard with probability >= 0.2, so P(never) = lim 0.8^n = 0 exactly."""
    world = GridWorld.make(4, 3, start=(0, 1), slip=0.1,
                           regions={"hazard": [(x, y) for x in range(4) for y in (0, 2)],
                                    "goal": [(3, 1)]})
    for spec in ("G !hazard", "G !hazard & F goal", "!hazard W goal & G !hazard"):
        r = synthesize(Model.from_game(world, spec))
        assert r.certified, spec
        assert r.lower == 0.0 and r.upper == 0.0, spec
        assert not r.acceptance.goal.any()
    # ... while the co-safe part alone is not hopeless
    assert synthesize(Model.from_game(world, "!hazard U goal")).lower > 0.1


def test_safety_is_for_ever_not_up_to_a_horizon() -> None:
    """With slip 0.01 the corridor between hazard rows loses only 2% a step: a bounded
    horizon of 100 steps would say 0.98^100 = 0.13; kept for ever it is 0, certified.
    A wall that holds the robot still makes it 1."""
    both = GridWorld.make(6, 3, start=(0, 1), slip=0.01,
                          regions={"hazard": [(x, y) for x in range(6) for y in (0, 2)]})
    r = synthesize(Model.from_game(both, "G !hazard"))
    assert r.certified and r.lower == 0.0 and r.upper == 0.0
    # top row hazardous only: S at the bottom wall stays or slips along the row
    row = GridWorld.make(6, 2, start=(0, 0), slip=0.1,
                         regions={"hazard": [(x, 1) for x in range(6)]})
    r = synthesize(Model.from_game(row, "G !hazard"))
    assert r.certified and r.lower == pytest.approx(1.0, abs=1e-12)


# --------------------------------------------------------------------------- brute force


def _brute(world: GridWorld, hazard: set, goal: set, k: int | None) -> float:
    """P_max(G !hazard [& F[0,k] goal]) from the start, written without the product.

    Safe cells: the greatest fixpoint S = {c not hazard | some move keeps all its
    outcomes in S}.  P_max(G !hazard) from c is P_max(reach S while avoiding hazard),
    an LP (min sum v, v >= P_a v, v = 1 on S, v = 0 where S is unreachable).  With a
    deadline: backward induction over the steps, the goal cell scoring its safe value.
    """
    cells = list(world.cells)
    idx = {c: i for i, c in enumerate(cells)}
    moves = {c: [world.successors(c, a) for a in world.actions(c)] for c in cells}
    safe = {c for c in cells if c not in hazard}
    while True:
        nxt = {c for c in safe if any(all(d in safe for d, _ in m) for m in moves[c])}
        if nxt == safe:
            break
        safe = nxt
    # cells from which S is reachable at all (avoiding the hazard)
    can = set(safe)
    while True:
        more = {c for c in cells if c not in hazard and c not in can
                and any(any(d in can for d, _ in m) for m in moves[c])}
        if not more:
            break
        can |= more
    n = len(cells)
    rows, rhs = [], []
    for c in cells:
        if c in safe or c not in can:
            continue
        for m in moves[c]:
            row = np.zeros(n)
            row[idx[c]] -= 1
            for d, p in m:
                row[idx[d]] += p
            rows.append(row)
            rhs.append(0.0)
    bounds = [(1.0, 1.0) if c in safe else (0.0, 0.0) if c not in can else (0.0, 1.0)
              for c in cells]
    res = linprog(np.ones(n), A_ub=np.array(rows) if rows else None,
                  b_ub=np.array(rhs) if rows else None, bounds=bounds, method="highs")
    assert res.status == 0
    v_safe = dict(zip(cells, res.x, strict=True))
    if k is None:
        return v_safe[world.initial]
    value = {c: 0.0 for c in cells}  # past the deadline without the goal: lost
    for _ in range(k + 1):
        value = {
            c: 0.0 if c in hazard else v_safe[c] if c in goal
            else max(sum(p * value[d] for d, p in m) for m in moves[c])
            for c in cells
        }
    return value[world.initial]


@pytest.mark.parametrize("seed", range(6))
def test_random_grids_against_the_brute_force(seed: int) -> None:
    rng = np.random.default_rng(seed)
    w, h = int(rng.integers(3, 6)), int(rng.integers(2, 5))
    every = list(itertools.product(range(w), range(h)))
    picks = rng.permutation(len(every))
    start = every[picks[0]]
    goal = {every[picks[1]]}
    hazard = {every[i] for i in picks[2 : 2 + int(rng.integers(1, 4))]}
    obstacles = [every[i] for i in picks[5 : 5 + int(rng.integers(0, 3))]]
    slip = float(rng.choice([0.0, 0.1, 0.2, 0.3]))
    world = GridWorld.make(w, h, start=start, slip=slip, obstacles=obstacles,
                           regions={"goal": sorted(goal), "hazard": sorted(hazard)})
    k = int(rng.integers(1, 7))
    for spec, deadline in (("G !hazard", None), (f"G !hazard & F[0,{k}] goal", k)):
        r = synthesize(Model.from_game(world, spec))
        want = _brute(world, hazard, goal, deadline)
        assert r.certified, (spec, [c.detail for c in r.failed_checks])
        assert r.lower == pytest.approx(want, abs=1e-7), (seed, spec)
        assert r.upper == pytest.approx(want, abs=1e-7), (seed, spec)


# --------------------------------------------------------------------------- the controller


def test_controller_never_leaves_the_accepting_components() -> None:
    """Certified means the policy's choices inside the accepting end components stay
    there: the check passes, and an independent look at the rows agrees."""
    r = synthesize(Model.from_game(_cross(0.1), "G !hazard & F goal"))
    names = [c.name for c in r.lower_model.checks]
    assert "policy stays in the accepting end components" in names
    goal = r.acceptance.goal
    assert goal.any()
    assert not escapes(r.mdp, r.lower_model.policy, goal).any()
    for s in np.flatnonzero(goal):
        c = int(r.lower_model.policy[s])
        if c >= 0:
            row = r.mdp.matrix[[c]].toarray().ravel()
            assert set(np.flatnonzero(row)) <= set(np.flatnonzero(goal))
    table = r.policy_table()
    marked = [row for row in table if row["accepting_component"]]
    assert marked
    # the centre is never inside: no move keeps the robot safe there for ever
    assert not any(row["game_state"] == (1, 1) for row in marked)
    assert any(row["game_state"] in {(0, 1), (2, 1)} for row in marked)


def test_simulation_sees_violations_and_agrees() -> None:
    from mitld_lp.running.simulate import simulate

    world = _cross(0.1)
    r = synthesize(Model.from_game(world, "G !hazard & F goal"))
    sim = simulate(r.model, r.controller, runs=2000, seed=3, max_steps=200)
    assert sim.horizon == 200
    assert sim.ci_low <= 0.8 <= sim.ci_high
    # the runs that failed did so by entering a hazard, none is left undecided
    assert sim.undecided == 0
    assert sim.kept == sim.successes  # no accepting automaton state: each success is kept


# --------------------------------------------------------------------------- Storm


def _prism_grid(w: int, h: int, slip: float, start, hazard, goal, k: int) -> str:
    """The grid as a PRISM MDP written from the rules (walls bounce, slips go to the two
    perpendicular neighbours), with a step counter ``t`` capped at ``k + 1`` for the
    deadline (label ``intime``: on the goal at a step <= k)."""
    main = 1 - 2 * slip

    def cond(cells) -> str:
        return "(" + " | ".join(f"(x={x} & y={y})" for x, y in cells) + ")"

    e, wst = f"(x'=min(x+1,{w - 1}))", "(x'=max(x-1,0))"
    n, s = f"(y'=min(y+1,{h - 1}))", "(y'=max(y-1,0))"
    t = f"(t'=min(t+1,{k + 1}))"
    moves = {"N": (n, e, wst), "S": (s, e, wst), "E": (e, n, s), "W": (wst, n, s)}
    lines = ["mdp", "module grid", f"  x : [0..{w - 1}] init {start[0]};",
             f"  y : [0..{h - 1}] init {start[1]};", f"  t : [0..{k + 1}] init 0;"]
    for a, (go, side1, side2) in moves.items():
        lines.append(f"  [{a}] true -> {main}:{go}&{t} + {slip}:{side1}&{t} + "
                     f"{slip}:{side2}&{t};")
    lines += ["endmodule", f'label "h" = {cond(hazard)};',
              f'label "intime" = {cond(goal)} & t<={k};']
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("slip", [0.1, 0.2])
def test_grid_against_storm_ltl(slip: float, tmp_path) -> None:
    """Storm checks the LTL formulas on its own encoding of the grid; ours equal its
    values to 1e-6."""
    stormpy = pytest.importorskip("stormpy")
    w, h, k = 4, 3, 6
    start, goal = (0, 0), [(3, 2)]
    hazard = [(1, 0), (0, 2), (2, 1)]  # G !h alone: 0.865 at slip 0.1
    path = tmp_path / "grid.prism"
    path.write_text(_prism_grid(w, h, slip, start, hazard, goal, k))
    program = stormpy.parse_prism_program(str(path))
    world = GridWorld.make(w, h, start=start, slip=slip,
                           regions={"goal": goal, "hazard": hazard})
    pairs = [
        ('Pmax=? [ G !"h" ]', "G !hazard"),
        ('Pmax=? [ (G !"h") & (F "intime") ]', f"G !hazard & F[0,{k}] goal"),
        ('Pmax=? [ (G !"h") | (F "intime") ]', f"G !hazard | F[0,{k}] goal"),
        ('Pmax=? [ (!"h") U "intime" ]', f"!hazard U[0,{k}] goal"),
    ]
    for storm_text, spec in pairs:
        prop = stormpy.parse_properties(storm_text, program)[0]
        model = stormpy.build_model(program, [prop])
        result = stormpy.model_checking(model, prop, only_initial_states=True)
        theirs = float(result.get_value_vector()[model.initial_states[0]])
        r = synthesize(Model.from_game(world, spec))
        assert r.certified, spec
        assert r.lower == pytest.approx(theirs, abs=1e-6), (spec, theirs)
        assert r.upper == pytest.approx(theirs, abs=1e-6), (spec, theirs)


_CROSS_FILE = """name = "cross"
spec = "G !hazard & F[0,3] goal"
[grid]
size = [3, 3]
start = [0, 1]
slip = 0.1
obstacles = [[0, 0], [0, 2], [2, 0], [2, 2]]
[regions]
goal = [[1, 1]]
hazard = [[1, 0], [1, 2]]
"""


def test_exported_drn_gives_storm_the_value(tmp_path) -> None:
    """``export --drn`` labels the accepting end components ``accept``: Storm's
    ``Pmax=? [F "accept"]`` on the file is the closed form (1 - 0.2^3) * 0.8."""
    stormpy = pytest.importorskip("stormpy")
    from mitld_lp.cli import main

    model = tmp_path / "cross.toml"
    model.write_text(_CROSS_FILE)
    drn = tmp_path / "cross.drn"
    assert main(["export", str(model), "--drn", str(drn), "-q"]) == 0
    parsed = stormpy.build_model_from_drn(str(drn))
    prop = stormpy.parse_properties('Pmax=? [F "accept"]')[0]
    result = stormpy.model_checking(parsed, prop, only_initial_states=True)
    theirs = float(result.get_value_vector()[parsed.initial_states[0]])
    assert theirs == pytest.approx((1 - 0.2**3) * 0.8, abs=1e-6)
