"""A PRISM world built without Storm's choice labels (prism-copy): every table a reader
of the world reads (each state's values, labels, choices' names and rows) against Storm's
own model of the same program, built by the test with every label, the valuations, the
choice labels and the choice origins, and read element by element through stormpy (no
export, no code of the package).  The choices are named when first read, by the second
build that also makes the valuations: read names first or states first, the answers are
Storm's.  And the check of a spec atom named like an action stays exact: an action never
enabled is not refused."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

pytestmark = pytest.mark.skipif(importlib.util.find_spec("stormpy") is None,
                                reason="needs stormpy: pip install -e '.[prism]'")

# QVBS-like: two synchronising modules, commands without an action, a module with two
# commands of one action (two choices of a state named alike, told apart by their
# commands), a probability sum that is 1 only within PRISM's tolerance, a deadlock,
# Booleans and integers with a lower bound that is not 0
SYNC = """mdp
const int N = 4;
module a
  x : [-1..N] init 0;
  [go] x<N -> 0.5 : (x'=x+1) + 0.5 : (x'=max(x-1, -1));
  [go] x<N-1 -> 0.8 : (x'=x+2) + 0.1 : (x'=x) + 0.1 : (x'=-1);
  [] x=-1 -> (x'=0);
  [tick] x>=0 & x<N -> true;
endmodule
module b
  on : bool init false;
  k : [1..3] init 1;
  [go] true -> 0.75 : (on'=!on) + 0.25 : true;
  [tick] k<3 -> (k'=k+1);
  [] on & k=3 -> 0.3 : (k'=1) + 0.7 : (on'=false);
endmodule
label "top" = x=N;
label "lit" = on & x>0;
"""

# a world where the task decides states (not expanded: Storm's own self-loop) and a
# state with no command enabled (Storm's deadlock loop)
STOP = """mdp
module walker
  p : [0..5] init 0;
  hurt : bool init false;
  [left] p>0 & !hurt -> 0.9 : (p'=p-1) + 0.1 : (hurt'=true);
  [right] p<4 & !hurt -> 0.6 : (p'=p+1) + 0.4 : true;
  [] p=4 & !hurt -> (p'=5);
  [] p=2 & !hurt -> 0.5 : (p'=0) + 0.5 : (p'=4);
endmodule
label "goal" = p=5;
label "bad" = hurt;
"""



@pytest.fixture(autouse=True)
def _storms_build(monkeypatch: pytest.MonkeyPatch) -> None:
    """These tests look into Storm's build (its options, its second build, its files):
    the load uses it, not the own explorer (tests/test_prism_explore.py compares them)."""
    monkeypatch.setenv("MITLD_PRISM_BUILDER", "storm")


def _toml(tmp_path: Path, name: str, text: str, spec: str) -> Path:
    (tmp_path / f"{name}.prism").write_text(text, encoding="utf-8")
    path = tmp_path / f"{name}.toml"
    path.write_text(f'spec = "{spec}"\n\n[prism]\nfile = "{name}.prism"\n', encoding="utf-8")
    return path


def storm_world(path: Path, terminal: str) -> dict:
    """Storm's own model of ``path`` read element by element: per state its values by
    variable, its labels, and per choice its name (the module docstring's rule, from
    the choice labels and origins) and its row (target index -> probability)."""
    import stormpy

    program = stormpy.parse_prism_program(str(path))
    commands = {}
    for module in program.modules:
        for k, cmd in enumerate(module.commands, start=1):
            commands[cmd.global_index] = (cmd.action_name if cmd.is_labeled else None,
                                          f"{module.name}_cmd{k}")
    if terminal:
        prop = stormpy.parse_properties(f"Pmax=? [F {terminal}]", program)[0]
        options = stormpy.BuilderOptions([prop.get_raw_formula()])
    else:
        options = stormpy.BuilderOptions()
    options.set_build_all_labels()
    options.set_build_state_valuations()
    options.set_build_choice_labels()
    options.set_build_choice_origins()
    options.set_exploration_checks(False)  # SYNC's 0.8 + 0.1 + 0.1 is not 1 exactly
    model = stormpy.build_model(program, options=options)
    matrix, origins = model.transition_matrix, model.choice_origins
    defined = {label.name for label in program.labels}  # not Storm's init, deadlock, ...
    states = []
    for s in range(model.nr_states):
        values = json.loads(str(model.state_valuations.to_json(s)))
        labels = set(model.labeling.get_labels_of_state(s)) & defined
        names, rows = [], []
        for c in range(matrix.get_row_group_start(s), matrix.get_row_group_end(s)):
            found = sorted(origins.get_command_set(c))
            chosen = set(model.choice_labeling.get_labels_of_choice(c))
            if not found:  # Storm's own self-loop: a deadlock, or a state not expanded
                assert not chosen
                names.append("deadlock" if "deadlock" in model.labeling.get_labels_of_state(s)
                             else "decided")
            elif commands[found[0]][0] is not None:  # an action: its choice label
                assert chosen == {commands[found[0]][0]}
                names.append((commands[found[0]][0], found))
            else:
                assert len(found) == 1 and not chosen
                names.append((commands[found[0]][1], found))
            rows.append({e.column: e.value for e in matrix.get_row(c)})
        plain = [x if isinstance(x, str) else x[0] for x in names]
        named = [x if isinstance(x, str) else
                 x[0] if plain.count(x[0]) == 1 else
                 x[0] + "@" + "+".join(commands[i][1] for i in x[1]) for x in names]
        states.append((values, labels, named, rows))
    return {"states": states, "initial": int(model.initial_states[0])}


def _check_against_storm(game, storm: dict) -> None:
    """Every state's values, labels, choices' names and rows, read as a per-state reader
    reads them (the game's own calls), against Storm's."""
    ours = list(game.states)
    assert len(ours) == len(storm["states"])
    assert ours[storm["initial"]] == game.initial
    index = {}
    for s, (values, labels, names, _) in enumerate(storm["states"]):
        state = ours[s]
        # Storm writes a Boolean as true/false, an integer as its value
        assert dict(zip(game.variables, state, strict=True)) == values
        assert all(isinstance(v, bool) == isinstance(values[k], bool)
                   for k, v in zip(game.variables, state, strict=True))
        index[state] = s
        assert game.propositions(state) == frozenset(labels)
        assert list(game.actions(state)) == names
    for s, (_, _, names, rows) in enumerate(storm["states"]):
        for name, row in zip(names, rows, strict=True):
            got = game.successors(ours[s], name, frozenset())
            total = sum(row.values())  # a row within PRISM's tolerance: divided by it
            want = {t: p / total if abs(total - 1) > 1e-12 else p for t, p in row.items()}
            assert {index[t]: p for t, p in got} == pytest.approx(want, rel=0, abs=1e-15)


@pytest.mark.parametrize("first", ["names", "states"])
@pytest.mark.parametrize(("text", "spec"), [(SYNC, "F top"), (STOP, "F goal & G !bad")])
def test_every_table_is_storms(tmp_path: Path, text: str, spec: str, first: str) -> None:
    from mitld_lp import load_model
    from mitld_lp.worlds.prism_names import DeferredNames

    model = load_model(_toml(tmp_path, "w", text, spec))
    game = model.game
    names = game._tables.action_names
    # built without choice labels: no choice but Storm's own loops named yet
    assert isinstance(names, DeferredNames) and not names.resolved
    assert set(names.known) <= {"deadlock", "decided"}
    if first == "names":  # the names' build makes the values too (one build for both)
        game.robot_actions(exact=True)
        assert names.resolved and game.states.built
    else:
        game.states[1]
        assert names.resolved
    _check_against_storm(game, storm_world(tmp_path / "w.prism", game.terminal))


def test_the_product_reads_as_with_every_name_known(tmp_path: Path,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """The MDP built on a world named late (its names read after the solve, the first
    read of any name) is the one built on the same world with every choice named at
    once by Storm's choice origins (the build before late names): the same action names
    and the same action of every choice, id for id, and the same bracket."""
    import numpy as np

    from mitld_lp import load_model, synthesize
    from mitld_lp.worlds import prism_build

    path = _toml(tmp_path, "w", STOP, "F goal & G !bad")
    late = synthesize(load_model(path))
    monkeypatch.setattr(prism_build, "is_late", lambda program: False)
    eager_model = load_model(path)
    assert not hasattr(eager_model.game._tables.action_names, "resolved")
    eager = synthesize(eager_model)
    assert list(late.mdp.action_names) == list(eager.mdp.action_names)
    assert np.array_equal(late.mdp.choice_actions, eager.mdp.choice_actions)
    assert (late.lower, late.upper) == (eager.lower, eager.upper)


def test_an_action_never_enabled_named_like_an_event_is_not_refused(tmp_path: Path) -> None:
    """The refusal of a spec event named like a robot action not listed in
    ``prism.events`` reads the actions enabled somewhere (Storm's names, made for it),
    not every action of the program: an action never enabled is no move of the robot."""
    from mitld_lp import load_model
    from mitld_lp.model import ModelError

    never = STOP.replace("label \"goal\"", "module idle\n  z : [0..1] init 0;\n"
                         "  [jump] z=1 -> (z'=0);\n"
                         "  [] true -> true;\nendmodule\nlabel \"goal\"")
    model = load_model(_toml(tmp_path, "never", never, "D[geometric(0.5)] jump & F goal"))
    assert model.events == {"jump"}
    assert "jump" not in model.game.robot_actions(exact=True)
    with pytest.raises(ModelError, match="prism.events: PRISM action 'right' has the name"):
        load_model(_toml(tmp_path, "right", STOP, "D[geometric(0.5)] right & F goal"))
