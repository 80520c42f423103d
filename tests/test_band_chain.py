"""``export --chain`` of a robust answer (issue 43): the controlled chain as an interval
chain, checked by Storm's robust check (``Pmin=? [F "accept"]`` with the uncertainty
resolved to the minimum).  Independent routes: hand calculations of the worst case over
the band's corner laws (one step of two band events, where Storm's joint intervals
would give less; a choice between two stops), and the certified bracket of the bundled
``bus_fit`` model (two band events pending together: nature's corners)."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

from mitld_lp import ExplicitGame, Model, synthesize
from mitld_lp.cli import main
from mitld_lp.controllers.kinds import load_controller
from mitld_lp.distributions import from_table
from mitld_lp.model import load_model
from mitld_lp.running.band_chain import BAND_PROPERTY, band_chain_of, write_band_chain
from mitld_lp.running.tree import tree_controller, tree_of

pytestmark = pytest.mark.skipif(importlib.util.find_spec("stormpy") is None,
                                reason="needs stormpy: pip install -e '.[prism]'")

MODELS = Path(__file__).resolve().parent.parent / "models"


def storm_worst(path: Path) -> float:
    """Storm's value of the exported file, nature minimising."""
    return storm_robust(path, BAND_PROPERTY)


def storm_robust(path: Path, prop: str, *, maximise: bool = False) -> float:
    """Storm's value of ``prop`` on the interval model at ``path``, its uncertainty
    resolved to the minimum (``maximise``: the maximum)."""
    import stormpy

    model = stormpy.build_model_from_drn[stormpy.Interval](str(path))
    env = stormpy.Environment()
    env.solver().min_max().precision = stormpy.Rational("1/1000000000000")
    mode = stormpy.UncertaintyResolutionMode
    result = stormpy.model_checking(
        model, stormpy.parse_properties(prop)[0], environment=env,
        uncertainty_resolution_mode=mode.MAXIMIZE if maximise else mode.MINIMIZE)
    return float(result.get_value(model.initial_states[0]))


def laws(**bands: list[float]) -> dict:
    return {name: from_table({"geometric": band}, name) for name, band in bands.items()}


def test_two_band_events_in_one_step_are_nature_s_corners(tmp_path: Path) -> None:
    """At step 1 the task holds iff both buses come or neither does.  Nature wants
    exactly one: over the corners (h1, h2) in {0.7, 0.9} x {0.3, 0.5} its best is
    h1 = 0.9, h2 = 0.3: 0.9 * 0.7 + 0.1 * 0.3 = 0.66, so the worst case is 0.34.
    Intervals on the four joint outcomes alone would let nature reach 0.74 (0.26)."""
    game = ExplicitGame(initial="s0", labels={"s1": {"p"}},
                        transitions={"s0": {"go": {"s1": 1.0}}, "s1": {"wait": {"s1": 1.0}}})
    r = synthesize(Model.from_game(
        game, "D[mu1] b1 & D[mu2] b2 & F[0,1] ((b1 & b2) | (!b1 & !b2 & p))",
        distributions=laws(mu1=[0.7, 0.9], mu2=[0.3, 0.5])))
    assert r.route == "robust" and r.certified
    path = write_band_chain(r, tmp_path / "c.drn")
    assert "action go/b1=hi/b2=lo" in path.read_text()  # nature's corners are choices
    value = storm_worst(path)
    assert value == pytest.approx(0.34, abs=1e-9)
    assert r.lower - 1e-9 <= value <= r.upper + 1e-9


