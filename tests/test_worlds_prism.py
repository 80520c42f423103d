"""PRISM worlds: a PRISM MDP built by Storm becomes a game whose labels, action names,
event effects and values are checked against Storm itself, a hand-written product
encoding solved by Storm, and hand calculations."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest
from scipy import stats

from mitld_lp import Model, load_model, synthesize
from mitld_lp.model import ModelError, loads_model
from mitld_lp.worlds import WorldError
from mitld_lp.worlds.game import check_game
from mitld_lp.worlds.prism import DEADLOCK_ACTION, load_prism

# Tests that build a PRISM file need Storm; the others (install hint, import hygiene) run
# without it.
needs_storm = pytest.mark.skipif(
    importlib.util.find_spec("stormpy") is None, reason="needs stormpy: pip install -e '.[prism]'"
)

MODELS = Path(__file__).resolve().parent.parent / "models"
CORRIDOR = MODELS / "corridor.prism"


def storm_pmax(source: Path, prop: str, constants: dict | None = None) -> float:
    """Storm's own value of ``prop`` at the initial state of the PRISM file ``source``."""
    import stormpy
    program = stormpy.parse_prism_program(str(source))
    if constants:
        program, _ = stormpy.instantiate_constants(program, constants)
    props = stormpy.parse_properties(prop, program)
    model = stormpy.build_model(program, props)
    result = stormpy.model_checking(model, props[0])
    return float(result.get_value_vector()[model.initial_states[0]])


def write(tmp_path: Path, text: str, name: str = "m.prism") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


# --------------------------------------------------------------------------- values


@needs_storm
@pytest.mark.parametrize("k", [3, 4, 6])
def test_event_free_reach_matches_storm_on_the_same_file(k: int) -> None:
    # With the door open from the start no event is needed: F[0,k] goal is Storm's
    # bounded reachability P=? [F<=k "goal"] maximised, step 0 being the initial state.
    game = load_prism(CORRIDOR, constants={"open_at_start": True})
    r = synthesize(Model.from_game(game, f"F[0,{k}] goal"))
    storm = storm_pmax(CORRIDOR, f'Pmax=? [F<={k} "goal"]', {"open_at_start": True})
    # by hand: 4 successful moves east (each 0.8) within k steps
    binom = float(stats.binom.sf(3, k, 0.8))
    assert r.certified
    assert r.lower == pytest.approx(storm, abs=1e-6)
    assert r.upper == pytest.approx(storm, abs=1e-6)
    assert storm == pytest.approx(binom, abs=1e-6)


def _hand_product(deadline: int, hazards: list[float]) -> str:
    """The corridor with the door event written as one PRISM MDP by hand: a phase bit
    (robot moves, then the environment opens the door with the step's hazard) and a
    step counter; goal counts only at a step <= deadline."""
    cap = deadline + 1
    h = " : ".join(f"t={t} ? {hz!r}" for t, hz in enumerate(hazards[:cap])) + " : 1"
    return f"""
mdp
formula h = {h};
module w
  x : [0..4] init 0;
  open : bool init false;
  phase : [0..1] init 0;
  t : [0..{cap}] init 0;
  [east] phase=0 & t<{cap} & (x<3 | (x=3 & open)) -> 0.8:(x'=x+1)&(phase'=1) + 0.2:(phase'=1);
  [west] phase=0 & t<{cap} & x>0 -> (x'=x-1)&(phase'=1);
  [wait] phase=0 & t<{cap} -> (phase'=1);
  [] phase=1 & !open -> h:(open'=true)&(phase'=0)&(t'=t+1) + (1-h):(phase'=0)&(t'=t+1);
  [] phase=1 & open -> (phase'=0)&(t'=t+1);
endmodule
label "goal" = x=4 & phase=0 & t<={deadline};
"""


