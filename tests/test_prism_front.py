"""The own PRISM parse (prism_parse, prism_expr, prism_front, prism_own) against stormpy's.

Each small program is loaded by ``load_prism`` as it loads now (the own parse) and with
the own parse turned off (stormpy parses it, as before): the two worlds must be the same
(states in order, initial state, actions, rows compared exactly, labels).  Expressions'
values are checked against PRISM's semantics worked by hand.
"""

from __future__ import annotations

import subprocess
import sys
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("stormpy")
pytest.importorskip("numba")

from mitld_lp.worlds import WorldError, prism  # noqa: E402
from mitld_lp.worlds.prism_explore import BUILDER_ENV  # noqa: E402
from mitld_lp.worlds.prism_expr import evaluate  # noqa: E402
from mitld_lp.worlds.prism_front import Declined, resolve  # noqa: E402
from mitld_lp.worlds.prism_own import own_program  # noqa: E402
from mitld_lp.worlds.prism_parse import Outside, PrismSyntaxError, parse, parse_expression  # noqa: E402

RENAMED = """mdp
const int N = 3;
formula free = y = 0;
module a
  x : [0..N] init 0;
  [go] x < N & free -> 0.5 : (x'=x+1) + 0.5 : (x'=x);
  [sync] x = N -> (x'=0);
  [] x = 1 -> (x'=2);
endmodule
module b = a [x=y, y=x, go=run] endmodule
label "both" = x = N & y = N;
"""

ARITHMETIC = """mdp
const int K;
const double p;
const bool B;
const double q = 1 - p;
module m
  x : [-3..6] init -2;
  s : bool init false;
  [a] x < 6 & B -> q : (x' = x < 0 ? x + 2 : min(x + 1, 6)) + p : (x' = mod(x, K) - 1);
  [b] x / 2 > 1.4 -> 1/3 : (x' = floor(x / 4)) + 2/3 : (x' = ceil(x / 4) + 1);
  [c] s | x = pow(2, 2) -> 0.1 + 0.2 : (s' = !s) + 0.7 : (x' = max(-3, x - 3));
  [d] x = 6 -> (s' = true);
endmodule
label "low" = x <= -1;
"""

DROPPED = """mdp
const int L = 1;
module m
  x : [0..4] init 0;
  u : [0..3] init 2;
  [] L > 2 -> (x'=4);
  [] x < 4 -> (x'=x+u-1) & (u'=u);
  [] x = 4 -> (x'=0);
endmodule
formula far = x >= 3;
"""


def _load(path: Path, own: bool, monkeypatch: pytest.MonkeyPatch, **kw):
    with monkeypatch.context() as m:
        m.setenv(BUILDER_ENV, "own")
        if not own:
            m.setattr(prism, "own_load", lambda *a, **k: None)
        return prism.load_prism(path, **kw)


def _same(a, b) -> None:
    ta, tb = a._tables, b._tables
    assert a.variables == b.variables
    assert [tuple(s) for s in a.states] == [tuple(s) for s in b.states]
    assert a.initial == b.initial
    for name in ("choices", "branches", "targets", "probabilities"):
        assert np.array_equal(getattr(ta, name), getattr(tb, name)), name
    assert a.proposition_names == b.proposition_names
    for s in a.states:
        assert a.propositions(s) == b.propositions(s)
        assert a.actions(s) == b.actions(s)


def _both(tmp_path, monkeypatch, text, **kw):
    path = tmp_path / "m.prism"
    path.write_text(text, encoding="utf-8")
    mine = _load(path, True, monkeypatch, **kw)
    assert "stormpy" not in str(mine.recipe) and mine.recipe is not None
    _same(mine, _load(path, False, monkeypatch, **kw))
    return mine


def test_renamed_module_reads_formulas_under_its_renaming(tmp_path, monkeypatch):
    program, labels = own_program(RENAMED, {}, {})
    assert [m.name for m in program.modules] == ["a", "b"]
    assert labels == ["both", "free"]  # the Boolean formula is a label too
    run = program.modules[1].commands[0]
    assert run.action_name == "run" and "(x = 0)" in str(run.guard_expression)
    game = _both(tmp_path, monkeypatch, RENAMED)
    # by hand: a moves only while y = 0 and b only while x = 0, so one of them stays 0:
    # (0,0), (1,0), (2,0), (3,0), (0,1), (0,2), (0,3); sync needs x = y = 3, never
    assert sorted(tuple(s) for s in game.states) == [(0, 0), (0, 1), (0, 2), (0, 3),
                                                     (1, 0), (2, 0), (3, 0)]
    assert {"go", "run"} <= game.robot_actions() and "sync" not in game.robot_actions()


