"""A PRISM file with a P property, solved without stormpy (branch ``door-83``).

* The :class:`~mitld_lp.worlds.prism_symbols.Symbols` our own parse gives (labels,
  constants, variables, formulas, printed as Storm prints its program) are the very
  record Storm's program gives (:func:`~mitld_lp.worlds.property_own.symbols_of_storm`).
* ``mitld-lp solve FILE.prism --prop ...`` (a property, and a properties file with a
  name) and the Python API (``read_program``, ``read_any``, ``pose_property``,
  ``load_prism``) import no ``stormpy`` module, and answer what Storm's route (forced:
  ``MITLD_PRISM_BUILDER=storm``) answers; the bracket holds stormpy's own model check.
* Bad input (an unknown label, a constant without a value, an undeclared ``--const``,
  a name the program does not define) gives the same message and exit code on both
  routes.
* A task of bounded horizon is loaded by the own explorer when the world is whole
  within the lazy route's first exploration: the same world as Storm's lazy route;
  a larger world still goes to that route.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("stormpy")
pytest.importorskip("numba")

from mitld_lp.worlds.prism_explore import BUILDER_ENV  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
CORRIDOR = ROOT / "models" / "corridor.prism"

# constants defined through others, an open one, formulas over formulas, every
# operator Storm's printing puts its own way (!(..), -(..), min, pow, mod, ?:, a decimal)
PROGRAM = """mdp
const int N = 4;
const int M = N*2;
const double p = 0.25;
const double q = 1 - p;
const int K;
const int P2 = floor(pow(2, K)) - 1;
formula f = x < N-1 & !b;
formula g = x + 1;
formula h = f | g > M/3;
module m
  x : [0..N] init 0;
  b : bool init false;
  [a] x<N -> p:(x'=x+1) + q:(x'=x);
  [c] true -> (b'=!b);
endmodule
label "a" = x = 2-1;
label "b" = x=1 | false;
label "c" = !(x=1) & b != false;
label "d" = -1 < x & x >= -K;
label "e" = mod(x,2)=0 & min(x,1)=max(x,0) & floor(p)=0;
label "f" = (x=1 ? true : false) => f;
label "g" = g > 0.5 & x*2/3 != 1 & h;
label "i" = x = 1 - 1/10 | x = 1.5e1;
"""


def _storm_symbols(path: Path) -> object:
    import stormpy

    from mitld_lp.worlds.property_own import symbols_of_storm

    program = stormpy.parse_prism_program(str(path))
    return symbols_of_storm(program, {lab.name: str(lab.expression) for lab in program.labels})


@pytest.mark.parametrize("name", ["program", "corridor", "qvbs_like"])
def test_own_symbols_are_storms(tmp_path: Path, name: str) -> None:
    from mitld_lp.worlds.prism_parse import parse
    from mitld_lp.worlds.prism_symbols import own_symbols

    if name == "corridor":
        path, given = CORRIDOR, {"open_at_start": True}
    else:
        path = tmp_path / f"{name}.prism"
        text = PROGRAM if name == "program" else PROGRAM.replace("const int K;",
                                                                  "const int K = 3;")
        path.write_text(text, encoding="utf-8")
        given = {"K": 2} if name == "program" else {}
    ours = own_symbols(parse(path.read_text(encoding="utf-8")), given)
    assert ours is not None
    assert ours == _storm_symbols(path)
    if name == "program":  # Storm's printing, as its program prints (by hand, from Storm)
        assert ours.labels["d"] == "((-1 < x) & (x >= -(K)))"
        assert ours.constants["q"] == ("double", "(1 - 1/4)")


def test_own_symbols_decline_what_storm_must_word(tmp_path: Path) -> None:
    """A program the front would leave to Storm gives no symbols: Storm reads it."""
    from mitld_lp.worlds.prism_parse import parse
    from mitld_lp.worlds.prism_symbols import own_symbols, read_own_program

    parsed = parse(PROGRAM)
    assert own_symbols(parsed, {}) is None  # K has no value
    assert own_symbols(parsed, {"K": True}) is None  # a value of another type
    bad = tmp_path / "bad.prism"
    bad.write_text(PROGRAM.replace('label "a" = x = 2-1;', 'label "a" = x + 1;'))
    assert read_own_program(str(bad), {"K": 2}) is None  # a label that is not Boolean
    equal = tmp_path / "eq.prism"  # Storm shortens b = true to b; our simplify does not
    equal.write_text(PROGRAM.replace('x=1 | false', 'b = true'))
    assert read_own_program(str(equal), {"K": 2}) is None


def test_read_program_parses_with_storm_only_when_asked(monkeypatch) -> None:
    from mitld_lp.worlds.properties import read_program

    monkeypatch.delenv(BUILDER_ENV, raising=False)
    own = read_program(str(CORRIDOR), {"open_at_start": True})
    assert own.symbols is not None and own._program is None  # noqa: SLF001
    storm = read_program(str(CORRIDOR), storm=True)
    assert storm.symbols is None
    assert own.labels == storm.labels == {"goal": "(x = N)", "at_door": "(x = (N - 1))"}
    assert own.constants == storm.constants and own.chain is storm.chain is False
    assert str(own.program) == str(storm.program)  # Storm's parse, on first use
    monkeypatch.setenv(BUILDER_ENV, "storm")
    assert read_program(str(CORRIDOR), {"open_at_start": True}).symbols is None


# ------------------------------------------------------------------ processes

CLI_CHILD = r"""
import json, sys
from mitld_lp.startup import command
sys.argv = ["mitld-lp", *json.loads(sys.argv[1])]
code = 0
try:
    command()
except SystemExit as exc:
    code = exc.code
stormpy = sorted(m for m in sys.modules if m.split(".")[0] == "stormpy")
print("CHILD " + json.dumps({"code": code, "stormpy": stormpy}), file=sys.stderr)
"""


def _cli(args: list[str], builder: str, cwd: Path) -> tuple[int, str, str, list[str]]:
    """``(exit code, stdout, the error lines, stormpy's modules loaded)`` of the command."""
    env = dict(os.environ, PYTHONPATH=str(ROOT), **{BUILDER_ENV: builder})
    done = subprocess.run([sys.executable, "-c", CLI_CHILD, json.dumps(args)],
                          capture_output=True, text=True, env=env, cwd=str(cwd))
    lines = done.stderr.strip().splitlines()
    assert lines and lines[-1].startswith("CHILD "), done.stderr[-3000:]
    out = json.loads(lines[-1][6:])
    errors = "\n".join(line for line in lines if "error:" in line)
    return out["code"], done.stdout, errors, out["stormpy"]


def _storm_check(formula: str, tmp_path: Path) -> float:
    """stormpy's own model check of ``formula`` on the corridor with its door open from
    the start (the constant written into a copy; the door not involved)."""
    import stormpy

    copy = tmp_path / "open.prism"
    copy.write_text(CORRIDOR.read_text(encoding="utf-8").replace(
        "const bool open_at_start;", "const bool open_at_start = true;"), encoding="utf-8")
    program = stormpy.parse_prism_program(str(copy))
    props = stormpy.parse_properties(formula, program)
    model = stormpy.build_model(program, props)
    result = stormpy.model_checking(model, props[0])
    return float(result.get_value_vector()[model.initial_states[0]])


def test_cli_property_and_named_property_import_no_stormpy(tmp_path: Path) -> None:
    props = tmp_path / "corridor.props"
    props.write_text('// two properties\n"soon": Pmin=? [F<=2 "goal"];\n'
                     '"reach": Pmax=? [F<=6 "goal"];\n', encoding="utf-8")
    expected = _storm_check('Pmax=? [F<=6 "goal"]', tmp_path)
    # by hand: the robot needs 4 east moves, each 0.8, within 6 steps with the door
    # open: P(at least 4 successes in 6 trials of 0.8)
    assert expected == pytest.approx(15 * 0.8**4 * 0.2**2 + 6 * 0.8**5 * 0.2 + 0.8**6)
    base = [str(CORRIDOR), "--const", "open_at_start=true", "--json"]
    for prop in (["Pmax=? [F<=6 \"goal\"]"], [str(props), "reach"]):
        answers = {}
        for builder in ("own", "storm"):
            code, out, errors, storm = _cli(["solve", *base, "--prop", *prop], builder,
                                            tmp_path)
            assert code == 0 and not errors, errors
            answers[builder] = json.loads(out.strip().splitlines()[-1])
            assert bool(storm) == (builder == "storm"), (builder, storm)
        mine, theirs = answers["own"], answers["storm"]
        assert mine["certified"] and mine["lower"] <= expected <= mine["upper"]
        for key in ("formula", "spec", "labels", "lower", "upper", "certified"):
            assert mine[key] == theirs[key], key
        assert mine["property"] == ("1" if len(prop) == 1 else "reach")


@pytest.mark.parametrize("prop, const, words", [
    ('Pmax=? [F "nope"]', "open_at_start=true", "label 'nope' is not defined"),
    ('Pmax=? [F "goal"]', "", "constants open_at_start have no value"),
    ('Pmax=? [F<=6 "goal"]', "open_at_start=true,zz=1", "constant 'zz' is not declared"),
    ('Pmax=? [F "goal" & ff]', "open_at_start=true", "property parse error"),
    ('Pmax=? [F x = N & near]', "open_at_start=true", "property parse error"),
    ('const int K; Pmax=? [F<=K "goal"]', "open_at_start=true",
     "constants K have no value: give them with --const"),
])
def test_bad_input_is_worded_the_same_on_both_routes(tmp_path: Path, prop: str,
                                                     const: str, words: str) -> None:
    args = ["solve", str(CORRIDOR), "--prop", prop] + (["--const", const] if const else [])
    mine = _cli(args, "own", tmp_path)
    theirs = _cli(args, "storm", tmp_path)
    assert mine[0] == theirs[0] == 2
    assert mine[2] == theirs[2] and words in mine[2]
    if "label" in words or "zz" in words:  # read by ours: Storm never loaded
        assert mine[3] == []


API_CHILD = r"""
import json, sys
from mitld_lp.logic.parser import parse
from mitld_lp.model import Model
from mitld_lp.synthesis import pose, solve
from mitld_lp.worlds.prism import load_prism
from mitld_lp.worlds.properties import pick, pose_property, read_program
from mitld_lp.worlds.property_own import read_any

path, text = sys.argv[1], sys.argv[2]
constants = {"open_at_start": True}
program = read_program(path, constants)
(name, prop), = pick(read_any(program, text, "P", constants), None, "P")
q = pose_property(name, prop, program.labels, program.reserved, chain=program.chain)
game = load_prism(path, constants=constants, define=q.define, task=parse(q.spec))
r = solve(pose(Model.from_game(game, q.spec, name="c", objective=q.objective)))
stormpy = sorted(m for m in sys.modules if m.split(".")[0] == "stormpy")
print(json.dumps({"spec": q.spec, "define": q.define, "lower": r.lower, "upper": r.upper,
                  "certified": r.certified, "stormpy": stormpy}))
"""


def test_python_api_imports_no_stormpy(tmp_path: Path) -> None:
    formula = 'Pmax=? [F<=6 "goal" & x > 2]'
    env = dict(os.environ, PYTHONPATH=str(ROOT), **{BUILDER_ENV: "own"})
    done = subprocess.run([sys.executable, "-c", API_CHILD, str(CORRIDOR), formula],
                          capture_output=True, text=True, env=env, cwd=str(tmp_path))
    assert done.returncode == 0, done.stderr[-3000:]
    out = json.loads(done.stdout.strip().splitlines()[-1])
    assert out["stormpy"] == []
    # the label written out as Storm prints it (its program's text of "goal")
    assert out["spec"] == "F[0,6] phi1" and out["define"] == {"phi1": "((x = N)) & (x > 2)"}
    expected = _storm_check(formula, tmp_path)
    assert out["certified"] and out["lower"] <= expected <= out["upper"]


# ------------------------------------------------------------------ the bounded load

def _tables(game: object) -> tuple:
    t = game._tables  # noqa: SLF001 - the world compared whole
    states = [game.states[i] for i in range(len(game.states))]
    return (game.variables, states, game.initial, t.choices.tolist(), t.branches.tolist(),
            t.targets.tolist(), t.probabilities.tolist(), sorted(game.proposition_names),
            [sorted(game.propositions(s)) for s in states],
            [game.actions(s) for s in states])


@pytest.mark.parametrize("task", ["F[0,6] goal", "F[0,2] at_door", "G[0,3] !goal"])
def test_bounded_task_own_world_is_storms_lazy_one(monkeypatch, task: str) -> None:
    from mitld_lp.logic.parser import parse
    from mitld_lp.worlds import prism

    calls = []
    real = prism.own_load
    monkeypatch.setattr(prism, "own_load", lambda *a, **k: calls.append(real(*a, **k))
                        or calls[-1])
    worlds = {}
    for builder in ("own", "storm"):
        monkeypatch.setenv(BUILDER_ENV, builder)
        worlds[builder] = prism.load_prism(CORRIDOR, constants={"open_at_start": True},
                                           task=parse(task))
    assert calls[0] is not None and calls[1] is None  # the own explorer, then Storm's
    assert type(worlds["own"]) is type(worlds["storm"]) is prism.PrismGame
    assert _tables(worlds["own"]) == _tables(worlds["storm"])


def test_bounded_task_past_the_first_exploration_goes_lazy(monkeypatch, tmp_path) -> None:
    from mitld_lp.logic.parser import parse
    from mitld_lp.worlds import prism

    path = tmp_path / "line.prism"
    path.write_text('mdp\nmodule m\n  x : [0..40] init 0;\n  [go] x < 40 -> 0.5 : '
                    "(x'=x+1) + 0.5 : (x'=x);\nendmodule\nlabel \"end\" = x = 40;\n")
    monkeypatch.setenv(BUILDER_ENV, "own")
    game = prism.load_prism(path, task=parse("F[0,3] end"), first_states=8)
    assert isinstance(game, prism.LazyPrismGame)  # Storm's lazy route, as before
    whole = prism.load_prism(path, task=parse("F[0,3] end"), first_states=64)
    assert type(whole) is prism.PrismGame and len(whole.states) == 41


FUNCTIONS = """mdp
const int N = 3;
formula least = min(x=1 ? y : N+1, y=2 ? x : N+1);
formula most = max(x, y);
formula half = floor(x/2) + ceil(y/2);
module m
  x : [0..N] init 0;
  y : [0..N] init 0;
  [a] x<N -> 0.5:(x'=x+1) + 0.5:(y'=min(y+1, N));
endmodule
label "end" = x = N;
"""


@pytest.mark.parametrize("prop", [
    "Pmax=? [F least < 2]", "Pmin=? [F most = N & half > 1]", 'Pmax=? [!"end" U least=1]',
])
def test_formulas_over_functions_are_read_as_storms_reader_reads_them(tmp_path: Path,
                                                                      prop: str) -> None:
    """csma's ``min(c ? a : b, ...)`` formula: read and posed by ours as by Storm's."""
    from mitld_lp.worlds.properties import pick, pose_property, read_program, read_properties
    from mitld_lp.worlds.property_own import OwnProperty, read_any

    path = tmp_path / "functions.prism"
    path.write_text(FUNCTIONS, encoding="utf-8")
    ours = read_program(str(path), {})
    (name, mine), = pick(read_any(ours, prop, "P", {}), None, "P")
    assert isinstance(mine, OwnProperty) and ours._program is None  # noqa: SLF001
    storm = read_program(str(path), storm=True)
    (_, theirs), = pick(read_properties(storm.program, prop, "P", {}), None, "P")
    assert pose_property(name, mine, ours.labels) == pose_property(name, theirs, storm.labels)
