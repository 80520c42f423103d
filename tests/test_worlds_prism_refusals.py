"""PRISM files that must be refused, not solved: an update out of a variable's range,
probabilities that do not sum to 1, a file that is not UTF-8 or not PRISM at all, a
program too large for the state budget.  Each is one line naming the file and the
module/command or line, through the library (:class:`WorldError`) and the command line
(exit 2 or 3, one line on stderr, nothing on stdout: Storm's own log is kept off it)."""

from __future__ import annotations

import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from mitld_lp.model import ModelError, load_model
from mitld_lp.worlds import WorldError
from mitld_lp.worlds.prism import PrismTooLarge, load_prism

pytestmark = pytest.mark.skipif(
    importlib.util.find_spec("stormpy") is None, reason="needs stormpy: pip install -e '.[prism]'"
)

ROOT = Path(__file__).resolve().parent.parent


def prism(tmp_path: Path, body: str | bytes, name: str = "m.prism") -> Path:
    p = tmp_path / name
    if isinstance(body, str):
        p.write_text(body)
    else:
        p.write_bytes(body)
    return p


def model_file(tmp_path: Path, source: Path, spec: str = "F goal") -> Path:
    m = tmp_path / "m.toml"
    m.write_text(f'name = "t"\nspec = "{spec}"\n[prism]\nfile = "{source.name}"\n')
    return m


def cli(*args: str) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-m", "mitld_lp", *args], env=env,
                          capture_output=True, text=True, timeout=120)


def one_line(run: subprocess.CompletedProcess[str], code: int = 2) -> str:
    """The single stderr line of a refused command (nothing may reach stdout)."""
    assert run.returncode == code, (run.returncode, run.stdout, run.stderr)
    assert run.stdout == ""
    lines = run.stderr.splitlines()
    assert len(lines) == 1, run.stderr
    return lines[0]


def module(commands: str, variables: str = "x : [0..3] init 0;") -> str:
    return f'mdp\nmodule m\n  {variables}\n{commands}\nendmodule\nlabel "goal" = x=1;\n'


# --------------------------------------------------------------------------- out of range


OUT_OF_RANGE = module("  [go] true -> (x'=x+5);")


def test_update_out_of_range_is_refused_not_wrapped_around(tmp_path: Path) -> None:
    # Without Storm's exploration checks x'=x+5 was stored modulo the range (x=5 -> 1)
    # and F goal was certified [1, 1].
    with pytest.raises(WorldError, match=r"m\.prism: module m, command 1 \(\[go\] .*\): an "
                       r"update gives 'x' the value 5, outside its range \[0\.\.3\]"):
        load_prism(prism(tmp_path, OUT_OF_RANGE))


@pytest.mark.parametrize("text, value", [
    # only from x=2 does the update leave the range: found while Storm explores
    (module("  [go] x<3 -> 0.5:(x'=x+2) + 0.5:(x'=x);"), 4),
    (module("  [] x>0 -> (x'=x-1);\n  [go] x=0 -> (x'=3);\n  [back] x=3 -> (x'=x-4);"), -1),
])
def test_state_dependent_update_out_of_range(tmp_path: Path, text: str, value: int) -> None:
    with pytest.raises(WorldError, match=rf"module m, command \d .*the value {value}, outside"):
        load_prism(prism(tmp_path, text))


def test_global_variable_out_of_range_names_the_command(tmp_path: Path) -> None:
    text = ("mdp\nglobal g : [0..1] init 0;\nmodule a\n  x : [0..1] init 0;\n"
            "  [] true -> (x'=1-x);\nendmodule\nmodule b\n  [s] true -> (g'=g+1);\nendmodule\n")
    with pytest.raises(WorldError, match=r"module b, command 1 .*'g' the value 2, outside its "
                       r"range \[0\.\.1\]"):
        load_prism(prism(tmp_path, text))


@pytest.mark.parametrize("variables, message", [
    ("x : [0..3] init 7;", r"module m: variable 'x': initial value 7 is outside its range "
                           r"\[0\.\.3\]"),
    ("x : [3..1] init 2;", r"module m: variable 'x': its range \[3\.\.1\] is empty"),
    ("x : int init 0;", r"module m: variable 'x' has no range; give it one \(x : \[lo\.\.hi\]\)"),
])
def test_variable_declarations_are_checked(tmp_path: Path, variables: str, message: str) -> None:
    text = module("  [go] x<3 -> (x'=x+1);\n  [stay] x=3 -> true;", variables)
    with pytest.raises(WorldError, match=message):
        load_prism(prism(tmp_path, text))