@needs_storm
def test_bundled_task_brackets_storms_value_of_a_hand_written_product(tmp_path: Path) -> None:
    m = load_model(MODELS / "corridor.toml")
    assert m.events == {"opened"}
    r = synthesize(m)
    # the door's opening step K = 1 + Poisson(2): hazard h(j) = P(K=j) / P(K > j-1)
    hazards = [
        float(stats.poisson.pmf(j - 1, 2) / (stats.poisson.sf(j - 2, 2) if j >= 2 else 1.0))
        for j in range(1, 12)
    ]
    storm = storm_pmax(write(tmp_path, _hand_product(7, hazards)), 'Pmax=? [F "goal"]')
    assert r.certified
    assert r.lower - 1e-6 <= storm <= r.upper + 1e-6
    assert r.upper - r.lower <= r.sta.epsilon_achieved + 1e-6
    assert 0.5 < storm < 0.99  # the task is neither trivial nor hopeless


# --------------------------------------------------------------------------- the mapping


LABELLED = """
mdp
const int N;
module robot
  x : [0..N] init 0;
  [go] x<N -> 0.5 : (x'=x+1) + 0.5 : (x'=x);
  [] x>0 -> (x'=x-1);
  [] x=1 -> (x'=0);
  [bus] x=N -> (x'=0);
endmodule
label "goal" = x=N;
label "odd" = mod(x, 2) = 1;
label "never" = x > N;
"""


@needs_storm
def test_every_label_is_a_proposition_where_its_expression_holds(tmp_path: Path) -> None:
    game = load_prism(write(tmp_path, LABELLED), constants={"N": 3})
    assert game.proposition_names == {"goal", "odd", "never"}
    assert game.variables == ("x",)
    assert sorted(game.states) == [(0,), (1,), (2,), (3,)]
    for s in game.states:
        x = game.valuation(s)["x"]
        expected = {"goal"} if x == 3 else set()
        expected |= {"odd"} if x % 2 == 1 else set()
        assert game.propositions(s) == expected
    only = load_prism(write(tmp_path, LABELLED), constants={"N": 3}, labels=["odd"])
    assert only.proposition_names == {"odd"}
    assert only.propositions((3,)) == {"odd"}


@needs_storm
def test_action_names_unlabelled_commands_and_events(tmp_path: Path) -> None:
    game = load_prism(write(tmp_path, LABELLED), constants={"N": 3}, events=["bus"])
    assert game.initial == (0,)
    assert game.actions((0,)) == ("go",)
    # x=1: two unlabelled commands, named by their position in module robot
    assert set(game.actions((1,))) == {"go", "robot_cmd2", "robot_cmd3"}
    # the event is never offered to the robot
    assert game.actions((3,)) == ("robot_cmd2",)
    assert game.event_names == {"bus"}
    check = check_game(game, events=["bus"])
    assert check.states == 4 and check.actions == {"go", "robot_cmd2", "robot_cmd3"}
    # robot first, then the event's command where enabled: from x=2, go reaches x=3
    # (bus fires there: back to 0) or stays at x=2 (bus not enabled: unchanged)
    assert dict(game.successors((2,), "go", frozenset({"bus"}))) == pytest.approx(
        {(0,): 0.5, (2,): 0.5})
    assert dict(game.successors((2,), "go", frozenset())) == pytest.approx(
        {(3,): 0.5, (2,): 0.5})
    # an event the file does not have changes nothing
    assert dict(game.successors((2,), "go", frozenset({"other"}))) == pytest.approx(
        {(3,): 0.5, (2,): 0.5})
    # without events=..., [bus] is an ordinary robot action
    plain = load_prism(write(tmp_path, LABELLED), constants={"N": 3})
    assert set(plain.actions((3,))) == {"robot_cmd2", "bus"}


