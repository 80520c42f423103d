"""The command line's exit when its command is done (``mitld_lp.cli._exit_done``): in a
process that is the command (``python -m mitld_lp``) the exit handlers run and both
streams are flushed before the process ends without the interpreter's teardown; with
another Python thread alive, or in a program that calls the command's function and
catches its ``SystemExit``, the interpreter's own exit as before.  Each in a fresh
interpreter; the expected lines are the probe's own, the exit status the command's."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

#: argv[1]: "thread" to leave a non-daemon thread running when the command ends,
#: "called" to call the command's function and go on after its ``SystemExit``.
PROBE = r"""
import atexit, os, sys, threading, time
mode = sys.argv[1]
ended = os._exit
def marked_exit(code):  # the process's end without the interpreter's teardown, marked
    os.write(2, b"os._exit\n")
    ended(code)
os._exit = marked_exit
atexit.register(lambda: sys.stderr.write("handler ran\n"))
if mode == "thread":
    def late():
        time.sleep(2.0)  # past the command's end
        sys.stdout.write("thread done\n")
    threading.Thread(target=late).start()
sys.argv = ["mitld-lp", "check", "F[0,5] goal"]
if mode == "called":
    from mitld_lp import startup
    try:
        startup.command()
    except SystemExit as stop:
        sys.stdout.write(f"went on after exit {stop.code}\n")
else:  # as python -m mitld_lp runs it
    import runpy
    runpy.run_module("mitld_lp", run_name="__main__", alter_sys=True)
"""


def _run(mode: str) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), *filter(None, [env.get("PYTHONPATH")])])
    return subprocess.run([sys.executable, "-c", PROBE, mode], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=300)


def test_a_done_command_runs_the_handlers_flushes_and_ends_at_once() -> None:
    done = _run("plain")
    assert done.returncode == 0, done.stderr[-2000:]
    assert "horizon:   5" in done.stdout  # the command's output, flushed (piped: buffered)
    assert "handler ran" in done.stderr
    assert done.stderr.endswith("handler ran\nos._exit\n")  # handlers first, no teardown


def test_another_thread_alive_leaves_the_interpreters_exit() -> None:
    done = _run("thread")
    assert done.returncode == 0, done.stderr[-2000:]
    assert "horizon:   5" in done.stdout and "thread done" in done.stdout  # waited for
    assert "handler ran" in done.stderr
    assert "os._exit" not in done.stderr  # the interpreter's own exit, as before


def test_a_program_calling_the_command_goes_on_after_it() -> None:
    done = _run("called")
    assert done.returncode == 0, done.stderr[-2000:]
    assert "horizon:   5" in done.stdout and "went on after exit 0" in done.stdout
    assert "os._exit" not in done.stderr and "handler ran" in done.stderr