# --------------------------------------------------------------------------- probabilities


@pytest.mark.parametrize("updates, total", [
    ("0.5:(x'=x+1) + 0.6:(x'=x)", "1.1"),
    ("0.5:(x'=x+1) + 0.4:(x'=x)", "0.9"),
    ("0.5:(x'=x+1) + 0.5:(x'=x) + 1e-4:(x'=0)", "1.0001"),  # beyond PRISM's 1e-5
])
def test_constant_probabilities_must_sum_to_one(tmp_path: Path, updates: str, total: str) -> None:
    text = module(f"  [stay] true -> true;\n  [go] x<3 -> {updates};")
    with pytest.raises(WorldError, match=rf"module m, command 2 \(\[go\] .*\): probabilities "
                       rf"sum to {total}, not 1"):
        load_prism(prism(tmp_path, text))


def test_state_dependent_probabilities_must_sum_to_one(tmp_path: Path) -> None:
    # x/4 + 1/2 is 1 only at x=2: Storm's check while exploring, at x=0 (sum 0.5)
    text = module("  [go] x<3 -> x/4:(x'=x+1) + 0.5:(x'=x);")
    with pytest.raises(WorldError, match=r"module m, command 1 \(\[go\] .*\): probabilities sum "
                       r"to 0\.5 in a state, not 1"):
        load_prism(prism(tmp_path, text))


def test_synchronised_command_probabilities_name_their_module(tmp_path: Path) -> None:
    text = ("mdp\nmodule a\n  x : [0..1] init 0;\n  [s] true -> 0.5:(x'=1) + 0.6:(x'=0);\n"
            "endmodule\nmodule b\n  y : [0..1] init 0;\n  [s] true -> (y'=1-y);\nendmodule\n")
    with pytest.raises(WorldError, match=r"module a, command 1 .*sum to 1\.1, not 1"):
        load_prism(prism(tmp_path, text))
    # state-dependent: Storm checks the synchronised choice (x=0: 0 + 0.6)
    text = text.replace("0.5:(x'=1)", "x/2:(x'=1)")
    with pytest.raises(WorldError, match=r"m\.prism: the synchronised commands of an action "
                       r"have probabilities summing to 0\.6 in a state, not 1"):
        load_prism(prism(tmp_path, text))


def test_negative_probability_is_one_line(tmp_path: Path) -> None:
    text = module("  [go] true -> -0.5:(x'=1) + 1.5:(x'=0);")
    with pytest.raises(WorldError, match=r"^[^\n]*m\.prism: .*negative probabilities[^\n]*$"):
        load_prism(prism(tmp_path, text))


# --------------------------------------------------------------------------- the file


def test_non_utf8_file_names_the_byte(tmp_path: Path) -> None:
    text = module("  [go] x<3 -> (x'=x+1);").encode()
    bad = text.replace(b"init 0;", b"init 0; // caf\xe9", 1)
    with pytest.raises(WorldError, match=r"m\.prism:3:28: not UTF-8 text \(byte 0xe9\)"):
        load_prism(prism(tmp_path, bad))


def test_parse_error_quotes_a_short_excerpt_of_a_foreign_file(tmp_path: Path) -> None:
    secret = "user,password," + "x" * 300
    path = prism(tmp_path, secret + "\nsecond line\n", "data.csv")
    with pytest.raises(WorldError) as info:
        load_prism(path)
    message = str(info.value)
    assert message.startswith(f"{path}:1:1: PRISM parse error: expecting <model type> at ")
    assert len(message) - len(str(path)) < 80 and "x" * 30 not in message


def test_parse_error_is_one_line_with_line_and_column(tmp_path: Path) -> None:
    bad = prism(tmp_path, "mdp\nmodule m\n x : [0..2] init 0\n [] x<1 -> (x'=x+1);\nendmodule\n")
    with pytest.raises(WorldError) as info:
        load_prism(bad)
    expected = "PRISM parse error: expecting \";\" at \"[] x<1 -> (x'=x+1);\""
    assert str(info.value) == f"{bad}:4:2: {expected}"


