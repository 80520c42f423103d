"""The decision tree of a controller that acts on sensor reports (``export --tree``):
a finite-memory controller whose memory is what the robot has observed.  Checked here:
on every (world state, memory) pair the controller's table lists, the tree takes the
controller's decision; the written ``.py`` file, run on its own (its ``act`` and
``update``), does the same and moves the memory as the table does; and the controlled
chain of the tree run as a controller, exported and read by Storm exactly, gives the
original controller's value, at least ``lower``, for a deterministic (sensed) and a
randomised (sensed-constrained) controller."""

from __future__ import annotations

import json
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from test_sensed_constrained import STATION
from test_sensing import SPEC

from mitld_lp import Model, synthesize
from mitld_lp.cli import main
from mitld_lp.files import drn
from mitld_lp.running.chain import chain_drn, chain_of
from mitld_lp.running.tree import tree_controller, tree_of, write_tree
from mitld_lp.worlds.names import state_values

stormpy = pytest.importorskip("stormpy")

CASES = {"sensed": {}, "sensed-constrained": {"constraints": ["P(F wet) <= 0.3"]}}


def _listed(plan, initial):  # noqa: ANN001, ANN202 - a sensed plan, the world's start
    """Every (world state, memory) pair the plan's table names: its initial memory at
    the world's start, and each move's next memory at the move's observed world state
    (a plain scan of the table, no search)."""
    pairs = {(initial, plan.initial)}
    for table in plan.moves.values():
        for obs, nxt in table.items():
            if not isinstance(nxt, str) and nxt >= 0:
                pairs.add((obs[0], nxt))
    return sorted(pairs, key=repr)


def _same(a, b) -> bool:  # noqa: ANN001 - two Decisions
    wa = None if a.weights is None else tuple(np.asarray(a.weights).tolist())
    wb = None if b.weights is None else tuple(np.asarray(b.weights).tolist())
    return (a.actions, wa, a.stay, a.inside, a.lost) == (b.actions, wb, b.stay, b.inside,
                                                         b.lost)


def _storm(chain, path: Path) -> Fraction:  # noqa: ANN001 - a Chain
    drn.write(chain_drn(chain), path)
    model = stormpy.build_model_from_drn[stormpy.Rational](str(path))
    result = stormpy.model_checking(model, stormpy.parse_properties('P=? [F "accept"]')[0])
    return Fraction(str(result.get_value(model.initial_states[0])))


@pytest.mark.parametrize("case", sorted(CASES))
def test_the_tree_is_the_controller_and_storm_gives_lower(tmp_path: Path, case: str) -> None:
    model = Model.from_game(STATION, SPEC, sensors={"b": {"detect": 0.5}})
    r = synthesize(model, **CASES[case])
    assert r.route == case and r.certified
    tree = tree_of(r)
    assert tree.memory is not None and tree.randomised is (case != "sensed")
    plan = r.controller.plan
    by_tree = tree_controller(r, tree).plan
    pairs = _listed(plan, STATION.initial)
    assert len(pairs) == tree.samples > 5
    for g, m in pairs:
        own = plan.decision(g, m)
        if not own.actions and own.weights is None and not own.lost:
            own = type(own)((plan.fallback(g),))  # "any action": the world's first
        assert _same(own, by_tree.decision(g, m)), (g, m)
    # the controlled chain of the tree run as a controller: Storm, exactly
    tree_value = _storm(chain_of(r, tree_controller(r, tree)), tmp_path / "tree.drn")
    own_value = _storm(chain_of(r), tmp_path / "own.drn")
    assert tree_value == own_value
    assert Fraction(r.lower) - Fraction(1, 10**9) <= tree_value


def test_the_written_python_file_is_the_controller(tmp_path: Path) -> None:
    model = Model.from_game(STATION, SPEC, sensors={"b": {"detect": 0.5}})
    r = synthesize(model)
    tree = tree_of(r)
    path = write_tree(r, tmp_path / "camera_tree.py", tree=tree)
    space: dict = {}
    exec(compile(path.read_text(), str(path), "exec"), space)  # noqa: S102 - our file
    plan = r.controller.plan
    game = r.model.game
    assert space["INITIAL"] == plan.initial
    for g, m in _listed(plan, STATION.initial):
        d = plan.decision(g, m)
        want = d.actions[0] if d.actions else plan.fallback(g)
        assert space["act"](*state_values(game, g), m) == want
    for (m, action), table in plan.moves.items():
        for (g, events, reports), nxt in table.items():
            got = space["update"](m, action, *state_values(game, g), events, reports)
            assert got == nxt
    assert space["update"](plan.initial, "no such action", *state_values(
        game, STATION.initial), (), ()) == space["BEYOND"]


def test_export_tree_of_a_sensed_model_file(tmp_path: Path, capsys) -> None:
    models = Path(__file__).resolve().parents[1] / "models"
    path = tmp_path / "camera.toml"
    path.write_text((models / "bus_grid.toml").read_text()
                    + "\n[sensors]\nb1 = { detect = 0.5 }\n")
    out = tmp_path / "camera.json"
    assert main(["export", str(path), "--tree", str(out), "--json"]) == 0
    said = json.loads(capsys.readouterr().out)
    written = json.loads(out.read_text())
    assert said["files"]["tree"] == str(out)
    assert written["features"][-1] == "memory" and written["memory"]["moves"]
    assert written["states"] == said["tree_states"] > 0


def test_a_band_seen_through_a_camera_keeps_its_worst_case_in_the_tree() -> None:
    """A sensed answer with a band: the tree controller's interval chain (nature picking
    each step's hazard in the band) has the original controller's worst case, ``lower``."""
    from mitld_lp import ExplicitGame
    from mitld_lp.distributions import from_table
    from mitld_lp.running.sensed_band_chain import sensed_band_chain_of, worst_case
    from mitld_lp.sensing import Sensor

    game = ExplicitGame(initial="mid", labels={"sa": {"A"}}, transitions={
        "mid": {"go": {"sa": 0.75, "mid": 0.25}, "wait": {"mid": 1.0}},
        "sa": {"back": {"trap": 1.0}}, "trap": {"back": {"mid": 1.0}}})
    r = synthesize(Model.from_game(
        game, "D[mu] b & F[0,3] (b & F[0,1] A)",
        distributions={"mu": from_table({"geometric": [0.1, 0.9]}, "mu")},
        sensors={"b": Sensor(0.5)}))
    assert r.route == "sensed" and r.bands
    tree = tree_of(r)
    plan, by_tree = r.controller.plan, tree_controller(r, tree).plan
    for g, m in _listed(plan, game.initial):
        own = plan.decision(g, m)
        if not own.actions:
            own = type(own)((plan.fallback(g),))
        assert _same(own, by_tree.decision(g, m)), (g, m)
    worst = worst_case(sensed_band_chain_of(r, tree_controller(r, tree)))
    assert worst.lower == worst_case(sensed_band_chain_of(r)).lower == r.lower
