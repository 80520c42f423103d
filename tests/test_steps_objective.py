"""``solve MODEL --objective min-steps|min-cost``: the least expected steps (cost) of
satisfying a task, against a hand calculation (a corridor) and Storm's exact engine on
the task's product written as DRN by this test (``Rmin=? [F "target"]``), compared as
fractions with no tolerance; infinity where no policy satisfies the task with
probability 1; the combinations not solved refused by name (exit 2)."""

from __future__ import annotations

import json
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from mitld_lp.cli import main

LINE = """name = "line"
spec = "{spec}"
{extra}
[grid]
size = [4, 1]
start = [0, 0]
slip = 0.1
obstacles = []
[regions]
A = [[3, 0]]
"""


def line(tmp_path: Path, spec: str = "F A", extra: str = "") -> str:
    path = tmp_path / "line.toml"
    path.write_text(LINE.format(spec=spec, extra=extra))
    return str(path)


def ours(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, dict]:
    code = main(["solve", *argv, "--json", "-q"])
    out = capsys.readouterr().out.strip()
    return code, json.loads(out)


def test_corridor_by_hand(capsys, tmp_path) -> None:
    """Three cells east, each move east succeeds w.p. 0.8 and otherwise slips into a
    wall (stays): 3 / 0.8 = 15/4 steps; with a move costing 2 and the others 1, the
    cheapest is 15/2 (any other move wastes a step and costs at least 1)."""
    code, a = ours(capsys, line(tmp_path), "--objective", "min-steps")
    assert code == 0 and a["certified"]
    assert Fraction(a["lower"]) <= Fraction(15, 4) <= Fraction(a["upper"])
    path = line(tmp_path, extra="[costs]\nE = 2")
    code, b = ours(capsys, path, "--objective", "min-cost")
    assert code == 0 and Fraction(b["lower"]) <= Fraction(15, 2) <= Fraction(b["upper"])


def _drn(mdp, rewards: np.ndarray) -> str:
    """The product as DRN, each row's probabilities the stored doubles as exact
    fractions with the last one making the row sum exactly 1 (a model within the
    allowance of the stored one)."""
    import scipy.sparse as sp

    matrix = sp.csr_array(mdp.matrix)
    lines = ["@type: MDP", "@parameters", "", "@reward_models", "r", "@nr_states",
             str(mdp.n_states), "@nr_choices", str(mdp.n_choices), "@model"]
    for s in range(mdp.n_states):
        labels = (" init" if s == mdp.initial else "") + (" target" if mdp.target[s] else "")
        lines.append(f"state {s} [0]{labels}")
        for c in range(mdp.row_groups[s], mdp.row_groups[s + 1]):
            lines.append(f"\taction {c - mdp.row_groups[s]} [{Fraction(rewards[c])}]")
            lo, hi = matrix.indptr[c], matrix.indptr[c + 1]
            cols = matrix.indices[lo:hi]
            probs = [Fraction(float(p)) for p in matrix.data[lo:hi]]
            probs[-1] = 1 - sum(probs[:-1])
            lines += [f"\t\t{t} : {p}" for t, p in sorted(zip(cols.tolist(), probs,
                                                             strict=True)) if p]
    return "\n".join(lines) + "\n"


def storm_on_product(path: str, tmp_path: Path, cost: dict | None = None
                     ) -> Fraction | None:
    """Storm's exact ``Rmin=? [F "target"]`` on the product of ``path``'s task (one
    reward a step, or the action's cost), None for infinity."""
    stormpy = pytest.importorskip("stormpy")
    from mitld_lp.mdp import ABSORB
    from mitld_lp.model import load_model
    from mitld_lp.routes.stages import build_posed
    from mitld_lp.synthesis import pose

    mdp = build_posed(pose(load_model(path))).mdp
    actions = np.asarray(mdp.choice_actions)
    per = np.array([(cost or {}).get(a, 1.0) for a in mdp.action_names])
    rewards = np.where(actions == ABSORB, 0.0, per[np.maximum(actions, 0)])
    drn = tmp_path / "product.drn"
    drn.write_text(_drn(mdp, rewards))
    model = stormpy.build_model_from_drn[stormpy.Rational](str(drn))
    prop = stormpy.parse_properties('R{"r"}min=? [F "target"]')[0]
    result = stormpy.model_checking(model, prop, only_initial_states=True)
    text = str(result.get_value(model.initial_states[0]))
    return None if text == "inf" else Fraction(text)


@pytest.mark.parametrize("p", ["0.3", "0.55"])
def test_waiting_for_a_geometric_bus_against_storm(capsys, tmp_path, p: str) -> None:
    """Reach A and see the bus (a geometric law): the steps until both happened."""
    path = line(tmp_path, spec="D[mu] b & F A & F b", extra=f"[distributions]\nmu = {{ "
                f"geometric = {p} }}")
    code, a = ours(capsys, path, "--objective", "min-steps")
    value = storm_on_product(path, tmp_path)
    assert value is not None and value > Fraction(15, 4)
    assert code == 0 and Fraction(a["lower"]) <= value <= Fraction(a["upper"])


def test_a_task_not_surely_satisfied_is_inf(capsys, tmp_path) -> None:
    """Be at A when the bus comes: it may come before the robot is there."""
    path = line(tmp_path, spec="D[mu] b & F (b & A)",
                extra="[distributions]\nmu = { geometric = 0.3 }")
    code, a = ours(capsys, path, "--objective", "min-steps")
    assert storm_on_product(path, tmp_path) is None
    assert code == 0 and a["value"] == "inf" and a["infinite"] and "probability 1" in a["why"]


@pytest.mark.parametrize("argv, says", [
    (["--then", "min-cost"], "with then min-cost"),
    (["--constraint", "E(steps) <= 9"], "with constraints"),
    (["--exact"], "with --exact"),
])
def test_combinations_refused_by_name(capsys, tmp_path, argv: list, says: str) -> None:
    assert main(["solve", line(tmp_path), "--objective", "min-steps", *argv, "-q"]) == 2
    assert says in capsys.readouterr().err


def test_safety_task_and_policy_refused(capsys, tmp_path) -> None:
    assert main(["solve", line(tmp_path, spec="G !A"), "--objective", "min-steps",
                 "-q"]) == 2
    assert "a safety task is not satisfied at a step" in capsys.readouterr().err
    policy = tmp_path / "p.json"
    assert main(["solve", line(tmp_path), "--objective", "min-steps", "--policy",
                 str(policy), "-q"]) == 2
    assert "writes no policy file" in capsys.readouterr().err and not policy.exists()


@pytest.mark.parametrize("objective", ["min-steps", "min-cost"])
def test_model_file_objective_stays_the_probabilitys(capsys, tmp_path,
                                                     objective: str) -> None:
    """A model file's ``objective`` is ``max`` or ``min`` (docs/constraints.md): the
    expected steps are refused there, naming the key, the values taken and the flag."""
    path = line(tmp_path, extra=f'objective = "{objective}"')
    assert main(["solve", path, "-q"]) == 2
    err = capsys.readouterr().err
    assert f'line.toml: objective: must be "max" or "min", got "{objective}"' in err
    assert f"--objective {objective}" in err and "Traceback" not in err
