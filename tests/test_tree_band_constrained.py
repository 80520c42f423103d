"""The decision tree of a randomised controller synthesised with constraints and a law
known only within a band (``export --tree``): replayed on every state the controller
reaches, it takes the controller's own decision; the interval chain of the policy read
back from the tree's leaves (written here, state by state) is checked by Storm's robust
engine, which gives ``lower``."""

from __future__ import annotations

import json
from collections import deque
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from mitld_lp import load_model, synthesize
from mitld_lp.cli import main
from mitld_lp.controllers.format import UNDECIDED
from mitld_lp.files import drn
from mitld_lp.running.band_mixture_chain import mixture_chain_drn
from mitld_lp.running.tree import tree_controller, tree_of, tree_value

GRID = """name = "walk"
spec = "{spec}"
constraints = ["{constraint}"]
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

CASES = {
    "co-safe": ("D[mu] b & F(b & F[0,3] goal)", "P(F puddle) <= 0.3"),
    "obligation": ("G !puddle & D[mu] b & F(b & F[0,3] goal)", "E(steps) <= 8"),
}


def _reached(r) -> list[int]:  # noqa: ANN001 - a constrained Result with a band
    """The merged states the policy reaches (its choices of positive probability, and
    the internal choices where it stays or keeps), by a search written here."""
    m = r.part.merged
    mdp = m.mdp
    prob, stay = r.part.prob, r.part.stay
    seen = {int(mdp.initial)}
    todo = deque(seen)
    while todo:
        s = todo.popleft()
        for c in range(int(mdp.row_groups[s]), int(mdp.row_groups[s + 1])):
            used = prob[c] > 0 or (stay[s] > 0 and m.internal[c]) or m.keep_internal[c]
            if not used:
                continue
            lo, hi = mdp.matrix.indptr[c], mdp.matrix.indptr[c + 1]
            for j in mdp.matrix.indices[lo:hi].tolist():
                if j not in seen:
                    seen.add(j)
                    todo.append(j)
    return sorted(seen)


def _solved(tmp_path: Path, case: str):  # noqa: ANN202
    spec, constraint = CASES[case]
    path = tmp_path / "walk.toml"
    path.write_text(GRID.format(spec=spec, constraint=constraint))
    r = synthesize(load_model(path))
    # (the obligation case's upper bound is not always certified; lower, the policy's
    # worst case, is what the tree must keep)
    assert r.route == "constrained" and r.bands and r.status == "optimal"
    assert r.lower == r.lower and all(c.holds for c in r.constraints)
    return path, r


@pytest.mark.parametrize("case", sorted(CASES))
def test_the_tree_takes_the_controllers_decision_and_storm_gives_lower(tmp_path: Path,
                                                                       case: str) -> None:
    stormpy = pytest.importorskip("stormpy")
    _, r = _solved(tmp_path, case)
    tree = tree_of(r)
    assert tree.randomised
    by_tree = tree_controller(r, tree).plan
    own = r.controller.plan
    m = r.part.merged
    checked = 0
    for s in _reached(r):
        p = int(m.origin[s])
        if p < 0 or m.absorbing[s]:
            continue
        rec = r.mdp.states[p]
        if UNDECIDED not in own.verdicts[rec.automaton]:
            continue
        a = own.decide(rec.game, rec.automaton, rec.pending, rec.clock)
        b = by_tree.decide(rec.game, rec.automaton, rec.pending, rec.clock)
        assert (a.actions, a.stay, a.inside, a.keep, a.kept) == (
            b.actions, b.stay, b.inside, b.keep, b.kept)
        assert np.array_equal(a.weights, b.weights)
        checked += 1
    assert checked >= 5
    # the policy read back from the tree's leaves, at every live merged state
    prob = np.zeros_like(r.part.prob)
    stay = np.zeros_like(r.part.stay)
    mdp = m.mdp
    for s in range(mdp.n_states):
        lo, hi = int(mdp.row_groups[s]), int(mdp.row_groups[s + 1])
        p = int(m.origin[s])
        d = None
        if p >= 0 and not m.absorbing[s]:
            rec = r.mdp.states[p]
            d = by_tree.decide(rec.game, rec.automaton, rec.pending, rec.clock)
        if d is None or d.weights is None or len(d.weights) != hi - lo:
            prob[lo] = 1.0  # a state the tree does not act in: never reached below
            continue
        prob[lo:hi] = d.weights
        stay[s] = d.stay
    induced = replace(r, part=replace(r.part, prob=prob, stay=stay))
    out = drn.write(mixture_chain_drn(induced), tmp_path / "tree_chain.drn")
    model = stormpy.build_model_from_drn[stormpy.Interval](str(out))
    env = stormpy.Environment()
    env.solver().min_max().precision = stormpy.Rational("1/1000000000000")
    res = stormpy.model_checking(
        model, stormpy.parse_properties('Pmin=? [F "accept"]')[0], environment=env,
        uncertainty_resolution_mode=stormpy.UncertaintyResolutionMode.MINIMIZE)
    worst = float(res.get_value(model.initial_states[0]))
    assert r.lower - 1e-9 <= worst <= r.lower + 1e-7
    with pytest.raises(ValueError, match="worst case"):
        tree_value(r, tree)


def test_export_tree_writes_a_band_and_constraint_controller(tmp_path: Path,
                                                             capsys) -> None:
    path, r = _solved(tmp_path, "co-safe")
    out = tmp_path / "tree.json"
    assert main(["export", str(path), "--tree", str(out), "--json"]) == 0
    said = json.loads(capsys.readouterr().out)
    written = json.loads(out.read_text())
    assert said["files"]["tree"] == str(out) and written["randomised"] is True
    leaves = [n for n in written["nodes"] if "actions" in n]
    assert leaves and all(abs(sum(n["actions"].values()) + n["stay"] - 1) < 1e-9
                          for n in leaves)
