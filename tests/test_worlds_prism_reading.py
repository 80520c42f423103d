"""PRISM files read as PRISM reads them: sums within PRISM's tolerance, budgets on the
explored part, states where the task is decided left unexpanded, formulas and model-file
labels as propositions.  Values are checked against Storm's own answer on the same file
(Storm's default build, which accepts the rounding these files have) and against the
same game explored in full."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from mitld_lp import Model, synthesize
from mitld_lp.logic.parser import parse
from mitld_lp.model import ModelError, loads_model
from mitld_lp.worlds import WorldError
from mitld_lp.worlds.prism import DECIDED_ACTION, load_prism

pytestmark = pytest.mark.skipif(
    importlib.util.find_spec("stormpy") is None, reason="needs stormpy: pip install -e '.[prism]'"
)

# The 3x3 room: 0.8 + 0.1 + 0.1 does not sum to 1 exactly in floating point
# (Storm's exploration checks refuse it; PRISM and Storm's default build accept it).
ROOM = """mdp
module room
  x : [0..2] init 0;
  y : [0..2] init 0;
  [up] y<2 -> 0.8 : (y'=y+1) + 0.1 : (x'=max(x-1,0)) + 0.1 : true;
  [right] x<2 -> 0.7 : (x'=x+1) + 0.2 : (y'=max(y-1,0)) + 0.1 : true;
  [stay] true -> true;
