"""One controller interface (issue 28 item 2, issue 32): the deterministic Controller and
the randomised ConstrainedController both act on an Observation, reset, save and load
(one file format, no pickle), and run under ``simulate(model, controller)``.

Independent routes: the randomised controller's Monte-Carlo frequency is compared with
the exact value of its policy (the synthesis's sparse solve) within a 4-sigma band; the
saved copy is compared with the in-memory controller observation by observation in a
fresh interpreter that lacks the world's class; the hand case's mix (1/2, 1/2) is
worked by hand (tests/test_constraints.py)."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mitld_lp import Observation, RunStatus, synthesize
from mitld_lp.controllers.format import ControllerFileError
from mitld_lp.controllers.kinds import ConstrainedController, Controller, load_controller
from mitld_lp.model import Model, load_model
from mitld_lp.routes.constrained import ConstrainedController as Reexported
from mitld_lp.running.simulate import rollout, simulate
from mitld_lp.synthesis import synthesize_constrained
from mitld_lp.testing import two_routes_world

ROOT = Path(__file__).resolve().parent.parent
MODELS = ROOT / "models"

HAND = two_routes_world()  # worked by hand: safe 1/2; risky 0.9, 0.3 via a hazard


@pytest.fixture(scope="module")
def bus_risk():
    m = load_model(MODELS / "bus_risk.toml")
    return m, synthesize_constrained(m, ["P(F puddle) <= 0.05"], seed=3)


def test_the_class_moved_and_is_still_importable_from_constrained() -> None:
    assert Reexported is ConstrainedController


def test_hand_case_mix_is_drawn_with_a_seeded_generator(tmp_path: Path) -> None:
    # P(hazard) = 0.3 lam <= 0.15 forces lam = 1/2 between safe and risky (by hand)
    r = synthesize_constrained(Model.from_game(HAND, "F goal"), ["P(F hazard) <= 0.15"])
    c = r.controller
    assert c.randomised and isinstance(c, ConstrainedController)
    draws = []
    for seed in range(2000):
        c.reset(seed=seed)
        draws.append(c.act(Observation("s0")))
    share = draws.count("risky") / len(draws)
    assert abs(share - 0.5) <= 4 * math.sqrt(0.25 / len(draws))
    c.reset(seed=5)
    first = [c.act(Observation("s0")) for _ in range(1)]
    c.reset(seed=5)
    assert [c.act(Observation("s0")) for _ in range(1)] == first
    # the saved copy draws the same actions from the same seed
    copy = ConstrainedController.load(c.save(tmp_path / "hand.npz"), seed=0)
    mine = []
    for seed in range(50):
        c.reset(seed=seed)
        copy.reset(seed=seed)
        mine.append((c.act(Observation("s0")), copy.act(Observation("s0"))))
    assert all(a == b for a, b in mine)


def test_simulate_takes_the_randomised_controller(bus_risk) -> None:
    m, r = bus_risk
    assert r.status == "optimal" and r.certified
    # bus_risk's laws are geometric: nothing is truncated, the policy's exact value is
    # its value in the real world, which the Monte-Carlo estimate must meet
    n = 2000
    sim = simulate(m, r.controller, runs=n, seed=1, max_steps=200)
    half = 4 * math.sqrt(r.lower * (1 - r.lower) / n)
    assert abs(sim.estimate - r.lower) <= half, (sim.estimate, r.lower)
    assert simulate(m, r.controller, runs=300, seed=4) == simulate(m, r.controller, runs=300,
                                                                     seed=4)


def test_randomised_controller_saves_and_loads_and_acts_the_same(bus_risk, tmp_path) -> None:
    m, r = bus_risk
    path = r.controller.save(tmp_path / "risk.npz")
    with pytest.raises(FileExistsError):
        r.controller.save(path)
    with pytest.raises(ControllerFileError, match="a randomised controller"):
        Controller.load(path)
    loaded = load_controller(path, seed=9)
    assert isinstance(loaded, ConstrainedController)
    rng = np.random.default_rng(8)
    r.controller.reset(seed=9)
    for _ in range(100):
        status, steps = rollout(m, r.controller, rng, max_steps=80, record=True)
        loaded.reset()
        assert [loaded.act(Observation(s.state, s.events)) for s in steps] == [
            s.action for s in steps]
        assert loaded.status is status
    # a deterministic file is refused by the randomised class, loaded by the common loader
    det = synthesize(load_model(MODELS / "bus_grid.toml")).controller.save(tmp_path / "d.npz")
    with pytest.raises(ControllerFileError, match="a deterministic controller"):
        ConstrainedController.load(det)
    assert isinstance(load_controller(det), Controller)


RUN_SAVED = r"""
import json, sys
from mitld_lp import Observation
from mitld_lp.controllers.kinds import load_controller

def state(v):
    return tuple(state(x) for x in v) if isinstance(v, list) else v

c = load_controller(sys.argv[1], seed=int(sys.argv[3]))
out = []
for run in json.load(open(sys.argv[2])):
    c.reset()
    out.append([c.act(Observation(state(s), frozenset(e))) for s, e in run])
print(json.dumps({"acts": out, "status": c.status.value,
                  "solvers": sorted(m for m in ("cvxpy", "clarabel", "highspy", "stormpy")
                                    if m in sys.modules)}))
"""


def test_saved_randomised_controller_runs_in_another_process(bus_risk, tmp_path) -> None:
    m, r = bus_risk
    path = r.controller.save(tmp_path / "risk.npz")
    rng = np.random.default_rng(2)
    r.controller.reset(seed=21)
    runs, acts = [], []
    for _ in range(40):
        _, steps = rollout(m, r.controller, rng, max_steps=60, record=True)
        runs.append([(list(s.state), sorted(s.events)) for s in steps])
        acts.append([s.action for s in steps])
    (tmp_path / "runs.json").write_text(json.dumps(runs))
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run([sys.executable, "-c", RUN_SAVED, str(path),
                           str(tmp_path / "runs.json"), "21"], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 0, done.stderr
    reply = json.loads(done.stdout)
    assert reply["acts"] == acts and reply["solvers"] == []


def test_both_kinds_offer_the_common_interface(bus_risk) -> None:
    _, r = bus_risk
    det = synthesize(load_model(MODELS / "bus_grid.toml")).controller
    for c in (det, r.controller):
        c.reset(seed=1)
        assert c.status is RunStatus.RUNNING and c.automaton_state is None
        assert c.act(Observation((0, 0))) is not None
        assert c.steps == 1 and c.clock == 0 and c.pending == c.events
        assert isinstance(c.randomised, bool) and not c.settled
        with pytest.raises(ValueError, match="unknown events"):
            c.act(Observation((0, 0), frozenset({"nonsense"})))