@needs_storm
def test_deadlock_and_overlapping_guards_get_distinct_names(tmp_path: Path) -> None:
    text = """
mdp
module m
  x : [0..2] init 0;
  [a] x=0 -> (x'=1);
  [a] x=0 -> (x'=2);
endmodule
"""
    game = load_prism(write(tmp_path, text))
    assert set(game.actions((0,))) == {"a@m_cmd1", "a@m_cmd2"}
    assert dict(game.successors((0,), "a@m_cmd2", frozenset())) == {(2,): 1.0}
    assert game.actions((1,)) == (DEADLOCK_ACTION,)
    assert dict(game.successors((1,), DEADLOCK_ACTION, frozenset())) == {(1,): 1.0}


@needs_storm
def test_synchronised_event_across_modules(tmp_path: Path) -> None:
    text = """
mdp
module door
  open : bool init false;
  [opened] !open -> (open'=true);
endmodule
module robot
  x : [0..1] init 0;
  [opened] true -> 0.5 : (x'=0) + 0.5 : (x'=1);
  [wait] true -> true;
endmodule
"""
    game = load_prism(write(tmp_path, text), events=["opened"])
    s0 = game.initial
    assert game.valuation(s0) == {"open": False, "x": 0}
    out = {tuple(game.valuation(s).values()): p
           for s, p in game.successors(s0, "wait", frozenset({"opened"}))}
    assert out == pytest.approx({(True, 0): 0.5, (True, 1): 0.5})


# --------------------------------------------------------------------------- errors


@needs_storm
def test_errors_name_the_file_and_the_problem(tmp_path: Path) -> None:
    with pytest.raises(WorldError, match="no such PRISM file"):
        load_prism(tmp_path / "missing.prism")
    with pytest.raises(WorldError, match="JANI files are not supported"):
        load_prism(write(tmp_path, "{}", "m.jani"))
    bad = write(tmp_path, "mdp\nmodule m\n x : [0..2] init 0\n [] x<1 -> (x'=x+1);\nendmodule\n")
    with pytest.raises(WorldError, match=r"m\.prism:4:2: PRISM parse error: expecting \";\" at"):
        load_prism(bad)
    src = write(tmp_path, LABELLED)
    with pytest.raises(WorldError, match=r"constants N have no value"):
        load_prism(src)
    with pytest.raises(WorldError, match=r"constant 'N' must be an integer, got 2.5"):
        load_prism(src, constants={"N": 2.5})
    with pytest.raises(WorldError, match=r"constant 'M' is not declared"):
        load_prism(src, constants={"N": 2, "M": 1})
    with pytest.raises(WorldError, match=r"label 'gaol' is not defined \(labels: goal, odd"):
        load_prism(src, constants={"N": 2}, labels=["gaol"])
    with pytest.raises(WorldError, match=r"event 'train' is not an action of the file"):
        load_prism(src, constants={"N": 2}, events=["train"])
    dtmc = write(tmp_path, "dtmc\nmodule m\n x : [0..1] init 0;\n [] true -> (x'=1);\nendmodule\n")
    with pytest.raises(WorldError, match="is a DTMC, a game needs an mdp"):
        load_prism(dtmc)
    only_event = write(tmp_path, "mdp\nmodule m\n x : [0..1] init 0;\n [e] x=0 -> (x'=1);\n"
                       " [go] x=1 -> true;\nendmodule\n")
    with pytest.raises(WorldError, match=r"at state \[x=0\] only event commands"):
        load_prism(only_event, events=["e"])
    twice = write(tmp_path, "mdp\nmodule m\n x : [0..1] init 0;\n [e] true -> (x'=1);\n"
                  " [e] true -> (x'=0);\n [go] true -> true;\nendmodule\n")
    with pytest.raises(WorldError, match=r"event 'e' has two enabled commands"):
        load_prism(twice, events=["e"])


def test_missing_stormpy_says_how_to_install(monkeypatch, tmp_path: Path) -> None:
    monkeypatch.setitem(sys.modules, "stormpy", None)  # import stormpy raises ImportError
    with pytest.raises(WorldError, match=r"pip install -e '\.\[prism\]'"):
        load_prism(write(tmp_path, LABELLED))