endmodule
formula corner = x=2 & y=2;
formula far = x+y;
label "top" = y=2;
label "wall" = x=0 & y=1;
"""



@pytest.fixture(autouse=True)
def _storms_build(monkeypatch: pytest.MonkeyPatch) -> None:
    """These tests look into Storm's build (its options, its second build, its files):
    the load uses it, not the own explorer (tests/test_prism_explore.py compares them)."""
    monkeypatch.setenv("MITLD_PRISM_BUILDER", "storm")


def write(tmp_path: Path, text: str, name: str = "m.prism") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def storm_value(source: Path, prop: str) -> float:
    """Storm's value of ``prop`` at the initial state, with Storm's default build
    (``1-P...`` is one minus the value of ``P...``)."""
    import stormpy

    if prop.startswith("1-"):
        return 1.0 - storm_value(source, prop[2:])
    program = stormpy.parse_prism_program(str(source))
    props = stormpy.parse_properties(prop, program)
    model = stormpy.build_model(program, props)
    result = stormpy.model_checking(model, props[0])
    return float(result.get_value_vector()[model.initial_states[0]])


def storm_states(source: Path, prop: str) -> int:
    """How many states Storm builds for ``prop`` (it does not expand decided states)."""
    import stormpy

    program = stormpy.parse_prism_program(str(source))
    return int(stormpy.build_model(program, stormpy.parse_properties(prop, program)).nr_states)


# --------------------------------------------------------------------------- sums


def test_room_loads_with_default_settings_and_agrees_with_storm(tmp_path: Path) -> None:
    src = write(tmp_path, ROOM)
    game = load_prism(src)
    assert game.n_states == 9
    r = synthesize(Model.from_game(game, "F top"))
    assert r.certified
    assert r.lower - 1e-7 <= storm_value(src, 'Pmax=? [F "top"]') <= r.upper + 1e-7
    r = synthesize(Model.from_game(game, "F[0,5] corner"))
    storm = storm_value(src, "Pmax=? [F<=5 x=2 & y=2]")
    assert 0.0 < storm < 1.0 and r.lower - 1e-7 <= storm <= r.upper + 1e-7


@pytest.mark.parametrize("updates", [
    "1/3 : (x'=1) + 1/3 : (x'=2) + 1/3 : true",         # exact 1 as rationals, not in floats
    "0.7 : (x'=1) + 0.2 : (x'=2) + 0.1 : true",          # 0.9999999999999999 in floats
    "0.333333 : (x'=1) + 0.333333 : (x'=2) + 0.333334 : true",
    "0.5 : (x'=1) + 0.5 : (x'=2) + 0.000001 : true",     # 1.000001: within PRISM's 1e-5
])
def test_sums_within_prisms_tolerance_are_accepted(tmp_path: Path, updates: str) -> None:
    # state-dependent guard, so that the check is Storm's (not the constant pre-check)
    text = f"mdp\nmodule m\n  x : [0..2] init 0;\n  [go] x<1 -> {updates};\n" \
           "  [stay] true -> true;\nendmodule\nlabel \"two\" = x=2;\n"
    game = load_prism(write(tmp_path, text))
    assert game.n_states == 3
    assert game.actions((0,)) == ("go", "stay")


@pytest.mark.parametrize("updates, shown", [
    ("(x+8)/10 : (x'=1) + 0.1 : true", "0.9"),     # shortfall at x=0
    ("(x+10)/10 : (x'=1) + 0.1 : true", "1.1"),    # excess at x=0
    ("0.5 : (x'=1) + 0.49 : true", "0.99"),        # constant: the pre-check
])
def test_real_shortfall_and_excess_are_refused_with_the_sum(
    tmp_path: Path, updates: str, shown: str
) -> None:
    text = f"mdp\nmodule m\n  x : [0..2] init 0;\n  [go] x<1 -> {updates};\nendmodule\n"
    with pytest.raises(WorldError, match=rf"m\.prism: module m, command 1 \(\[go\] .*\): "
                       rf"probabilities sum to {shown}( in a state)?, not 1$"):
        load_prism(write(tmp_path, text))


def test_out_of_range_is_still_refused_when_a_sum_is_rounded(tmp_path: Path) -> None:
    # the rounded sum makes Storm's double check fail first; the exact check must still
    # find the update out of range (without checks Storm would wrap x around)
    text = ("mdp\nmodule m\n  x : [0..3] init 0;\n"
            "  [go] x<3 -> 0.7 : (x'=x+1) + 0.2 : (x'=x+2) + 0.1 : true;\nendmodule\n")
    with pytest.raises(WorldError, match=r"'x' the value [45], outside its range \[0\.\.3\]"):
        load_prism(write(tmp_path, text))



def test_a_rounded_sum_costs_no_exact_build_when_the_world_is_accepted(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # the exact build (three times the float one) runs only to word a refusal; an
    # accepted world is Storm's unchecked float build, checked on the copy
    import mitld_lp.worlds.prism_build as build

    kinds: list[str] = []

    def recording(stormpy, program, options, value_type, limit):  # noqa: ANN001, ANN202
        kinds.append("float" if value_type is float else "exact")
        return real(stormpy, program, options, value_type, limit)

    real = build.storm_build
    monkeypatch.setattr(build, "storm_build", recording)
    game = load_prism(write(tmp_path, ROOM))
    assert kinds == ["float", "float"]  # the checked build stopped at 0.8+0.1+0.1
    assert game.n_states == 9  # 3 x 3, every cell reachable (by hand)
    kinds.clear()
    text = ROOM.replace("[stay] true -> true;", "[stay] true -> true;\n"
                        "  [jump] x=2 & y=2 -> (x+3)/10 : (x'=0) + 0.49 : (y'=0);")
    with pytest.raises(WorldError, match=r"module room, command 4 \(\[jump\] .*\): "
                       r"probabilities sum to 0\.99( in a state)?, not 1$"):
        load_prism(write(tmp_path, text, "bad.prism"))
    # (a state-dependent sum, 0.5 + 0.49 at x=2: Storm's, not the constant pre-check)
    # refused on the copy, then worded by Storm's exact checks, which pass 0.8+0.1+0.1
    # and stop at the jump
    assert kinds == ["float", "float", "exact"]


@pytest.mark.parametrize("jump, found", [
    ("(x'=3)", r"an update gives a variable a value outside its range"),  # not exact:
    ("(x+3)/10 : (x'=0) + 0.3 : (y'=0)", r"probabilities sum to 0\.8, not 1"),  # 1/3 stops it
])
def test_a_refusal_after_an_inexact_sum_is_the_copys(tmp_path: Path, jump: str,
                                                     found: str) -> None:
    # 1/3 as 0.333333 sums to 0.999999: within the tolerance, and the exact checks stop
    # there too, before x=2 & y=2: the refusal found on the copy stands, naming the state
    text = ROOM.replace("0.8 : (y'=y+1) + 0.1 : (x'=max(x-1,0)) + 0.1 : true",
                        "0.333333 : (y'=y+1) + 0.333333 : (x'=max(x-1,0)) + 0.333334 : true"
                        ).replace("[stay] true -> true;",
                                  f"[stay] true -> true;\n  [jump] x=2 & y=2 -> {jump};")
    text = text.replace("0.333334", "0.333333")
    with pytest.raises(WorldError, match=rf"m\.prism: at state \[x=2 & y=2\], action "
                       rf"'jump': {found}"):
        load_prism(write(tmp_path, text))


# --------------------------------------------------------------------------- decided states


CHAIN = """mdp
module m
  x : [0..6] init 0;
  c : bool init false;
  [go] x<6 -> 0.7 : (x'=x+1) + 0.2 : (c'=true) + 0.1 : (x'=max(x-1,0));
  [hop] x<3 -> 0.5 : (x'=x+2) + 0.5 : (c'=true);
  [rest] true -> true;
endmodule
label "goal" = x=4;
label "crash" = c;
label "mid" = x=2;
"""


@pytest.mark.parametrize("spec, storm", [
    ("F goal", 'Pmax=? [F "goal"]'),
    ("!crash U goal", 'Pmax=? [!"crash" U "goal"]'),
    ("F[0,4] goal", 'Pmax=? [F<=4 "goal"]'),
    ("G[0,3] !crash", '1-Pmin=? [F<=3 "crash"]'),
])
def test_decided_states_are_not_expanded_and_values_are_storms(
    tmp_path: Path, spec: str, storm: str
) -> None:
    src = write(tmp_path, CHAIN)
    full = load_prism(src)
    game = load_prism(src, task=parse(spec))
    assert game.decided > 0 and game.n_states < full.n_states
    # Storm, given the property, explores no fewer states (its terminal states are the
    # targets of F and U; ours also the states where the left side of U fails)
    if "<=" not in storm:
        assert game.n_states <= storm_states(src, storm)
    if spec == "F goal":
        assert game.n_states == storm_states(src, storm) == 10  # x=5, 6 only via x=4
    for s in game.states:
        if game.actions(s) == (DECIDED_ACTION,):
            assert dict(game.successors(s, DECIDED_ACTION, frozenset())) == {s: 1.0}
    reduced = synthesize(Model.from_game(game, spec))
    whole = synthesize(Model.from_game(full, spec))
    value = storm_value(src, storm)
    for r in (reduced, whole):
        assert r.certified and r.lower - 1e-7 <= value <= r.upper + 1e-7


@pytest.mark.parametrize("spec", [
    "F mid & F goal",            # decided only where both hold at once: x=2 & x=4, never
    "F (mid & X goal)",          # X: never decided by a state
    "F[2,5] goal",               # a window that opens later: never decided by a state
    "goal U mid",                # decided at mid or at !goal
    "F (crash & F goal)",
    "G !crash | F goal",
])
def test_decided_condition_never_changes_a_value(tmp_path: Path, spec: str) -> None:
    src = write(tmp_path, CHAIN)
    full = synthesize(Model.from_game(load_prism(src), spec))
    game = load_prism(src, task=parse(spec))
    cut = synthesize(Model.from_game(game, spec))
    assert full.certified and cut.certified
    assert abs(full.lower - cut.lower) < 1e-6 and abs(full.upper - cut.upper) < 1e-6


def test_model_file_gives_the_task_to_the_world(tmp_path: Path) -> None:
    src = write(tmp_path, CHAIN)
    m = loads_model(f'name = "t"\nspec = "!crash U goal"\n[prism]\nfile = "{src}"\n')
    assert m.game.decided > 0 and m.game.terminal
    # decided: x=4 (goal) and c (crash): with c false, x in 0..4; with c true, x in 0..3
    assert m.game.n_states == 5 + 4


# --------------------------------------------------------------------------- vocabulary


def test_formulas_are_propositions(tmp_path: Path) -> None:
    src = write(tmp_path, ROOM)
    game = load_prism(src)
    # Boolean formulas become labels; a numeric one (far = x+y) does not
    assert game.proposition_names == {"top", "wall", "corner"}
    assert {s for s in game.states if "corner" in game.propositions(s)} == {(2, 2)}


def test_model_file_labels_are_evaluated_by_storm(tmp_path: Path) -> None:
    src = write(tmp_path, ROOM)
    text = (f'name = "t"\nspec = "F done"\n[prism]\nfile = "{src}"\n'
            '[labels]\ndone = "x=1 & far>=2"\n')
    m = loads_model(text)
    assert {s for s in m.game.states if "done" in m.game.propositions(s)} == {(1, 1), (1, 2)}
    r = synthesize(m)
    value = storm_value(src, "Pmax=? [F x=1 & x+y>=2]")
    assert r.certified and r.lower - 1e-7 <= value <= r.upper + 1e-7
    assert src.read_text() == ROOM  # the user's file is not changed


@pytest.mark.parametrize("labels, message", [
    ('done = "x=1 &"', r"labels\.done: PRISM parse error"),
    ('top = "x=1"', r"labels\.top: .*already has a label 'top'"),
    ('corner = "x=1"', r"labels\.corner: .*already has a formula 'corner'"),
    ('done = 3', r"labels\.done: must be a string"),
    ('done = "x=1; label \\"y\\" = true"', r"labels\.done: must be one PRISM expression"),
])
def test_model_file_label_errors_name_the_key(tmp_path: Path, labels: str, message: str) -> None:
    src = write(tmp_path, ROOM)
    with pytest.raises(ModelError, match=message):
        loads_model(f'name = "t"\nspec = "F top"\n[prism]\nfile = "{src}"\n[labels]\n{labels}\n')


# Variables of every shape the valuations' bit-packed records hold: negative lower
# bounds, Booleans, a range of 17 bits that crosses byte boundaries (six values of it
# reached), a global.
PACKED = """mdp
global g : [-5..-1] init -3;
module a
  x : [-3..4] init -2;
  b : bool init true;
  w : [0..100000] init 99990;
  [step] x<4 -> 0.5 : (x'=x+1) & (b'=!b) + 0.5 : (w'=w<99995 ? w+1 : 99990) & (g'=g<-1 ? g+1 : -5);
  [step] x=4 -> (x'=-3);
endmodule
module c
  y : [5..9] init 7;
  d : bool init false;
  [step] true -> 0.5 : (y'=y<9 ? y+1 : 5) + 0.5 : (d'=!d);
endmodule
"""


def test_valuations_are_storms_state_by_state(tmp_path: Path) -> None:
    """The states read from Storm's binary export are the valuations Storm prints for
    each state (its JSON, one state at a time), and the initial one is the program's."""
    import json

    import stormpy

    source = write(tmp_path, PACKED)
    game = load_prism(source)
    assert game.initial == tuple({"g": -3, "x": -2, "b": True, "w": 99990, "y": 7,
                                  "d": False}[v] for v in game.variables)
    program = stormpy.parse_prism_program(str(source))
    options = stormpy.BuilderOptions()
    options.set_build_state_valuations()
    model = stormpy.build_model(program, options=options)
    storm = [json.loads(str(model.state_valuations.to_json(s))) for s in range(model.nr_states)]
    assert len(game.states) == model.nr_states > 100
    assert sorted(game.states) == sorted(tuple(v[name] for name in game.variables)
                                         for v in storm)
    booleans = [game.variables.index(name) for name in ("b", "d")]
    assert all(type(s[j]) is bool for s in game.states for j in booleans)


@pytest.mark.parametrize("layout", [
    {"classes": []},
    {"classes": [{"variables": [{"name": "x", "type": {"size": 8, "type": "int"}}]}]},
    {"classes": [{"variables": [{"name": "x", "type": {"size": 7, "type": "uint"}}]}]},
    {"classes": [{"variables": [{"name": "x", "type": {"size": 60, "type": "uint"}},
                                {"padding": 4}]}]},
])
def test_valuation_records_of_another_layout_are_not_read(layout: dict) -> None:
    """A layout the archive reader does not know (a signed field, records that do not
    fill whole bytes, a field wider than 56 bits, no class) is left to Storm's calls."""
    import numpy as np

    from mitld_lp.worlds.prism_tables import unpack_valuations

    assert unpack_valuations(layout, 3, 3 * 8, lambda: np.zeros(24, dtype=np.uint8)) is None


def test_valuations_are_built_when_a_state_is_first_named(tmp_path: Path) -> None:
    """A world built whole leaves its valuations to Storm until a state other than the
    initial one is named: a solve names none; then (also after a pickle) Storm's second
    build gives each state the values Storm's own build with valuations prints for that
    state number."""
    import json
    import pickle

    import stormpy

    from mitld_lp.worlds.prism_valuations import DeferredValuations

    source = write(tmp_path, PACKED)
    game = load_prism(source, define={"far": "x = 4 & y = 9"})
    states = game.states
    assert isinstance(states, DeferredValuations) and not states.built
    assert len(states) > 100 and game.initial[game.variables.index("w")] == 99990
    result = synthesize(Model.from_game(game, "F far"))
    assert result.certified and not states.built  # the solve named no state
    copy = pickle.loads(pickle.dumps(game))
    program = stormpy.parse_prism_program(str(source))
    options = stormpy.BuilderOptions()
    options.set_build_state_valuations()
    model = stormpy.build_model(program, options=options)
    storm = [json.loads(str(model.state_valuations.to_json(s))) for s in range(model.nr_states)]
    for named in (copy.states, states):
        assert list(named) == [tuple(v[name] for name in game.variables) for v in storm]
    assert states.built
    # a world an event changes is read by name, state by state: valuations at once
    events = load_prism(write(tmp_path, PACKED.replace("[step] true", "[bus] true"), "e.prism"),
                        events=["bus"])
    assert not isinstance(events.states, DeferredValuations)


def test_labels_over_many_words_are_the_label_expressions(tmp_path: Path) -> None:
    """Each state's propositions (read from Storm's bit vectors, several 64-bit words
    long here) are the labels whose expressions hold on the state's values, evaluated
    here in Python."""
    labels = 'label "hi" = w >= 99993;\nlabel "neg" = x < 0 & d;\nlabel "far" = g = -1;\n'
    game = load_prism(write(tmp_path, PACKED + labels))
    at = {name: game.variables.index(name) for name in game.variables}
    assert len(game.states) > 3 * 64
    for s in game.states:
        expected = {name for name, holds in (
            ("hi", s[at["w"]] >= 99993), ("neg", s[at["x"]] < 0 and s[at["d"]]),
            ("far", s[at["g"]] == -1)) if holds}
        assert game.propositions(s) == expected


ACTIONS = """mdp
module m
  x : [0..199] init 0;
  [a] x < 150 -> (x'=x+1);
  [b] mod(x, 3) = 0 & x < 198 -> 0.5 : (x'=x+2) + 0.5 : true;
  [] x >= 100 -> (x'=0);
endmodule
"""


@pytest.mark.parametrize("archive", [True, False])
def test_choice_actions_are_the_enabled_commands(tmp_path: Path, archive: bool,
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    """Each state's actions (each choice's name read from Storm's archive in one pass,
    or, without it, from Storm's bit vector of each choice label) are the commands
    whose guards hold on the state's values, evaluated here in Python; the unlabelled
    command is named by its module and place."""
    from mitld_lp.worlds import prism_tables

    if not archive:
        monkeypatch.setattr(prism_tables, "_choice_actions", lambda *args: None)
    game = load_prism(write(tmp_path, ACTIONS))
    assert len(game.states) > 150
    for (x,) in game.states:
        expected = {name for name, holds in (
            ("a", x < 150), ("b", x % 3 == 0 and x < 198), ("m_cmd3", x >= 100)) if holds}
        assert set(game.actions((x,))) == expected
