"""The choices of a PRISM world named from Storm's choice origins
(:mod:`mitld_lp.worlds.prism_origins`): the names are those of Storm's build where every
command without an action is given ``<module>_cmd<k>`` as its action (built here with
Storm's own ``label_unlabelled_commands`` and read by its choice labels), and each named
choice's distribution is that choice's in Storm's exact build, as rationals; the states
are Storm's build of the file itself, in its order."""

from __future__ import annotations

import importlib.util
from collections import Counter
from fractions import Fraction
from pathlib import Path

import pytest

from mitld_lp.worlds.prism import load_prism

pytestmark = pytest.mark.skipif(
    importlib.util.find_spec("stormpy") is None, reason="needs stormpy: pip install -e '.[prism]'"
)

# Several unlabelled commands in each module (overlapping guards, one that changes
# nothing, one enabled nowhere), an action both modules synchronise on, a module with two
# commands of one action (its choices told apart by their commands), a state without an
# enabled command (Storm's deadlock self-loop), probabilities exact only as rationals.
MODEL = """mdp
module a
  x : [0..3] init 0;
  [] x<3 -> 1/3 : (x'=x+1) + 2/3 : true;
  [] x<3 -> 0.1 : (x'=x+1) + 0.9 : (x'=0);
  [go] x=3 -> (x'=0);
  [go] x>=2 -> (x'=1);
  [] x=1 -> true;
  [] x>5 -> (x'=0);
endmodule
module b
  y : [0..2] init 0;
  [] y=0 -> 0.3 : (y'=1) + 0.7 : (y'=2);
  [go] y<2 -> 1/7 : (y'=0) + 6/7 : (y'=1);
  [] y=1 & x<2 -> (y'=0);
  [] y=1 & x=0 -> 0.5 : (y'=2) + 0.5 : true;
endmodule
"""

# A program whose states reach one without a command: x=2 & y=2 stays (deadlock).
DEADLOCK = """mdp
module a
  x : [0..2] init 0;
  [] x<2 -> 0.5 : (x'=x+1) + 0.5 : true;
  [] x=0 -> (x'=2);
endmodule
module b
  y : [0..2] init 0;
  [] y<2 & x>0 -> (y'=y+1);
  [tick] y<2 -> true;
endmodule
"""


def storm_named(path: Path, exact: bool = True) -> tuple[dict, list]:
    """Storm's own build of the file with each command without an action given the
    action ``<module>_cmd<k>``: per state (its values), the multiset of its choices as
    (label, distribution over the successors' values); and the states' values in the
    order of Storm's build of the file as it is."""
    import stormpy

    program = stormpy.parse_prism_program(str(path))
    fresh = {cmd.global_index: f"{module.name}_cmd{k}"
             for module in program.modules
             for k, cmd in enumerate(module.commands, start=1) if not cmd.is_labeled}
    named = program.label_unlabelled_commands(fresh)
    options = stormpy.BuilderOptions()
    options.set_build_choice_labels()
    options.set_build_state_valuations()
    kind = stormpy.Rational if exact else float
    model = stormpy.build_model[kind](named, options=options)

    def values(s: int) -> tuple:
        v = model.state_valuations
        return tuple(v.get_value(s, var) for var in
                     sorted(v.get_all_variables(), key=lambda var: var.name))

    out: dict[tuple, Counter] = {}
    for state in model.states:
        choices: Counter = Counter()
        for action in state.actions:
            labels = model.choice_labeling.get_labels_of_choice(
                model.transition_matrix.get_row_group_start(state.id) + action.id)
            label = next(iter(labels)) if labels else "deadlock"
            dist = frozenset((values(t.column), Fraction(str(t.value)))
                             for t in action.transitions if Fraction(str(t.value)) != 0)
            choices[label, dist] += 1
        out[values(state.id)] = choices
    plain_options = stormpy.BuilderOptions()
    plain_options.set_build_state_valuations()
    plain = stormpy.build_model(program, options=plain_options)
    order = [tuple(plain.state_valuations.get_value(s, var) for var in
                   sorted(plain.state_valuations.get_all_variables(), key=lambda v: v.name))
             for s in range(plain.nr_states)]
    return out, order


