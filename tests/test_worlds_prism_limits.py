"""PRISM text at the edges of what Storm takes (issue 41).

A deep or long expression (a guard in 2,000 parentheses, a ``[labels]`` entry of 2,000
disjuncts) used to reach Storm's parser, which recursed in this process until the stack
overflowed (exit 139, no message): the scan of :mod:`mitld_lp.worlds.prism_depth` refuses
it first, naming the file, the place and the limit.  The depths are counted here by hand
from the module's rule (a group: 1 + its operators + its deepest part)."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest

from mitld_lp.worlds.prism_depth import MAX_DEPTH, ExpressionDepth

ROOT = Path(__file__).resolve().parent.parent
needs_storm = pytest.mark.skipif(importlib.util.find_spec("stormpy") is None,
                                 reason="needs stormpy: pip install -e '.[prism]'")

CORRIDOR = (ROOT / "models" / "corridor.prism").read_text()


def cli(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-m", "mitld_lp", *args], env=env, cwd=cwd,
                          capture_output=True, text=True, timeout=120)


def corridor_model(folder: Path, prism_text: str, labels: str = "") -> Path:
    (folder / "c.prism").write_text(prism_text)
    model = folder / "c.toml"
    model.write_text('name = "c"\nspec = "D[door] opened & F[0,7] goal"\n[prism]\n'
                     'file = "c.prism"\nconstants = { open_at_start = false }\n'
                     'events = ["opened"]\n[distributions]\ndoor = { poisson = 2 }\n'
                     + (f"[labels]\n{labels}\n" if labels else ""))
    return model


def nested(n: int) -> str:
    return "(" * n + "x" + ")" * n


def test_depth_counts_parentheses_and_operators_by_hand() -> None:
    # n parentheses around a name: n groups of no operator, each 1 deeper
    assert ExpressionDepth().deepest(nested(MAX_DEPTH)) is None
    deep = ExpressionDepth().deepest("label \"a\" = x=1;\n  " + nested(MAX_DEPTH + 1))
    assert deep is not None and (deep.line, deep.column) == (2, 3)
    # n disjuncts "x=1": n-1 "|" and n "=" at one level, 2n - 1 operators
    assert ExpressionDepth().deepest(" | ".join(["x=1"] * 500)) is None  # 999
    assert ExpressionDepth().deepest(" | ".join(["x=1"] * 501)) is not None  # 1001
    # a sum of updates is no exception: every "+", ":" and "=" counts
    updates = " + ".join(["0.01 : (x'=1)"] * 100)  # 99 + 100 at the top, 1 inside each
    assert ExpressionDepth().deepest(f"[a] true -> {updates};") is None


def test_a_formula_counts_as_deep_as_its_definition_where_it_is_used() -> None:
    scan = ExpressionDepth()
    text = "formula f = " + " & ".join(["y"] * 401) + ";\n"  # 400 operators
    assert scan.deepest(text) is None and scan.named == {"f": 400}
    # (f | f) is 1 + 1 + 400 deep; 599 more operators beside it: 1001
    assert scan.deepest("(f | f)" + " & z" * 599) is not None
    assert scan.deepest("(f | f)" + " & z" * 598) is None
    # a chain of short formulas, each two deeper than the last
    chain = "formula g0 = x=1;\n" + "".join(f"formula g{k + 1} = (g{k} & y);\n"
                                             for k in range(600))
    found = ExpressionDepth().deepest(chain)
    assert found is not None and found.line < 600


def test_statements_end_at_keywords_and_brackets_not_only_semicolons() -> None:
    # a module renaming has no ";": "[q0=q1, ...]" pairs of modules are not one expression
    renamings = "".join(f"module p{i} = p0 [ q0=q{i}, q1=q{i + 1} ] endmodule\n"
                        for i in range(1, 400))
    assert ExpressionDepth().deepest(renamings) is None


@needs_storm
def test_deep_guard_is_refused_before_storm_can_crash(tmp_path: Path) -> None:
    text = CORRIDOR.replace("[west] x > 0", f"[west] {nested(2000)} > 0")
    run = cli("info", "-q", str(corridor_model(tmp_path, text)), cwd=tmp_path)
    assert run.returncode == 2, (run.returncode, run.stderr)  # was -11: SIGSEGV
    line = run.stderr.strip()
    assert "c.toml: prism: " in line
    assert "c.prism:23:10: an expression more than 1,000 levels deep" in line


@needs_storm
def test_long_labels_entry_is_refused_with_its_key_path(tmp_path: Path) -> None:
    disjuncts = " | ".join(f"x={i % 5}" for i in range(2000))
    model = corridor_model(tmp_path, CORRIDOR, f'many = "{disjuncts}"')
    run = cli("info", "-q", str(model), cwd=tmp_path)
    assert run.returncode == 2, (run.returncode, run.stderr)
    assert "c.toml: labels.many: an expression more than 1,000 levels deep" in run.stderr


@needs_storm
def test_an_expression_within_the_limit_is_built_by_storm(tmp_path: Path) -> None:
    # 900 parentheses and a comparison: within the limit, and Storm builds it
    text = CORRIDOR.replace("[west] x > 0", f"[west] {nested(900)} > 0")
    run = cli("info", "-q", str(corridor_model(tmp_path, text)), cwd=tmp_path)
    assert run.returncode == 0, run.stderr


# --------------------------------------------------------------------------- sums


THIRDS = """mdp
module m
  x : [0..3] init 0;
  [go] x=0 -> {p} : (x'=1) + {p} : (x'=2) + {p} : (x'=3);
  [stay] x>0 -> true;
{extra}endmodule
label "goal" = x=3;
"""


def thirds(folder: Path, p: str = "0.333333", extra: str = "") -> Path:
    (folder / "t.prism").write_text(THIRDS.format(p=p, extra=extra))
    model = folder / "t.toml"
    model.write_text('name = "t"\nspec = "F[0,3] goal"\n[prism]\nfile = "t.prism"\n')
    return model


def test_rows_are_normalised_only_beyond_the_games_tolerance() -> None:
    import numpy as np

    from mitld_lp.worlds.successors import normalise_rows

    lengths = np.array([2, 3, 3])
    probs = np.array([0.5, 0.5, 0.333333, 0.333333, 0.333333, 0.1, 0.2, 0.7])
    out, rows, largest = normalise_rows(lengths, probs)
    assert rows == 1
    assert largest == pytest.approx(1e-6, rel=1e-9)  # 1 - 3 x 0.333333
    assert out[2:5].tolist() == pytest.approx([1 / 3] * 3, abs=1e-15)  # 333333/999999
    assert out[[0, 1, 5, 6, 7]].tolist() == probs[[0, 1, 5, 6, 7]].tolist()  # untouched


@needs_storm
def test_a_sum_prism_accepts_is_normalised_and_the_answer_says_so(tmp_path: Path) -> None:
    from mitld_lp.model import load_model
    from mitld_lp.synthesis import synthesize

    model = load_model(thirds(tmp_path))
    game = model.game
    assert game.normalised is not None and game.normalised.rows == 1
    assert game.normalised.largest == pytest.approx(1e-6, rel=1e-9)
    succ = dict(game.successors((0,), "go", frozenset()))
    assert succ == pytest.approx({(1,): 1 / 3, (2,): 1 / 3, (3,): 1 / 3}, abs=1e-15)
    r = synthesize(model)
    # by hand: the goal x=3 is reached in one step with probability 1/3, never after
    assert r.certified and r.lower == pytest.approx(1 / 3, abs=1e-12)
    said = [c for c in r.checks if c.name == "world's probabilities normalised"]
    assert len(said) == 1 and said[0].passed
    assert "1 row of" in said[0].detail and "1e-06" in said[0].detail


@needs_storm
@pytest.mark.parametrize("verb", ["solve", "info"])
def test_a_sum_prism_accepts_is_solved_on_the_command_line(tmp_path: Path, verb: str) -> None:
    run = cli(verb, "-q", str(thirds(tmp_path)), cwd=tmp_path)
    assert run.returncode == 0, run.stderr  # was 1: "internal error: GameError ..."
    assert "internal error" not in run.stderr


@needs_storm
def test_a_sum_beyond_prisms_tolerance_is_refused(tmp_path: Path) -> None:
    run = cli("solve", "-q", str(thirds(tmp_path, "0.3333")), cwd=tmp_path)
    assert run.returncode == 2, run.stderr
    assert "t.prism: module m, command 1 ([go] (x = 0) ->" in run.stderr
    assert "probabilities sum to 0.9999, not 1" in run.stderr


@needs_storm
def test_an_update_out_of_range_is_refused_when_storms_checks_are_off(tmp_path: Path) -> None:
    # the sum within PRISM's tolerance makes Storm build without its checks; x'=x+2 at
    # x=2 leaves [0..3] and was stored modulo the range, silently
    model = thirds(tmp_path, extra="  [up] x=2 -> (x'=x+2);\n")
    run = cli("solve", "-q", str(model), cwd=tmp_path)
    assert run.returncode == 2, run.stderr
    assert ("t.prism: at state [x=2], action 'up': an update gives a variable a value "
            "outside its range") in run.stderr