def test_optional_dependencies_are_not_imported_with_the_package() -> None:
    code = (
        "import sys, mitld_lp, mitld_lp.worlds, mitld_lp.worlds.prism, mitld_lp.worlds.gym\n"
        "bad = {'stormpy', 'gymnasium'} & set(sys.modules)\n"
        "assert not bad, bad\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


# --------------------------------------------------------------------------- model files


def _toml(file: Path, extra: str = "", spec: str = "F[0,4] goal") -> str:
    return f'name = "t"\nspec = "{spec}"\n[prism]\nfile = "{file}"\n{extra}'


@needs_storm
def test_model_file_prism_table(tmp_path: Path) -> None:
    src = write(tmp_path, LABELLED)
    m = loads_model(_toml(src, "constants = { N = 2 }\n"))
    assert m.game.proposition_names == {"goal", "odd", "never"}
    # a relative path is read from the model file's folder
    (tmp_path / "m.toml").write_text(_toml(Path("m.prism"), "constants = { N = 2 }\n"))
    assert load_model(tmp_path / "m.toml").game.initial == (0,)
    cases = [
        ("constants = { N = 2 }\nlabels = [\"goal\", \"x\"]\n", r"prism: .*label 'x' is not"),
        ("constants = { N = \"2\" }\n", r"prism.constants.N: must be a boolean or a number"),
        ("constants = { N = 2 }\nfile2 = 1\n", r"prism.file2: unknown key"),
    ]
    for extra, message in cases:
        with pytest.raises(ModelError, match=message):
            loads_model(_toml(src, extra))
    with pytest.raises(ModelError, match=r"prism: .*no such PRISM file"):
        loads_model(_toml(tmp_path / "nope.prism"))
    with pytest.raises(ModelError, match=r"spec: proposition 'gaol' is neither a label"):
        loads_model(_toml(src, "constants = { N = 2 }\n", spec="F[0,4] gaol"))
    # an event of the spec that is also a PRISM action must be listed as an event
    with pytest.raises(ModelError, match=r"prism.events: PRISM action 'bus'"):
        loads_model(_toml(src, "constants = { N = 2 }\n",
                          spec="D[geometric(0.5)] bus & F[0,4] goal"))
    # words of the spec that are not propositions (operators, distributions) are fine
    poisson = write(tmp_path, LABELLED.replace("[go]", "[poisson]"), "p.prism")
    assert loads_model(_toml(poisson, "constants = { N = 2 }\n",
                             spec="D[poisson(2)] e & F[0,4] goal")).events == {"e"}
    m = loads_model(_toml(src, "constants = { N = 2 }\nevents = [\"bus\"]\n",
                          spec="D[geometric(0.5)] bus & F[0,4] goal"))
    assert m.events == {"bus"} and "bus" not in m.game.actions((2,))


@needs_storm
def test_corridor_tightest_deadline_by_hand() -> None:
    # F[0,4] goal: four moves east must all succeed (0.8 each) and the door must be
    # open when the robot stands before it after step 3, i.e. open by step 3:
    # 0.8^4 * P(K <= 3) with K = 1 + Poisson(2).
    m = load_model(MODELS / "corridor.toml")
    r = synthesize(Model.from_game(m.game, "D[poisson(2)] opened & F[0,4] goal"))
    hand = 0.8**4 * float(stats.poisson.cdf(2, 2))
    assert r.lower - 1e-9 <= hand <= r.upper + 1e-9
    assert r.upper - r.lower <= r.sta.epsilon_achieved + 1e-9


# --------------------------------------------------------------------------- the copy


RICH = """
mdp
global g : [0..2] init 0;
module door
  open : bool init false;
  [opened] !open -> 0.5 : (open'=true) + 0.5 : true;
  [close] open -> (open'=false);
endmodule
module robot
  x : [0..3] init 0;
  [go] x<3 -> 0.7 : (x'=x+1) + 0.3 : true;
  [go] x=1 -> (x'=0);
  [] x>0 -> (x'=x-1) & (g'=min(g+1, 2));
  [opened] true -> true;
  [close] true -> (x'=0);
endmodule
label "goal" = x=3;
label "gate" = open & x>=2;
"""


def _storm_by_state(source: Path) -> dict:
    """Storm's MDP read one state and one choice at a time through stormpy's own
    accessors (the route the arrays of the game must agree with): valuation ->
    (labels, [(action or None, command positions, {valuation: probability})])."""
    import json

    import stormpy
    program = stormpy.parse_prism_program(str(source))
    options = stormpy.BuilderOptions()
    options.set_build_all_labels()
    options.set_build_choice_labels()
    options.set_build_choice_origins()
    options.set_build_state_valuations()
    model = stormpy.build_model(program, options=options)
    position = {c.global_index: f"{m.name}_cmd{k}" for m in program.modules
                for k, c in enumerate(m.commands, start=1)}
    order = ["g", "open", "x"]

    def value(s: int) -> tuple:
        v = json.loads(str(model.state_valuations.to_json(s)))
        return tuple(v[name] for name in order)

    out = {}
    matrix = model.transition_matrix
    for s in range(model.nr_states):
        rows = []
        for c in range(matrix.get_row_group_start(s), matrix.get_row_group_end(s)):
            labels = model.choice_labeling.get_labels_of_choice(c)
            origin = "+".join(position[i] for i in sorted(model.choice_origins.get_command_set(c)))
            dist = {value(e.column): e.value for e in matrix.get_row(c)}
            rows.append((next(iter(labels)) if labels else None, origin, dist))
        props = set(model.labeling.get_labels_of_state(s)) & {"goal", "gate"}
        out[value(s)] = (props, rows)
    return out


@needs_storm
def test_arrays_agree_with_storm_read_state_by_state(tmp_path: Path) -> None:
    src = write(tmp_path, RICH)
    game = load_prism(src, events=["opened"])
    storm = _storm_by_state(src)
    assert game.variables == ("g", "open", "x")
    assert set(game.states) == set(storm) and len(game.states) == len(storm)
    for state, (props, rows) in storm.items():
        assert game.propositions(state) == props
        robot = [(a, o, d) for a, o, d in rows if a != "opened"]
        named = [a if a is not None else o for a, o, _ in robot]
        names = [f"{n}@{o}" if named.count(n) > 1 else n
                 for n, (_, o, _) in zip(named, robot, strict=True)]
        assert sorted(game.actions(state)) == sorted(names)
        assert sum(a == "opened" for a, _, _ in rows) <= 1
        for name, (_, _, dist) in zip(names, robot, strict=True):
            assert dict(game.successors(state, name, frozenset())) == pytest.approx(dist)
            # then the event at each state reached, where its command is enabled
            moved: dict = {}
            for t, p in dist.items():
                after = [d for a, _, d in storm[t][1] if a == "opened"]
                for u, q in (after[0] if after else {t: 1.0}).items():
                    moved[u] = moved.get(u, 0.0) + p * q
            got = dict(game.successors(state, name, frozenset({"opened", "other"})))
            assert got == pytest.approx(moved)
    # x=1: the two [go] commands overlap and are told apart by their commands
    assert {"go@robot_cmd1", "go@robot_cmd2"} <= set(game.actions((0, False, 1)))


@needs_storm
def test_program_whose_variables_storm_made_constants(tmp_path: Path) -> None:
    # x is never assigned: Storm makes it a constant, the MDP has one state, no variables
    game = load_prism(write(tmp_path, 'mdp\nmodule m\n x : [0..2] init 1;\n [] true -> true;\n'
                                      'endmodule\nlabel "one" = x=1;\n'))
    assert game.variables == () and game.states == ((),) and game.initial == ()
    assert game.propositions(()) == {"one"} and game.actions(()) == ("m_cmd1",)
    assert game.successors((), "m_cmd1", frozenset()) == (((), 1.0),)
