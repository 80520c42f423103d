"""The DRN exports, checked by Storm with the property their docs name (issue 41).

``mitld-lp export MODEL --drn FILE`` writes the interval MDP; the docs tell the user to
check ``Pmax=? [F "target"]`` with Storm's robust value iteration.  A task with a safety
part (``G !P``) used to export only ``init`` and ``sink``: Storm refused the property
(``unknown label 'target'``).  Independent route: Storm's robust value on each exported
file, against the synthesis's bracket (one ambiguous event: the file is exactly the
model, so the values agree).  The plain DRN of a task no policy can satisfy had no
``target`` or ``accept`` either: Storm's ``Pmax=? [F "accept"]`` must answer 0."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from mitld_lp.cli import main
from mitld_lp.model import load_model
from mitld_lp.routes.robust import interval_export
from mitld_lp.synthesis import synthesize

pytestmark = pytest.mark.skipif(importlib.util.find_spec("stormpy") is None,
                                reason="needs stormpy: pip install -e '.[prism]'")

GRID = """[grid]
size = [{w}, {h}]
start = [0, 0]
slip = {slip}
obstacles = []
[regions]
A = [[{ax}, {ay}]]
P = [[1, {py}]]
[distributions]
mu = {law}
"""

CASES = {  # name: (spec, grid), each with a safety part
    "safety": ("D[mu] b & G !P", dict(w=3, h=3, slip=0.1, ax=2, ay=2, py=1,
                                      law="{ geometric = [0.2, 0.4] }")),
    "obligation": ("D[mu] b & F(b & F[0,3] A) & G !P",  # truncated: lower < upper
                   dict(w=3, h=3, slip=0.1, ax=2, ay=2, py=1, law="{ poisson = [2.0, 3.0] }")),
    "lost": ("D[mu] b & F(b & F[0,2] A) & G !P",  # P blocks the corridor to A: value 0
             dict(w=5, h=1, slip=0.0, ax=4, ay=0, py=0, law="{ geometric = [0.2, 0.4] }")),
}


def model_file(folder: Path, name: str) -> Path:
    spec, grid = CASES[name]
    path = folder / f"{name}.toml"
    path.write_text(f'name = "{name}"\nspec = "{spec}"\nepsilon = 0.05\n' + GRID.format(**grid))
    return path


def storm_robust(path: Path) -> float:
    import stormpy

    model = stormpy.build_model_from_drn[stormpy.Interval](str(path))
    prop = stormpy.parse_properties('Pmax=? [F "target"]')[0]  # as docs/robust.md says
    env = stormpy.Environment()
    env.solver().min_max().precision = stormpy.Rational("1/1000000000000")
    result = stormpy.model_checking(
        model, prop, uncertainty_resolution_mode=stormpy.UncertaintyResolutionMode.ROBUST,
        environment=env)
    return float(result.get_value(model.initial_states[0]))


@pytest.mark.parametrize("name", sorted(CASES))
def test_every_exported_interval_drn_is_checked_by_storm(tmp_path: Path, name: str) -> None:
    path = model_file(tmp_path, name)
    r = synthesize(load_model(path))
    assert r.route == "robust" and r.certified, r.failed_checks
    for upper, want in ((False, r.lower), (True, r.upper)):
        drn = tmp_path / f"{name}{'_upper' if upper else ''}.drn"
        args = ["export", str(path), "--drn", str(drn), "-q"] + (["--upper"] if upper else [])
        assert main(args) == 0
        text = drn.read_text()
        for label in ("target", "accept"):  # the labels the docs' properties name
            assert f" {label}" in text, (name, label)
        assert storm_robust(drn) == pytest.approx(want, abs=1e-8), (name, upper)
    if name == "lost":
        assert r.upper == 0.0  # Storm read the label from the state no state reaches
    if name == "obligation":
        assert r.lower < r.upper - 1e-3  # the two files differ


def test_the_target_of_a_safety_part_is_the_goal_the_synthesis_kept(tmp_path: Path) -> None:
    model = load_model(model_file(tmp_path, "obligation"))
    r = synthesize(model)
    imdp, target = interval_export(model)
    assert imdp.n_states == r.mdp.n_states
    assert np.array_equal(target, r.goal)
    assert not np.array_equal(target, imdp.target)  # the accepting states alone are not it


def test_a_plain_drn_with_nothing_to_reach_still_has_its_labels(tmp_path: Path) -> None:
    import stormpy

    path = tmp_path / "never.toml"  # P blocks the corridor to A: value 0, no target state
    path.write_text('name = "never"\nspec = "F[0,2] A & G !P"\n' + GRID.format(
        w=5, h=1, slip=0.0, ax=4, ay=0, py=0, law="{ geometric = 0.5 }").replace(
        "[distributions]\nmu = { geometric = 0.5 }\n", ""))
    r = synthesize(load_model(path))
    assert r.route == "plain" and r.certified and r.upper == 0.0
    drn = tmp_path / "never.drn"
    assert main(["export", str(path), "--drn", str(drn), "-q"]) == 0
    model = stormpy.build_model_from_drn(str(drn))
    for prop in ('Pmax=? [F "accept"]', 'Pmax=? [F "target"]'):
        check = stormpy.model_checking(model, stormpy.parse_properties(prop)[0])
        assert check.get_value(model.initial_states[0]) == 0.0
