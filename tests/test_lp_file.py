"""The exported LP's optimum is the value: HiGHS, reading the MPS and LP files the
command line and the library write, finds the probability of satisfying the task from
the initial state, as Storm (on the DRN export) and interval iteration compute it."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import highspy
import numpy as np
import pytest
import stormpy
import stormpy.environments
from conftest import build_mdp

from mitld_lp.cli import main
from mitld_lp.model import load_model
from mitld_lp.solvers import interval_iteration, write_lp
from mitld_lp.synthesis import build_product

MODELS = Path(__file__).resolve().parent.parent / "models"


def highs_optimum(path: Path) -> float:
    """HiGHS's optimal objective of the LP in ``path`` (tight tolerances)."""
    highs = highspy.Highs()
    highs.setOptionValue("output_flag", False)
    highs.setOptionValue("primal_feasibility_tolerance", 1e-10)
    highs.setOptionValue("dual_feasibility_tolerance", 1e-10)
    assert highs.readModel(str(path)) == highspy.HighsStatus.kOk
    highs.run()
    assert highs.getModelStatus() == highspy.HighsModelStatus.kOptimal
    return float(highs.getInfo().objective_function_value)


def storm_value(path: Path) -> float:
    """Storm's Pmax=? [F "target"] at the initial state of the DRN file (sound value
    iteration, precision 1e-10)."""
    model = stormpy.build_model_from_drn(str(path))
    prop = stormpy.parse_properties('Pmax=? [F "target"]')[0]
    env = stormpy.Environment()
    env.solver().min_max().method = stormpy.environments.MinMaxMethod.SOUND_VALUE_ITERATION
    env.solver().min_max().precision = stormpy.Rational("1/10000000000")
    result = stormpy.model_checking(model, prop, environment=env)
    return float(result.get_value_vector()[model.initial_states[0]])


@pytest.mark.parametrize("upper", [False, True], ids=["lower", "upper"])
@pytest.mark.parametrize("name", ["patrol.toml", "red_light.toml"])
def test_exported_lp_optimum_is_the_value(tmp_path: Path, name: str, upper: bool) -> None:
    flag = ["--upper"] if upper else []
    mps, lp, drn = tmp_path / "m.mps", tmp_path / "m.lp", tmp_path / "m.drn"
    model_file = str(MODELS / name)
    assert main(["export", model_file, "--lp", str(mps), "--drn", str(drn), "-q", *flag]) == 0
    assert main(["export", model_file, "--lp", str(lp), "-q", *flag]) == 0
    storm = storm_value(drn)
    m = load_model(MODELS / name)
    mdp = build_product(m.game, m.spec, m.distributions, epsilon=m.epsilon).mdp
    target = mdp.target | mdp.truncated if upper else mdp.target
    bounds = interval_iteration(mdp, target, tol=1e-10, progress=False)
    assert bounds.value_upper - bounds.value_lower < 1e-9
    assert abs(storm - bounds.value_lower) < 1e-8  # the two references agree
    for path in (mps, lp):
        optimum = highs_optimum(path)
        assert optimum == pytest.approx(storm, abs=1e-8), path.name
        assert bounds.value_lower - 1e-8 <= optimum <= bounds.value_upper + 1e-8
    # One writer: the library writes the very file the command line wrote.
    assert write_lp(mdp, target, tmp_path / "lib.mps").read_bytes() == mps.read_bytes()
    assert write_lp(mdp, target, tmp_path / "lib.lp").read_bytes() == lp.read_bytes()


# State 0 chooses between a fair coin (target 1 / sink 2) and the sink; state 3 can only
# reach the sink.
DECIDED = build_mdp(
    [[("coin", {1: 0.5, 2: 0.5}), ("give_up", {2: 1.0})], [], [], [("stay", {2: 1.0})]],
    target=[1],
    sink=[2],
)


@pytest.mark.parametrize("suffix", [".mps", ".lp"])
@pytest.mark.parametrize(("initial", "value"), [(0, 0.5), (1, 1.0), (2, 0.0), (3, 0.0)])
def test_lp_of_a_decided_initial_state_has_the_decided_value(
        tmp_path: Path, suffix: str, initial: int, value: float) -> None:
    mdp = replace(DECIDED, initial=initial)
    path = write_lp(mdp, mdp.target, tmp_path / f"d{suffix}")
    assert highs_optimum(path) == pytest.approx(value, abs=1e-12)
    highs = highspy.Highs()
    highs.setOptionValue("output_flag", False)
    highs.readModel(str(path))
    if initial != 0:  # decided by graph analysis: the one row of the initial state
        assert list(highs.getLp().row_names_) == [f"s{initial}"]
        assert np.all(np.asarray(highs.getLp().row_lower_) == 1.0)


def test_cli_exports_the_lp_of_a_task_decided_at_step_0(tmp_path: Path) -> None:
    (tmp_path / "done.toml").write_text(
        'name = "done"\nspec = "F[0,3] A"\n[grid]\nsize = [2, 1]\nstart = [0, 0]\n'
        "slip = 0.0\nobstacles = []\n[regions]\nA = [[0, 0]]\n")
    out = tmp_path / "done.mps"
    assert main(["export", str(tmp_path / "done.toml"), "--lp", str(out), "-q"]) == 0
    assert highs_optimum(out) == pytest.approx(1.0, abs=1e-12)  # A holds at the start
