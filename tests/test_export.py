"""Exports read back by other tools: DRN by Storm (stormpy), MPS / LP by HiGHS."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import highspy
import numpy as np
import pytest
import stormpy
import stormpy.environments
from conftest import HAND_CHOICES, build_mdp

from mitld_lp.mdp import MDP
from mitld_lp.solvers import interval_iteration, solve_lp, write_drn, write_lp
from mitld_lp.solvers.quotient import prob0_max
from mitld_lp.testing import random_mdp

# The shared HAND MDP with a state 7 that reaches target, sink or truncated (8).
HAND = build_mdp(
    [*HAND_CHOICES, [("h", {3: 0.5, 8: 0.25, 2: 0.25})], []],
    target=[3],
    sink=[2],
    truncated=[8],
)


def storm_pmax(path: Path) -> tuple[np.ndarray, list[set[str]]]:
    """Pmax=? [F "target"] in every state by Storm (sound value iteration, precision
    1e-12), and the labels of every state."""
    model = stormpy.build_model_from_drn(str(path))
    prop = stormpy.parse_properties('Pmax=? [F "target"]')[0]
    env = stormpy.Environment()
    minmax = env.solver().min_max()
    # Sound value iteration: certified to the precision (the default method stops at a
    # 1e-6 relative change).  Not policy iteration with the Eigen solver: on one of the
    # random models below it returns values off by 0.8 (seed 2), where every other
    # Storm method and an independent scipy value LP agree with ours.
    minmax.method = stormpy.environments.MinMaxMethod.SOUND_VALUE_ITERATION
    minmax.precision = stormpy.Rational("1/1000000000000")
    result = stormpy.model_checking(model, prop, environment=env)
    labels = [set(model.labeling.get_labels_of_state(s)) for s in range(model.nr_states)]
    return np.asarray(result.get_value_vector()), labels


def test_drn_read_back_by_storm(tmp_path: Path) -> None:
    path = write_drn(HAND, HAND.target, tmp_path / "hand.drn")
    values, labels = storm_pmax(path)
    # State ids are kept: the labels sit where we put them.
    assert labels[0] == {"init"} and labels[3] == {"target", "accept"} and labels[2] == {"sink"}
    assert labels[8] == {"truncated"}
    np.testing.assert_allclose(values, [0.25, 0.5, 0, 1, 0.5, 0, 1, 0.5, 0], atol=1e-9)
    # The upper model: truncated counts as reached.
    upper = write_drn(HAND, HAND.target | HAND.truncated, tmp_path / "upper.drn",
                      truncated_label=False)
    values, labels = storm_pmax(upper)
    assert labels[8] == {"target", "accept"}
    assert values[7] == pytest.approx(0.75, abs=1e-9)


@pytest.mark.parametrize("seed", range(4))
def test_drn_random_models_agree_with_storm(tmp_path: Path, seed: int) -> None:
    mdp = random_mdp(120, seed=seed, locality=None if seed % 2 else 5, sink_fraction=0.1)
    path = write_drn(mdp, mdp.target, tmp_path / "m.drn")
    values, labels = storm_pmax(path)
    assert [s for s, lab in enumerate(labels) if "init" in lab] == [mdp.initial]
    assert np.flatnonzero(["target" in lab for lab in labels]).tolist() == \
        np.flatnonzero(mdp.target).tolist()
    ours = interval_iteration(mdp, mdp.target, gap="max", progress=False)
    np.testing.assert_allclose(values, ours.lower, atol=1e-8)
    lp = solve_lp(mdp, mdp.target, everywhere=True, backend="direct")
    assert lp.values is not None
    # Interior-point duals: accurate to the solver's tolerance times the conditioning.
    np.testing.assert_allclose(values, lp.values, atol=1e-6)


def test_drn_action_names_and_overwrite(tmp_path: Path) -> None:
    mdp = build_mdp([[("move north", {1: 1.0})], []], target=[1])
    path = write_drn(mdp, mdp.target, tmp_path / "a.drn")
    text = path.read_text()
    assert "\taction move_north\n" in text and "\taction absorb\n" in text
    assert "@nr_states\n2\n@nr_choices\n2\n" in text
    with pytest.raises(FileExistsError, match="overwrite=True"):
        write_drn(mdp, mdp.target, path)
    write_drn(mdp, mdp.target, path, overwrite=True)


def undecided(mdp: MDP) -> MDP:
    maybe = ~mdp.target & ~prob0_max(mdp, mdp.target)
    return replace(mdp, initial=int(np.flatnonzero(maybe)[0]))


@pytest.mark.parametrize("suffix", [".mps", ".lp"])
@pytest.mark.parametrize("seed", [0, 1])
def test_lp_file_read_back_by_highs(tmp_path: Path, suffix: str, seed: int) -> None:
    mdp = undecided(random_mdp(150, seed=seed, locality=6, sink_fraction=0.1))
    path = write_lp(mdp, mdp.target, tmp_path / f"model{suffix}")
    highs = highspy.Highs()
    highs.setOptionValue("output_flag", False)
    assert highs.readModel(str(path)) == highspy.HighsStatus.kOk
    highs.run()
    assert highs.getModelStatus() == highspy.HighsModelStatus.kOptimal
    ref = interval_iteration(mdp, mdp.target, tol=1e-11, progress=False)
    assert highs.getInfo().objective_function_value == pytest.approx(ref.value_lower, abs=1e-8)
    ours = solve_lp(mdp, mdp.target, solver="HIGHS")
    assert highs.getInfo().objective_function_value == pytest.approx(ours.value, abs=1e-8)


def test_lp_file_hand_model(tmp_path: Path) -> None:
    path = write_lp(HAND, HAND.target, tmp_path / "hand.mps")
    highs = highspy.Highs()
    highs.setOptionValue("output_flag", False)
    highs.readModel(str(path))
    highs.run()
    assert highs.getInfo().objective_function_value == pytest.approx(0.25, abs=1e-10)
    lp = highs.getLp()
    assert lp.num_row_ == 4 and lp.num_col_ == 6  # 7, MEC{0}, MEC{1,4}, 6; 6 columns
    assert set(lp.row_names_) == {"s6", "s7", "mec0", "mec1"}


def test_lp_export_refusals(tmp_path: Path) -> None:
    path = tmp_path / "x.mps"
    write_lp(HAND, HAND.target, path)
    with pytest.raises(FileExistsError, match="overwrite=True"):
        write_lp(HAND, HAND.target, path)
    write_lp(HAND, HAND.target, path, overwrite=True)
    with pytest.raises(ValueError, match="the suffix must be one of .mps, .lp"):
        write_lp(HAND, HAND.target, tmp_path / "x.txt")


def test_drn_is_the_same_whatever_the_chunk(tmp_path: Path,
                                            monkeypatch: pytest.MonkeyPatch) -> None:
    from mitld_lp.files import drn

    mdp = random_mdp(60, seed=9, locality=4)
    whole = write_drn(mdp, mdp.target, tmp_path / "whole.drn")
    monkeypatch.setattr(drn, "CHUNK_STATES", 7)  # 60 states: 9 chunks, the last short
    chunked = write_drn(mdp, mdp.target, tmp_path / "chunked.drn")
    assert chunked.read_bytes() == whole.read_bytes()
    values, _ = storm_pmax(chunked)
    ours = interval_iteration(mdp, mdp.target, gap="max", progress=False)
    np.testing.assert_allclose(values, ours.lower, atol=1e-8)


def test_storms_scheduler_on_our_drn_maps_back_to_our_value(tmp_path):
    """The DRN carries valuations and action names: Storm's optimal scheduler, read
    back by choice label, is a policy of ours, and its exact value is our optimum."""
    from stormpy.core._building import DirectEncodingParserOptions

    from mitld_lp import load_model, synthesize
    from mitld_lp.solvers.iteration import evaluate_policy

    models = Path(__file__).resolve().parent.parent / "models"
    r = synthesize(load_model(models / "red_light.toml"))
    mdp = r.mdp
    path = write_drn(mdp, mdp.target, tmp_path / "m.drn")
    lines = path.read_text().splitlines()
    # every state line is followed by its valuation, the product state it stands for
    first = lines.index("state 0 init")
    s0 = mdp.states[0]
    assert lines[first + 1] == (f"//[game=({s0.game[0]},{s0.game[1]}) & q={s0.automaton} & "
                                f"pending={{{','.join(sorted(s0.pending))}}} & clock={s0.clock}]")
    assert sum(1 for line in lines if line.startswith("//[")) == mdp.n_states

    options = DirectEncodingParserOptions()
    options.build_choice_labeling = True
    model = stormpy.build_model_from_drn(str(path), options=options)
    prop = stormpy.parse_properties('Pmax=? [F "target"]')[0]
    checked = stormpy.model_checking(model, prop, extract_scheduler=True)
    scheduler = checked.get_scheduler()
    matrix, labels = model.transition_matrix, model.choice_labeling
    policy = np.full(mdp.n_states, -1, dtype=np.int64)
    for s in range(mdp.n_states):
        row = matrix.get_row_group_start(s) + scheduler.get_choice(s).get_deterministic_choice()
        (name,) = labels.get_labels_of_choice(row)
        if name == "absorb":
            continue
        # our choice of that name in our state s: the labels are what maps back
        ours = [c for c in mdp.choices(s) if mdp.action_name(c) == name]
        assert len(ours) == 1
        policy[s] = ours[0]
    value = evaluate_policy(mdp, mdp.target, policy)[mdp.initial]
    assert value == pytest.approx(r.lower, abs=1e-6)
    storm = checked.get_value_vector()[model.initial_states[0]]
    assert value == pytest.approx(storm, abs=1e-6)