def test_a_choice_between_two_stops(tmp_path: Path) -> None:
    """The robot picks a stop at step 0 and waits there; bus 1 serves stop 1 (hazard in
    [0.2, 0.5]), bus 2 stop 2 ([0.1, 0.3]); the task: its bus within steps 1..2.  The
    worst law keeps each hazard low: stop 1 gives 1 - 0.8^2 = 0.36, stop 2
    1 - 0.9^2 = 0.19; the robust controller picks stop 1, and the chain of its saved
    and loaded controller gives 0.36 too."""
    game = ExplicitGame(initial="home", transitions={
        "home": {"one": {"s1": 1.0}, "two": {"s2": 1.0}},
        "s1": {"wait": {"s1": 1.0}}, "s2": {"wait": {"s2": 1.0}}},
        labels={"s1": {"at1"}, "s2": {"at2"}})
    r = synthesize(Model.from_game(
        game, "D[mu1] b1 & D[mu2] b2 & F[0,2] ((b1 & at1) | (b2 & at2))",
        distributions=laws(mu1=[0.2, 0.5], mu2=[0.1, 0.3])))
    assert r.route == "robust" and r.certified
    assert storm_worst(write_band_chain(r, tmp_path / "c.drn")) == pytest.approx(0.36,
                                                                                abs=1e-9)
    loaded = load_controller(r.controller.save(tmp_path / "c.npz"))
    chain = band_chain_of(r, loaded)
    assert chain.n_states == band_chain_of(r).n_states
    assert storm_worst(write_band_chain(r, tmp_path / "l.drn", controller=loaded)) == (
        pytest.approx(0.36, abs=1e-9))


def test_one_band_event_is_an_interval_chain(tmp_path: Path) -> None:
    """One band event a step: a DTMC with intervals (the outcome states); waiting at the
    stop for a bus with hazard in [0.2, 0.5], within steps 1..3: 1 - 0.8^3."""
    stop = ExplicitGame(initial="stop", transitions={"stop": {"wait": {"stop": 1.0}}})
    r = synthesize(Model.from_game(stop, "D[mu] b & F[0,3] b",
                                   distributions=laws(mu=[0.2, 0.5])))
    path = write_band_chain(r, tmp_path / "c.drn")
    text = path.read_text()
    assert "@type: DTMC" in text and "[0.2, 0.5]" in text
    assert storm_worst(path) == pytest.approx(1 - 0.8**3, abs=1e-9)


def test_bus_fit_chain_and_tree_from_the_command_line(tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]
                                                      ) -> None:
    """The bundled band model: the file written, its claim stated, Storm's worst case
    inside the certified bracket; the tree (the controller's own actions on every state
    some law reaches) has the same interval chain."""
    chain, tree = tmp_path / "c.drn", tmp_path / "t.json"
    args = ["export", str(MODELS / "bus_fit.toml"), "--chain", str(chain), "--json"]
    assert main([*args, "--tree", str(tree)]) == 0
    said = json.loads(capsys.readouterr().out)
    assert said["files"] == {"chain": str(chain), "tree": str(tree)}
    lower, upper = said["lower"], said["upper"]
    assert said["chain_accept"] == lower
    value = storm_worst(chain)
    assert lower - 1e-9 <= value <= upper + 1e-9, (lower, value, upper)
    assert main(["export", str(MODELS / "bus_fit.toml"), "--chain",
                 str(tmp_path / "d.drn")]) == 0
    assert "Pmin=? [F \"accept\"] with uncertainty MINIMIZE >= lower" in capsys.readouterr().out
    r = synthesize(load_model(MODELS / "bus_fit.toml"))
    by_tree = write_band_chain(r, tmp_path / "tree.drn",
                               controller=tree_controller(r, tree_of(r)))
    assert storm_worst(by_tree) == pytest.approx(value, abs=1e-12)


def test_a_band_with_constraints_writes_its_chain_and_its_tree(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """bus_fit with a constraint: a randomised controller.  ``--chain`` writes its
    controlled model (nature's corners as choices; refused until issue 43), which Storm's
    robust check evaluates to at least the answer's ``lower`` (and within 1e-7 of it:
    the same worst case); ``--tree`` writes its randomised tree (checked against the
    controller and Storm in tests/test_tree_band_constrained.py)."""
    text = (MODELS / "bus_fit.toml").read_text().replace(
        'epsilon = 0.01', 'epsilon = 0.01\nconstraints = ["P(F A) <= 0.9"]')
    path = tmp_path / "m.toml"
    path.write_text(text)
    (tmp_path / "data").symlink_to(MODELS / "data")
    assert main(["export", str(path), "--chain", str(tmp_path / "c.drn"), "--json",
                 "-q"]) == 0
    said = json.loads(capsys.readouterr().out)
    value = storm_worst(tmp_path / "c.drn")
    assert said["lower"] - 1e-9 <= value <= said["lower"] + 1e-7
    assert main(["export", str(path), "--tree", str(tmp_path / "t.json"), "-q"]) == 0
    assert json.loads((tmp_path / "t.json").read_text())["randomised"] is True
