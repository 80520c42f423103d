"""The controller as a decision tree (issue 32, part 2): exact, small, in three formats.

Independent routes: Storm's ``P=? [F "accept"]`` on the tree controller's own chain
equals ``lower`` (zero value lost); at every state that chain reaches, the tree's action
satisfies the Bellman equation of the controller's values, recomputed here from the
product's matrix; with ``same_actions`` the tree's action is the controller's own at
every state the controller reaches, enumerated from the controller's chain; the
Python function written to a file, executed here, answers as the tree does."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from mitld_lp import Observation, synthesize
from mitld_lp.model import load_model
from mitld_lp.product import ProductState
from mitld_lp.running.chain import chain_of, write_chain
from mitld_lp.running.tree import tree_controller, tree_of, tree_value, write_tree
from mitld_lp.synthesis import synthesize_constrained

MODELS = Path(__file__).resolve().parent.parent / "models"


def storm_accept(path: Path) -> float:
    from test_chain import storm_accept as check

    return check(path)


@pytest.fixture(scope="module")
def results():
    return {name: synthesize(load_model(MODELS / f"{name}.toml"))
            for name in ("bus_grid", "patrol", "bus_puddle", "corridor")}


def _reached_actions(result, tree):
    """Per product state the tree controller's chain reaches and acts in: its action."""
    c = tree_controller(result, tree)
    chain = chain_of(result, c)
    out = {}
    for i in {int(i) for i in chain.origin if i >= 0}:
        rec = result.mdp.states[i]
        if isinstance(rec, ProductState) and -1 in c._plan.verdicts[rec.automaton]:
            d = c._plan.decide(rec.game, rec.automaton, rec.pending, rec.clock)
            out[i] = None if d.lost else d.actions[0]
    return out


@pytest.mark.parametrize("name", ["bus_grid", "patrol", "bus_puddle", "corridor"])
def test_the_tree_loses_no_value(results, name, tmp_path) -> None:
    r = results[name]
    tree = tree_of(r)
    # Storm, on the chain of the world under the tree's controller
    path = write_chain(r, tmp_path / "tree.drn", controller=tree_controller(r, tree))
    assert storm_accept(path) == pytest.approx(r.lower, abs=1e-9)
    assert tree_value(r, tree) == pytest.approx(r.lower, abs=1e-9)
    # the Bellman equation of the controller's values at every state the tree reaches
    mdp, v = r.mdp, r.lower_model.policy_values
    q = mdp.matrix @ v
    for i, action in _reached_actions(r, tree).items():
        rows = [c for c in mdp.choices(i) if mdp.action_name(c) == action]
        assert len(rows) == 1 and abs(q[rows[0]] - v[i]) <= 1e-12, (name, i, action)


def test_sizes_against_the_policy_table(results) -> None:
    sizes = {}
    for name in ("bus_grid", "patrol"):
        r = results[name]
        rows = len(r.policy_table())
        sizes[name] = (tree_of(r).size, tree_of(r, same_actions=True).size, rows)
    print("tree nodes (value-keeping, same actions) vs policy table rows:", sizes)
    assert sizes["patrol"][0] * 10 <= sizes["patrol"][2]
    assert sizes["bus_grid"][0] * 2 <= sizes["bus_grid"][2]
    for free, same, _ in sizes.values():
        assert free <= same


@pytest.mark.parametrize("name", ["bus_grid", "corridor"])
def test_same_actions_is_the_controller_everywhere_it_goes(results, name) -> None:
    r = results[name]
    tree = tree_of(r, same_actions=True)
    chain = chain_of(r)
    checked = 0
    c, mine = r.controller, tree_controller(r, tree)

    def answer(plan, rec):  # what act() does with the plan's decision
        d = plan.decide(rec.game, rec.automaton, rec.pending, rec.clock)
        return None if d.lost else d.actions[0] if d.actions else plan.fallback(rec.game)

    for i in {int(i) for i in chain.origin if i >= 0}:
        rec = r.mdp.states[i]
        if not isinstance(rec, ProductState):
            continue
        assert answer(mine._plan, rec) == answer(c._plan, rec), i
        checked += 1
    assert checked > 40


