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

from mitld_lp.worlds import WorldError
from mitld_lp.worlds.prism import load_prism

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


# --------------------------------------------------------------------------- the file


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
    with pytest.raises(WorldError):
        load_prism(prism(tmp_path, "mdp\nmodule m\n x : [0..2] init 0\nendmodule\n"))
    out, _ = capfd.readouterr()
    assert out == ""


# --------------------------------------------------------------------------- the command line


@pytest.mark.parametrize("body, expected", [
    ("mdp\nmodule m\n x : [0..2] init 0\n [] x<1 -> (x'=x+1);\nendmodule\n",
     r"m\.prism:4:2: PRISM parse error: expecting \";\""),
], ids=["parse-error"])
def test_cli_refuses_with_one_line_and_exit_2(tmp_path: Path, body: str | bytes,
                                              expected: str) -> None:
    run = cli("solve", str(model_file(tmp_path, prism(tmp_path, body))))
    line = one_line(run)
    assert line.startswith(f"mitld-lp: error: {tmp_path / 'm.toml'}: prism: {tmp_path / 'm.prism'}")
    assert re.search(expected, line), line