def ours(game) -> dict:
    """Our game's choices per state as :func:`storm_named` gives them: the label is the
    name without the commands a clash appends (``go@a_cmd3+b_cmd2`` is ``go``)."""
    order = sorted(range(len(game.variables)), key=lambda j: game.variables[j])
    out = {}
    for s in game.states:
        choices: Counter = Counter()
        for name in game.actions(s):
            dist = frozenset((tuple(int(t[j]) for j in order), p)
                             for t, p in game.exact_successors(s, name, frozenset()))
            choices[name.split("@")[0], dist] += 1
        out[tuple(int(s[j]) for j in order)] = choices
    return out


@pytest.mark.parametrize("text", [MODEL, DEADLOCK], ids=["model", "deadlock"])
def test_names_and_exact_choices_are_storms_fresh_action_build(tmp_path: Path,
                                                               text: str) -> None:
    path = tmp_path / "m.prism"
    path.write_text(text)
    game = load_prism(path)
    expected, order = storm_named(path)
    assert ours(game) == expected
    # the states in the order of Storm's build of the file as it is
    sort = sorted(range(len(game.variables)), key=lambda j: game.variables[j])
    assert [tuple(int(s[j]) for j in sort) for s in game.states] == order


def test_two_choices_of_one_action_name_their_commands(tmp_path: Path) -> None:
    """The state x=3, y=0 has [go] from a's third command and from its fourth (each with
    b's [go]), and a's first two unlabelled commands: the names count them by hand."""
    path = tmp_path / "m.prism"
    path.write_text(MODEL)
    game = load_prism(path)
    state = (3, 0) if game.variables == ("x", "y") else (0, 3)
    assert sorted(game.actions(state)) == [
        "b_cmd1", "go@a_cmd3+b_cmd2", "go@a_cmd4+b_cmd2"]
    assert sorted(game.actions(game.initial)) == ["a_cmd1", "a_cmd2", "b_cmd1"]
    assert "a_cmd6" not in game.robot_actions()  # enabled nowhere


def test_a_lazily_explored_world_names_its_choices_alike(tmp_path: Path) -> None:
    """The world explored breadth first from one state on (a state limit) names the
    choices of every state it expanded as the whole build does, and offers every
    command's name before it has met them."""
    path = tmp_path / "m.prism"
    path.write_text(MODEL)
    whole = load_prism(path)
    lazy = load_prism(path, explore="lazy", first_states=1)
    for s in whole.states:
        assert lazy.actions(s) == whole.actions(s)
    assert lazy.robot_actions() >= {"a_cmd1", "a_cmd2", "a_cmd5", "b_cmd1", "b_cmd3",
                                    "b_cmd4", "go"}


def test_an_action_named_as_an_unlabelled_command_is_told_apart(tmp_path: Path) -> None:
    """Module ``a``'s first command has no action, so it is ``a_cmd1``, and its second
    command's action is written ``a_cmd1``: both are enabled in the initial state, and
    each name gets the command it comes from."""
    path = tmp_path / "m.prism"
    path.write_text("mdp\nmodule a\n  x : [0..1] init 0;\n  [] x=0 -> (x'=1);\n"
                    "  [a_cmd1] true -> (x'=0);\nendmodule\n")
    game = load_prism(path)
    assert sorted(game.actions((0,))) == ["a_cmd1@a_cmd1", "a_cmd1@a_cmd2"]
    assert game.successors((0,), "a_cmd1@a_cmd1", frozenset()) == (((1,), 1.0),)
    assert game.actions((1,)) == ("a_cmd1",)