def test_the_three_formats(results, tmp_path) -> None:
    r = results["bus_grid"]
    tree = tree_of(r)
    data = json.loads(write_tree(r, tmp_path / "t.json", tree=tree).read_text())
    assert data["features"] == ["x", "y", "q", "pending_b1", "pending_b2", "clock"]
    assert len(data["nodes"]) == tree.size
    leaves = [n for n in data["nodes"] if "action" in n]
    assert {n["action"] for n in leaves} <= {"N", "E", "S", "W", None}
    dot = write_tree(r, tmp_path / "t.dot", tree=tree).read_text()
    assert dot.startswith("digraph") and dot.count("shape=box") == len(leaves)
    code = write_tree(r, tmp_path / "t.py", tree=tree).read_text()
    space: dict = {}
    exec(compile(code, "t.py", "exec"), space)
    act = space["act"]
    # the function answers as the tree at every state the tree's controller reaches
    for i in _reached_actions(r, tree):
        rec = r.mdp.states[i]
        x, y = rec.game
        got = act(x, y, rec.automaton, "b1" in rec.pending, "b2" in rec.pending, rec.clock)
        assert got == tree.decide((x, y, rec.automaton, "b1" in rec.pending,
                                   "b2" in rec.pending, rec.clock))
    with pytest.raises(ValueError):
        write_tree(r, tmp_path / "t.txt", tree=tree)
    with pytest.raises(FileExistsError):
        write_tree(r, tmp_path / "t.json", tree=tree)


def test_a_randomised_controllers_tree_keeps_its_distributions(tmp_path) -> None:
    m = load_model(MODELS / "bus_risk.toml")
    r = synthesize_constrained(m, ["P(F puddle) <= 0.05"])
    tree = tree_of(r)
    assert tree.randomised
    path = write_chain(r, tmp_path / "t.drn", controller=tree_controller(r, tree))
    assert storm_accept(path) == pytest.approx(r.lower, abs=1e-9)
    # the tree's controller draws as the controller does, seed for seed
    a, b = r.controller, tree_controller(r, tree)
    for seed in range(20):
        a.reset(seed=seed)
        b.reset(seed=seed)
        assert a.act(Observation((0, 0))) == b.act(Observation((0, 0)))
    assert np.isfinite(tree_value(r, tree))


@pytest.mark.skipif(__import__("importlib").util.find_spec("stormpy") is None,
                    reason="needs stormpy: pip install -e '.[prism]'")
def test_memory_features_do_not_clash_with_world_variables(tmp_path) -> None:
    # the world's variables take the names of the controller's memory (q, clock,
    # pending_b) and two names that are one Python name (lambda is a keyword)
    (tmp_path / "w.prism").write_text(
        "mdp\nmodule m\n  clock : [0..3] init 0;\n  q : [0..2] init 0;\n"
        "  pending_b : bool init false;\n  lambda : [0..1] init 0;\n  lambda_ : [0..1] init 1;\n"
        "  [go] q<2 -> 0.7 : (q'=q+1) + 0.3 : (lambda'=1-lambda);\n"
        "  [tick] clock<3 -> (clock'=clock+1) & (pending_b'=!pending_b) & (lambda_'=lambda);\n"
        'endmodule\nlabel "goal" = q=2;\n')
    (tmp_path / "w.toml").write_text(
        'name = "w"\nspec = "D[geometric(0.5)] b & F(b & F[0,3] goal)"\n'
        '[prism]\nfile = "w.prism"\n')
    r = synthesize(load_model(tmp_path / "w.toml"))
    world = r.model.game.variables
    assert sorted(world) == ["clock", "lambda", "lambda_", "pending_b", "q"]
    tree = tree_of(r, same_actions=True)
    data = json.loads(write_tree(r, tmp_path / "t.json", tree=tree).read_text())
    assert data["features"] == [*world, "q_", "pending_b_", "clock_"]
    code = write_tree(r, tmp_path / "t.py", tree=tree).read_text()
    space: dict = {}
    exec(compile(code, "t.py", "exec"), space)  # was: def act(clock, q, ..., q, ..., clock)
    act = space["act"]
    assert act.__code__.co_argcount == len(world) + 3
    # the function plays the controller's own action wherever the controller goes
    plan, checked = r.controller._plan, 0
    for i in {int(i) for i in chain_of(r).origin if i >= 0}:
        rec = r.mdp.states[i]
        if not isinstance(rec, ProductState) or -1 not in plan.verdicts[rec.automaton]:
            continue
        d = plan.decide(rec.game, rec.automaton, rec.pending, rec.clock)
        own = None if d.lost else d.actions[0] if d.actions else plan.fallback(rec.game)
        assert act(*rec.game, rec.automaton, "b" in rec.pending, rec.clock) == own
        checked += 1
    assert checked >= 10
