"""The lean PRISM load (labels, valuations and names only where asked for) loads the
world a full load does: the product of a task that reads one label is the product with
every label and the product of the same module's transitions written out by hand; the
states and names read after a load without valuations are those Storm gives with them;
an update out of a variable's range is still refused with its module and command."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from mitld_lp.automata.sta import make_sta
from mitld_lp.automata.translate import to_dta
from mitld_lp.model import Model
from mitld_lp.product import product
from mitld_lp.worlds import WorldError
from mitld_lp.worlds.game import ExplicitGame
from mitld_lp.worlds.prism import DECIDED_ACTION, load_prism
from mitld_lp.worlds.prism_valuations import DeferredValuations

pytestmark = pytest.mark.skipif(
    importlib.util.find_spec("stormpy") is None, reason="needs stormpy: pip install -e '.[prism]'"
)

# x in 0..3; goal at x=3, "far" at x=2, "home" at x=0 (three labels, the task reads one)
WALK = """mdp
module walk
  x : [0..3] init 0;
  [step] x<3 -> 0.75 : (x'=x+1) + 0.25 : (x'=0);
  [jump] x<2 -> 0.5 : (x'=x+2) + 0.5 : true;
  [rest] x<3 -> true;
endmodule
label "goal" = x=3;
label "far" = x=2;
label "home" = x=0;
"""

SPEC = "F[0,4] goal"


def by_hand() -> ExplicitGame:
    """WALK's transitions written out (states as Storm's valuations, ``(x,)``; each
    distribution's successors in Storm's order of the states, which is x's); the goal
    state is not expanded (the task is decided there): one self-loop, ``decided``."""
    rows: dict[Any, dict[str, dict[Any, float]]] = {}
    for x in range(3):
        rows[(x,)] = {"step": {(0,): 0.25, (x + 1,): 0.75}}  # in the commands' order
        if x < 2:
            rows[(x,)]["jump"] = {(x,): 0.5, (x + 2,): 0.5}
        rows[(x,)]["rest"] = {(x,): 1.0}
    rows[(3,)] = {DECIDED_ACTION: {(3,): 1.0}}
    return ExplicitGame(initial=(0,), transitions=rows, labels={(3,): {"goal"}},
                        proposition_names=frozenset({"goal"}))


def product_of(game: Any) -> Any:
    m = Model.from_game(game, SPEC)
    return product(game, make_sta(to_dta(m.spec), m.distributions, m.epsilon))


def same_mdp(a: Any, b: Any) -> None:
    assert list(a.action_names) == list(b.action_names)
    for name in ("row_groups", "choice_actions", "target", "sink", "truncated"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert np.array_equal(a.matrix.indptr, b.matrix.indptr)
    assert np.array_equal(a.matrix.indices, b.matrix.indices)
    assert a.matrix.data.tobytes() == b.matrix.data.tobytes()  # bit for bit
    assert a.initial == b.initial and list(a.states) == list(b.states)


def test_a_task_reading_one_label_builds_the_product_of_every_label(tmp_path: Path) -> None:
    path = tmp_path / "walk.prism"
    path.write_text(WALK)
    task = Model.from_game(by_hand(), SPEC).spec
    lean = load_prism(path, labels=["goal"], task=task)
    full = load_prism(path, task=task)
    assert lean.proposition_names == {"goal"}
    assert full.proposition_names == {"goal", "far", "home"}
    assert lean.decided == full.decided == 1  # the goal state, not expanded
    reference = product_of(by_hand())
    assert reference.n_states > 4
    same_mdp(product_of(lean), reference)
    same_mdp(product_of(full), reference)


# an unlabelled command (named robot_cmd3) and a module with two commands of one action:
# a whole load leaves out the valuations and the choice names, made when first read
NAMED = """mdp
module robot
  x : [0..3] init 0;
  on : bool init false;
  [go] x<3 -> 0.5 : (x'=x+1) + 0.5 : true;
  [go] x=1 -> (x'=3);
  [] x=2 & !on -> (on'=true);
  [back] x>0 -> (x'=x-1);
endmodule
label "done" = x=3 & on;
"""


def storm_truth(path: Path, variables: tuple[str, ...],
                ) -> tuple[list[tuple[Any, ...]], list[list[tuple[str, ...]]]]:
    """Each state's valuation (the values of ``variables``) and each choice's commands,
    ``(module, k)`` from 1, from Storm's build with its valuations and choice origins on."""
    import stormpy

    options = stormpy.BuilderOptions()
    options.set_build_state_valuations()
    options.set_build_choice_origins()
    model = stormpy.build_model(stormpy.parse_prism_program(str(path)), options=options)
    origins = model.choice_origins
    program = origins.program
    where = {}  # Storm's global command index -> (module, k)
    for module in program.modules:
        for k, command in enumerate(module.commands, start=1):
            where[command.global_index] = (module.name, k)
    states, commands = [], []
    matrix = model.transition_matrix
    for s in range(model.nr_states):
        v = json.loads(str(model.state_valuations.to_json(s)))
        states.append(tuple(v[name] for name in variables))
        row = []
        for c in range(matrix.get_row_group_start(s), matrix.get_row_group_end(s)):
            row.append(tuple(sorted(where[i] for i in origins.get_command_set(c))))
        commands.append(row)
    return states, commands


def expected_name(cmds: tuple[tuple[str, int], ...], row: list[tuple[Any, ...]]) -> str:
    """A choice's name by the module docstring's rule, written out for NAMED: its
    action, ``robot_cmd3`` for the unlabelled command, ``deadlock`` for Storm's
    self-loop, ``go@robot_cmd<k>`` where two [go] choices share a state."""
    if not cmds:
        return "deadlock"
    (module, k), = cmds
    action = {1: "go", 2: "go", 3: None, 4: "back"}[k]
    if action is None:
        return f"{module}_cmd{k}"
    if action == "go" and sum(1 for c in row if c and c[0][1] in (1, 2)) == 2:
        return f"go@{module}_cmd{k}"
    return action


def test_names_asked_after_a_lean_load_are_storms_with_valuations_on(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("MITLD_PRISM_BUILDER", "storm")  # about Storm's lean load: forced
    path = tmp_path / "named.prism"
    path.write_text(NAMED)
    game = load_prism(path)
    assert isinstance(game.states, DeferredValuations)  # none made by the load
    assert sorted(game.variables) == ["on", "x"]
    states, commands = storm_truth(path, game.variables)
    assert list(game.states) == states
    for s, row in zip(states, commands, strict=True):
        assert game.actions(s) == tuple(expected_name(c, row) for c in row)
    seen = {a for s in states for a in game.actions(s)}
    assert {"go@robot_cmd1", "go@robot_cmd2", "robot_cmd3", "back", "go"} <= seen


def test_an_update_out_of_range_is_refused_with_its_place(tmp_path: Path) -> None:
    path = tmp_path / "over.prism"
    path.write_text(WALK.replace("[jump] x<2", "[jump] x<3"))  # x=2 jumps to 4
    with pytest.raises(WorldError) as err:
        load_prism(path, labels=["goal"], task=Model.from_game(by_hand(), SPEC).spec)
    text = str(err.value)
    assert "module walk, command 2" in text
    assert "'x' the value 4, outside its range [0..3]" in text