def test_arithmetic_and_given_constants(tmp_path, monkeypatch):
    for given in ({"K": 2, "p": 0.25, "B": True}, {"K": 3, "p": 0.1, "B": False}):
        _both(tmp_path, monkeypatch, ARITHMETIC, constants=given)


def test_dropped_command_and_constant_variable(tmp_path, monkeypatch):
    program, _ = own_program(DROPPED, {}, {})
    (m,) = program.modules
    assert [v.name for v in m.integer_variables] == ["x"]  # u is never assigned
    assert [c.global_index for c in m.commands] == [1, 2]  # the first is dropped
    _both(tmp_path, monkeypatch, DROPPED)


def test_define_labels_and_chosen(tmp_path, monkeypatch):
    game = _both(tmp_path, monkeypatch, DROPPED, define={"high": "x > 1 & far"},
                 labels=["high", "far"])
    assert game.proposition_names == {"high", "far"}
    assert "high" in game.propositions((3,)) and "high" not in game.propositions((1,))


@pytest.mark.parametrize("text, value", [
    ("1 + 2 * 3", 7), ("2 - 1 - 1", 0), ("7 / 2", Fraction(7, 2)), ("mod(-3, 2)", 1),
    ("mod(5, 3)", 2), ("floor(-7 / 2)", -4), ("ceil(7 / 2)", 4), ("pow(2, 3)", 8),
    ("true ? 1 : 0 + 5", 1), ("false | true & false", False), ("!false & false", False),
    ("1 < 2 = true", True), ("max(1, 2, 3) - min(4, 0.5)", Fraction(5, 2)),
    ("false => false | true", True),  # (false => false) | true, as Storm reads it
])
def test_expression_values_by_hand(text, value):
    got = evaluate(resolve(parse_expression(text), {}), {})
    assert got == value and type(got) is type(value)


def test_syntax_error_has_line_and_column():
    with pytest.raises(PrismSyntaxError) as info:
        parse("mdp\nmodule m\n  x : [0..2] init 0;\n  [] x < -> (x'=1);\nendmodule\n")
    assert (info.value.line, info.value.column) == (4, 10)
    with pytest.raises(Outside):
        parse("mdp\nmodule m\n x : [0..1];\n [] true -> (x'=1);\nendmodule\ninit x=0 endinit\n")
    with pytest.raises(Declined):
        own_program("mdp\nmodule m\n x : [0..1];\n [] x -> (x'=1);\nendmodule\n", {}, {})


def test_errors_are_storms_as_before(tmp_path, monkeypatch):
    bad = tmp_path / "bad.prism"
    bad.write_text("mdp\nmodule m\n  x : [0..2] init 0;\n  [] x < -> (x'=1);\nendmodule\n")
    with pytest.raises(WorldError, match=r"bad\.prism:4:\d+: PRISM parse error"):
        _load(bad, True, monkeypatch)
    out = tmp_path / "out.prism"
    out.write_text("mdp\nmodule m\n  x : [0..2] init 0;\n  [] true -> (x'=x+1);\nendmodule\n")
    with pytest.raises(WorldError) as mine:
        _load(out, True, monkeypatch)
    with pytest.raises(WorldError) as theirs:
        _load(out, False, monkeypatch)
    assert str(mine.value) == str(theirs.value) and "outside its range" in str(mine.value)


def test_a_load_imports_no_stormpy(tmp_path):
    path = tmp_path / "m.prism"
    path.write_text(RENAMED, encoding="utf-8")
    code = ("import sys; from mitld_lp.worlds.prism import load_prism; "
            f"g = load_prism({str(path)!r}); print(len(g.states), 'stormpy' in sys.modules)")
    got = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, env={**__import__("os").environ, BUILDER_ENV: "own"})
    assert got.stdout.split() == ["7", "False"]
