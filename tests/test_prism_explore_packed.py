"""The own PRISM explorer's compact forms (mitld_lp.worlds.prism_explore), against
Storm's build as the independent route: the states' values kept packed and decoded when
read (one state, a slice, some rows, every state) must be Storm's valuations, and a
synchronised choice's commands, kept as one mixed-radix number, must be the command set
Storm's choice origins give that choice; the load's names of such choices, told apart
by their commands, must be Storm's."""

from __future__ import annotations

import numpy as np
import pytest

stormpy = pytest.importorskip("stormpy")
pytest.importorskip("numba")

from mitld_lp.worlds.prism import load_prism  # noqa: E402
from mitld_lp.worlds.prism_compile import compile_program  # noqa: E402
from mitld_lp.worlds.prism_explore import (  # noqa: E402
    BUILDER_ENV,
    PackedValuations,
    explore_program,
)
from mitld_lp.worlds.table import LATE  # noqa: E402

# three modules with two or three commands of the action go each (up to 12 choices of
# go in a state, several of them named alike), a command without an action (the choices
# then named late, told apart by their commands), Booleans and a negative range
THREE = """mdp
module a
  x : [-1..3] init 0;
  [go] x < 2 -> (x'=x+1);
  [go] x < 3 -> 0.5 : (x'=x+1) + 0.5 : (x'=-1);
  [go] x = 0 -> (x'=2);
  [] x = 3 -> (x'=0);
endmodule
module b
  y : [0..2] init 0;
  [go] y < 2 -> (y'=y+1);
  [go] true -> (y'=0);
endmodule
module c
  z : bool init false;
  [go] true -> (z'=!z);
  [go] !z -> 0.3 : (z'=true) + 0.7 : true;
endmodule
label "top" = x = 3;
"""


def _program(tmp_path):
    path = tmp_path / "three.prism"
    path.write_text(THREE)
    return path, stormpy.parse_prism_program(str(path))


def _storm_states(model) -> list[tuple]:
    """Storm's valuations, each state's values by variable name, sorted by name (the
    load's order of the variables), Booleans as bools."""
    valuations = model.state_valuations
    variables = sorted(valuations.get_all_variables(), key=lambda v: v.name)
    return [tuple(valuations.get_value(s, v) for v in variables)
            for s in range(model.nr_states)]


def test_packed_values_are_storms_valuations(tmp_path, monkeypatch) -> None:
    path, program = _program(tmp_path)
    options = stormpy.BuilderOptions()
    options.set_build_state_valuations()
    model = stormpy.build_model[float](program, options=options)
    expected = _storm_states(model)
    monkeypatch.setenv(BUILDER_ENV, "own")
    states = load_prism(path)._tables.states
    assert isinstance(states, PackedValuations)
    assert len(states) == model.nr_states == len(expected)
    assert states[0] == expected[0] and states[-1] == expected[-1]
    assert states[3] == expected[3]
    assert states[2:7] == tuple(expected[2:7])
    picks = np.array([5, 0, len(expected) - 1, 5])
    assert states.rows(picks) == [expected[i] for i in picks.tolist()]
    assert states._values is None  # a few states read: none decoded whole
    with pytest.raises(IndexError):
        states[len(expected)]
    assert list(states) == expected  # every state: decoded whole, then kept
    assert states._values is not None and states[4] == expected[4]
    assert isinstance(states[1][2], bool) and isinstance(states[1][0], int)


def test_many_states_read_one_by_one_decoded_whole(tmp_path, monkeypatch) -> None:
    """A reader going through many states one by one gets every state decoded once
    (after ``ALONE`` alone), and the same values as Storm's."""
    from mitld_lp.worlds import prism_explore

    path, program = _program(tmp_path)
    options = stormpy.BuilderOptions()
    options.set_build_state_valuations()
    expected = _storm_states(stormpy.build_model[float](program, options=options))
    monkeypatch.setenv(BUILDER_ENV, "own")
    monkeypatch.setattr(prism_explore, "ALONE", 3)
    states = load_prism(path)._tables.states
    states._alone = 0  # whatever the load itself read (the initial state)
    seen = []
    for i in range(6):
        seen.append(states[i])
        assert (states._values is None) == (i < 3), i
    assert seen == expected[:6]
    assert [states[i] for i in range(len(expected))] == expected


def test_synchronised_commands_are_storms_origins(tmp_path) -> None:
    _, program = _program(tmp_path)
    options = stormpy.BuilderOptions()
    options.set_build_choice_origins()
    model = stormpy.build_model[float](program, options=options)
    compiled = compile_program(program)
    built = explore_program(compiled, 1 << 20)
    assert not isinstance(built, str)
    assert len(built.choices) - 1 == model.nr_states
    assert len(built.origin) == model.nr_choices
    origins = model.choice_origins
    sync = np.flatnonzero(built.origin <= -3).tolist()
    assert len(sync) > 20  # the mixed-radix numbers are exercised
    assert max(len(built.commands(c)) for c in sync) == 3
    first = built.first_commands()
    for c in range(model.nr_choices):
        if built.origin[c] < 0 and built.origin[c] > -3:  # Storm's own self-loops
            continue
        mine = {compiled.cmd_global[x] for x in built.commands(c)}
        assert mine == set(origins.get_command_set(c)), c
        assert int(first[c]) == built.commands(c)[0]  # the first module's, its name's
    # in blocks as the names read them: the same first commands
    blocks = np.concatenate([built.first_commands(lo, lo + 7)
                             for lo in range(0, len(built.origin), 7)])
    assert np.array_equal(blocks, first)


def _names(tables) -> list[str]:
    ids = tables.action_index
    late = np.flatnonzero(ids >= LATE)
    codes, known = tables.action_names.names_of(late)
    out = {int(c): known[int(k)] for c, k in zip(late.tolist(), codes.tolist(), strict=True)}
    return [out.get(c, tables.action_names[int(ids[c])] if ids[c] >= 0 else None)
            for c in range(ids.size)]


def test_names_of_synchronised_clashes_are_storms(tmp_path, monkeypatch) -> None:
    path, _ = _program(tmp_path)
    monkeypatch.setenv(BUILDER_ENV, "storm")
    storm = load_prism(path)._tables
    monkeypatch.setenv(BUILDER_ENV, "own")
    own = load_prism(path)._tables
    assert type(own.action_names).__name__ == "KnownNames"  # the own explorer's
    assert np.array_equal(own.targets, storm.targets)
    assert own.probabilities.tobytes() == storm.probabilities.tobytes()
    theirs = _names(storm)
    assert any(name is not None and name.count("+") == 2 for name in theirs)
    assert _names(own) == theirs
    assert own.action_index.dtype == storm.action_index.dtype == np.int32


@pytest.mark.parametrize("guess", [1, 3, 6, 1 << 16])
def test_any_guess_and_a_small_budget(tmp_path, guess) -> None:
    """Arrays started at any number of states (the hash table a power of two whatever
    the guess) give Storm's build; a budget below the states found stops with its
    reason. By hand: x in -1..3 (5 values) x y in 0..2 x z both ways, and the build
    must find more than 5 states."""
    _, program = _program(tmp_path)
    model = stormpy.build_model[float](program)
    compiled = compile_program(program)
    built = explore_program(compiled, 1 << 20, guess=guess)
    assert not isinstance(built, str)
    assert len(built.choices) - 1 == model.nr_states > 5
    assert built.targets.size == model.nr_transitions
    assert len(built.keys) == model.nr_states  # one word a state, cut in place
    stopped = explore_program(compiled, 5, guess=guess)
    assert isinstance(stopped, str) and stopped.startswith("more states than max_states")