def test_library_stdout_stays_empty_when_storm_fails(tmp_path: Path, capfd) -> None:
    # Storm logs its errors on file descriptor 1 from C++; none of it may get through.
    for text in (OUT_OF_RANGE, "mdp\nmodule m\n x : [0..2] init 0\nendmodule\n"):
        with pytest.raises(WorldError):
            load_prism(prism(tmp_path, text))
    out, _ = capfd.readouterr()
    assert out == ""


def test_model_file_reports_the_prism_problem(tmp_path: Path) -> None:
    src = prism(tmp_path, OUT_OF_RANGE)
    with pytest.raises(ModelError, match=r"m\.toml: prism: .*m\.prism: module m, command 1"):
        load_model(model_file(tmp_path, src))


# --------------------------------------------------------------------------- the command line


@pytest.mark.parametrize("body, expected", [
    (OUT_OF_RANGE, r"module m, command 1 \(\[go\] .*'x' the value 5, outside its range"),
    (module("  [go] x<3 -> 0.5:(x'=x+1) + 0.6:(x'=x);"), r"module m, command 1 .*sum to 1\.1"),
    (module("  [go] x<3 -> (x'=x+1);").encode().replace(b"m\n", b"m\xff\n", 1),
     r"m\.prism:2:9: not UTF-8 text"),
    ("mdp\nmodule m\n x : [0..2] init 0\n [] x<1 -> (x'=x+1);\nendmodule\n",
     r"m\.prism:4:2: PRISM parse error: expecting \";\""),
], ids=["out-of-range", "sum-1.1", "not-utf8", "parse-error"])
def test_cli_refuses_with_one_line_and_exit_2(tmp_path: Path, body: str | bytes,
                                              expected: str) -> None:
    run = cli("solve", str(model_file(tmp_path, prism(tmp_path, body))))
    line = one_line(run)
    assert line.startswith(f"mitld-lp: error: {tmp_path / 'm.toml'}: prism: {tmp_path / 'm.prism'}")
    assert re.search(expected, line), line


# --------------------------------------------------------------------------- budgets


# 2000 x 2000 = 4,000,000 states, all reachable: building it takes minutes and gigabytes,
# so these tests finish only because Storm's exploration stops at the budget.
HUGE = """mdp
module m
  x : [0..1999] init 0;
  y : [0..1999] init 0;
  [a] x<1999 -> (x'=x+1);
  [b] y<1999 -> (y'=y+1);
  [c] x=1999 -> (x'=0);
endmodule
label "goal" = x=1999 & y=1999;
"""


def test_state_budget_stops_the_exploration(tmp_path: Path) -> None:
    # the range product (4,000,000) is reported as a note, the refusal is the budget's
    with pytest.raises(PrismTooLarge, match=r"m\.prism: Storm's exploration passed the budget "
                       r".*max_states = 1,000 .*at most 4,000,000 states from the variables' "
                       r"ranges \(x: 2,000 x y: 2,000\)\): raise max_states "
                       r"\(--max-world-states\)"):
        load_prism(prism(tmp_path, HUGE), max_states=1000)
    with pytest.raises(PrismTooLarge, match=r"max_memory = .*--max-memory"):
        load_prism(prism(tmp_path, HUGE), max_memory=32 << 20)


# The ranges allow 100,001^2 valuations; from (0, 0) the program reaches x in 0..3 and
# y in 0..5 only (go raises x or y, back lowers x): 4 * 6 = 24 states.
WIDE = """mdp
module m
  x : [0..100000] init 0;
  y : [0..100000] init 0;
  [go] x<3 -> 0.5:(x'=x+1) + 0.5:(y'=min(y+1,5));
  [back] x>0 -> (x'=x-1);
endmodule
label "goal" = x=3;
"""


def test_wide_ranges_with_a_small_reachable_part_load_with_default_budgets(
    tmp_path: Path,
) -> None:
    game = load_prism(prism(tmp_path, WIDE))
    assert sorted(game.states) == [(x, y) for x in range(4) for y in range(6)]
    # and within a budget just above the reachable part, not the ranges' product
    assert game.n_states == len(load_prism(prism(tmp_path, WIDE), max_states=24).states)
    with pytest.raises(PrismTooLarge, match=r"Storm explored 24 states, more than "
                       r"max_states = 23"):
        load_prism(prism(tmp_path, WIDE), max_states=23)


def test_budget_stop_is_a_world_error_and_a_product_budget(tmp_path: Path) -> None:
    from mitld_lp.product import ProductTooLarge

    with pytest.raises(WorldError):
        load_prism(prism(tmp_path, HUGE), max_states=1000)
    with pytest.raises(ProductTooLarge):
        load_prism(prism(tmp_path, HUGE), max_states=1000)


