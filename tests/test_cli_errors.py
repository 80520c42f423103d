"""The command line's one error path: every bad argument or output path is one printable
line and exit 2 before any work; budget and time stops exit 3; Ctrl-C exits 130."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from mitld_lp.cli import main

MODELS = Path(__file__).resolve().parent.parent / "models"
BUS = str(MODELS / "bus_grid.toml")
PATROL = str(MODELS / "patrol.toml")


def _one_error_line(capsys, code: int, argv: list[str]) -> str:
    assert main(argv) == code
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1, captured.err
    assert lines[0].isprintable()
    return lines[0]


@pytest.mark.parametrize(
    ("argv", "says"),
    [
        (["simulate", BUS, "--max-steps", "-1"], "--max-steps: must be an integer in 1.."),
        (["simulate", BUS, "-n", "1000000000000"], "--runs: must be an integer in 1.."),
        (["simulate", BUS, "-n", "-5"], "--runs: must be an integer in 1.."),
        (["simulate", BUS, "--seed", "-1"], "--seed: must be an integer >= 0"),
        (["solve", BUS, "--epsilon", "0"], "--epsilon: must be a number in (0, 1)"),
        (["solve", BUS, "--epsilon", "1"], "--epsilon: must be a number in (0, 1)"),
        (["solve", BUS, "--epsilon", "-1"], "--epsilon: must be a number in (0, 1)"),
        (["solve", BUS, "--epsilon", "nan"], "--epsilon: must be a number in (0, 1)"),
        (["solve", BUS, "--epsilon", "inf"], "--epsilon: must be a number in (0, 1)"),
        (["solve", BUS, "--max-states", "0"], "--max-states: must be an integer >= 1"),
        (["solve", BUS, "--time-limit", "-3"], "--time-limit: must be a positive number"),
        (["info", BUS, "--max-memory", "lots"], "--max-memory: must be a size such as 4G"),
        (["info", BUS, "--max-memory", "0"], "--max-memory: must be a positive size"),
        (["frobnicate"], "invalid choice: 'frobnicate'"),
        ([], "give a command: check,"),
    ],
)
def test_bad_arguments_are_one_line_and_exit_2(capsys, argv, says):
    line = _one_error_line(capsys, 2, argv)
    assert line.startswith("mitld-lp: error:") and says in line


@pytest.mark.parametrize(
    ("where", "says"),
    [
        ("/nonexistent/x.drn", "the folder /nonexistent does not exist"),
        ("{tmp}/nodir/x.drn", "does not exist"),
        ("{tmp}/x.txt", "the suffix must be one of .drn"),
        ("{tmp}/folder.drn", "is a directory"),
    ],
)
def test_bad_output_paths_are_refused_before_any_work(tmp_path, capsys, where, says):
    (tmp_path / "folder.drn").mkdir()
    path = where.format(tmp=tmp_path)
    line = _one_error_line(capsys, 2, ["export", BUS, "--drn", path, "--force"])
    assert says in line


def test_dta_dot_paths_are_checked_like_the_others(tmp_path, capsys):
    assert "does not exist" in _one_error_line(
        capsys, 2, ["dta", "F[0,1] p", "--dot", "/nonexistent/x.dot"])
    assert "suffix must be one of .dot, .gv" in _one_error_line(
        capsys, 2, ["dta", "F[0,1] p", "--dot", str(tmp_path / "x.png")])
    full = tmp_path / "full.dot"
    full.symlink_to("/dev/full")
    assert "cannot write" in _one_error_line(
        capsys, 2, ["dta", "F[0,1] p", "--dot", str(full), "--force"])


def test_lp_suffix_and_same_file_are_refused(tmp_path, capsys):
    assert "suffix must be one of .mps, .lp" in _one_error_line(
        capsys, 2, ["export", BUS, "--lp", str(tmp_path / "out.txt")])
    line = _one_error_line(capsys, 2, ["export", BUS, "--lp", str(tmp_path / "x.mps"),
                                       "--drn", str(tmp_path / "x.mps")])
    assert "--drn" in line
    assert not (tmp_path / "x.mps").exists()  # nothing written half-way


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="needs /dev/full")
def test_a_full_disk_is_a_one_line_error(tmp_path, capsys):
    # /dev/full accepts the open and fails every write with ENOSPC.
    full = tmp_path / "full.drn"
    full.symlink_to("/dev/full")
    line = _one_error_line(capsys, 2, ["export", BUS, "--drn", str(full), "--force", "-q"])
    assert "cannot write: No space left on device" in line


def test_json_never_carries_nan(capsys, tmp_path):
    assert main(["solve", BUS, "--json", "-q"]) == 0
    text = capsys.readouterr().out
    assert "NaN" not in text and "Infinity" not in text
    json.loads(text)


def test_control_characters_in_user_names_are_escaped(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    text = Path(BUS).read_text().replace('A = [[1, 2]]', '"A\\u001b[31m\\nB" = [[1, 2]]')
    bad.write_text(text)
    line = _one_error_line(capsys, 2, ["solve", str(bad)])
    assert "\x1b" not in line and "\\x1b" in line


def test_a_deeply_nested_toml_is_a_model_error(tmp_path, capsys):
    bad = tmp_path / "deep.toml"
    bad.write_text("x = " + "[" * 2000 + "]" * 2000 + "\n")
    line = _one_error_line(capsys, 2, ["info", str(bad)])
    assert "nested too deeply" in line


def test_a_time_limit_is_a_status_not_a_hang(capsys, tmp_path):
    # A 64x64 bus grid with deadline 10 takes seconds to build and solve.  Either the
    # solvers answer with the status (and their bracket so far) or, if a stage that
    # cannot stop itself is still running, the watchdog stops it: exit 3 both ways.
    big = tmp_path / "big.toml"
    big.write_text(Path(BUS).read_text().replace("size = [4, 4]", "size = [64, 64]")
                   .replace("F[0,3]", "F[0,10]").replace("A = [[1, 2]]", "A = [[16, 32]]")
                   .replace("B = [[3, 0]]", "B = [[48, 0]]"))
    assert main(["solve", str(big), "--json", "--time-limit", "0.01"]) == 3
    captured = capsys.readouterr()
    assert json.loads(captured.out)["status"] == "time_limit"


def test_a_time_limit_spent_before_the_solve_is_a_status_not_a_user_error():
    # On a loaded machine the model's loading ate a 0.01 s limit: the time left, zero,
    # went to the settings, which refuse a zero limit as a user error (exit 2, "got
    # 0.0").  Spent is a positive sliver now; the settings take it and the solve stops.
    import argparse

    from mitld_lp import load_model, synthesize
    from mitld_lp.cli import kernel

    spent = argparse.Namespace(time_limit=0.01, started=time.monotonic() - 60.0)
    left = kernel.time_left(spent)
    assert left is not None and 0 < left <= kernel.SPENT
    assert kernel.time_left(argparse.Namespace(time_limit=None, started=0.0)) is None
    big = load_model(BUS)
    r = synthesize(big, time_limit=left)
    assert r.status in {"time_limit", "optimal"}  # the tiny case may finish in 1 ms


def test_a_memory_budget_stops_before_the_work(capsys):
    # 10 KiB cannot hold the bus grid's 371-state product: a budget stop, exit 3.
    line = _one_error_line(capsys, 3, ["info", BUS, "--max-memory", "10K", "-q"])
    assert line.startswith("mitld-lp: stopped:") and "memory" in line
    assert main(["info", BUS, "--max-memory", "1G", "-q"]) == 0


def test_the_automaton_is_held_to_the_state_budget_too(tmp_path, capsys):
    # A deadline of a million steps needs a million automaton states: refused at the
    # budget while the automaton is built, not after (it ran to the time limit before).
    long = tmp_path / "long.toml"
    long.write_text(Path(BUS).read_text().replace("F[0,3] A", "F[0,1000000] A"))
    line = _one_error_line(capsys, 3, ["info", str(long), "--max-states", "1000", "-q"])
    assert line.startswith("mitld-lp: stopped:") and "more than 1,000 automaton states" in line


def test_stage_lines_go_to_stderr_and_quiet_silences_them(capsys):
    assert main(["info", BUS]) == 0
    err = capsys.readouterr().err
    assert "mitld-lp: product: " in err and "states" in err
    assert main(["info", BUS, "-q"]) == 0
    assert capsys.readouterr().err == ""


def _cli(*args: str, **kw) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parent.parent)}
    return subprocess.Popen([sys.executable, "-m", "mitld_lp", *args], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kw)


def test_python_dash_m_and_version():
    proc = _cli("--version")
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err
    from mitld_lp import __version__

    assert out.strip() == f"mitld-lp {__version__}"


def test_ctrl_c_ends_the_command_with_130_and_one_line(tmp_path):
    # Rollouts that would run for an hour: the signal comes in the middle of the work.
    proc = _cli("simulate", BUS, "-n", "50000000")
    assert proc.stderr is not None
    for line in proc.stderr:  # wait for the stage line that precedes the rollouts
        if line.startswith("mitld-lp: synthesis:"):
            break
    time.sleep(0.5)
    assert proc.poll() is None, proc.communicate()
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 130
    assert err.strip().splitlines() == ["mitld-lp: interrupted"]
    assert out == ""