def test_bound_is_the_product_of_every_variables_range(tmp_path: Path) -> None:
    # global g: 3 values, module a: x 4 values and b bool, module c (renamed a): y 4, d bool
    text = ("mdp\nglobal g : [0..2] init 0;\nmodule a\n  x : [0..3] init 0;\n"
            "  b : bool init false;\n  [] x<3 -> (x'=x+1);\n  [] x=3 -> (b'=!b)&(x'=0);\n"
            "  [] true -> (g'=min(g+1,2));\n"
            "endmodule\nmodule c = a [x=y, b=d] endmodule\n")
    src = prism(tmp_path, text)
    bound = 3 * 4 * 2 * 4 * 2
    game = load_prism(src, max_states=bound)  # the bound itself is within the budget
    assert len(game.states) == bound  # every valuation is reachable: the bound is tight
    with pytest.raises(PrismTooLarge, match=rf"explored {bound} states, more than "
                       rf"max_states = {bound - 1}"):
        load_prism(src, max_states=bound - 1)


def test_model_file_passes_the_budget_to_the_prism_world(tmp_path: Path) -> None:
    m = model_file(tmp_path, prism(tmp_path, HUGE))
    with pytest.raises(PrismTooLarge, match=rf"^{re.escape(str(m))}: prism: .*m\.prism: Storm's "
                       "exploration passed the budget"):
        load_model(m, max_states=1000)


def test_cli_budget_stop_is_one_line_exit_3(tmp_path: Path) -> None:
    m = model_file(tmp_path, prism(tmp_path, HUGE))
    line = one_line(cli("solve", str(m), "--max-world-states", "1000", "--max-memory", "1G"),
                    code=3)
    assert line.startswith(f"mitld-lp: stopped: {m}: prism: ")
    assert "max_states = 1,000" in line and "--max-world-states" in line


def test_world_and_product_budgets_are_separate_settings(tmp_path: Path) -> None:
    m = model_file(tmp_path, prism(tmp_path, WIDE))
    line = one_line(cli("solve", str(m), "--max-world-states", "23"), code=3)
    assert "Storm explored 24 states, more than max_states = 23" in line
    # the product's budget no longer bounds the world (nor the other way round)
    ok = cli("solve", str(m), "--max-world-states", "24", "--max-memory", "1048576T", "-q")
    assert ok.returncode == 0, ok.stderr


@pytest.mark.parametrize("text, value", [
    ("1048576T", 1 << 60), ("1P", 1 << 50), ("2PiB", 2 << 50), ("1.5G", 3 << 29), ("7E", 7 << 60),
])
def test_memory_sizes_take_every_unit(text: str, value: int) -> None:
    from mitld_lp.cli.arguments import memory_size

    assert memory_size(text) == value


@pytest.mark.parametrize("text", ["8E", "0.5", "inf", "nan", "4X"])
def test_memory_sizes_out_of_range_are_refused(text: str) -> None:
    import argparse

    from mitld_lp.cli.arguments import memory_size

    with pytest.raises(argparse.ArgumentTypeError):
        memory_size(text)


@pytest.mark.parametrize("kind, make", [
    ("a FIFO (named pipe)", lambda p: os.mkfifo(p)),
    ("a directory", lambda p: p.mkdir()),
    ("a character device", lambda p: p.symlink_to("/dev/null")),
])
def test_a_prism_file_that_is_no_regular_file_is_named_for_what_it_is(tmp_path, kind, make):
    # issue 41: a FIFO, device or directory given as [prism] file was "no such PRISM file"
    source = tmp_path / "m.prism"
    make(source)
    with pytest.raises(WorldError, match=rf"m\.prism: is {re.escape(kind)}, not a regular "
                                         "file$"):
        load_prism(source)
    line = one_line(cli("solve", str(model_file(tmp_path, source)), "-q"))
    assert line == (f"mitld-lp: error: {tmp_path / 'm.toml'}: prism: {source}: is {kind}, "
                    "not a regular file")


def test_a_missing_prism_file_is_still_said_missing(tmp_path):
    with pytest.raises(ModelError, match=r"m\.toml: prism: .*m\.prism: no such PRISM file$"):
        load_model(model_file(tmp_path, tmp_path / "m.prism"))
