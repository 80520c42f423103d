"""``--time-limit`` (or the ``[budgets] time_limit`` of the command's model file, which
binds as the flag does) as a promise about the process.

The command's own watchdog (:func:`mitld_lp.cli.main`) stops a stage that returns to the
interpreter, but a native call that holds Python's lock for seconds (a ``scipy.stats``
law whose survival function sums a billion terms) keeps even that watchdog from running.
So the command line runs a command with a time limit in a child process and watches it
from this, otherwise idle, parent:

* the child does everything as usual (its output goes straight to the terminal) and
  reports through a pipe each temporary file it starts writing and the moment it has
  said "stopped";
* when the child ends, the parent exits with the child's status;
* at the limit plus :data:`GRACE` seconds the parent kills the child, removes the
  temporary files it reported (a file being replaced keeps its old content: writers
  rename only complete files), says "stopped" if the child could not, and exits 3.

Ctrl-C reaches both; the parent gives the child :data:`GRACE` seconds to stop by itself.
Only the console script (:func:`mitld_lp.cli.run`) forks, and only on systems with
``fork``; a program calling :func:`mitld_lp.cli.main` or :func:`mitld_lp.synthesize`
is not forked (``synthesize(time_limit=...)`` returns with status ``time_limit`` at the
next point a stage checks its clock).
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import time
from collections.abc import Callable
from pathlib import Path

__all__ = ["GRACE", "SAID", "watched", "report"]

GRACE = 1.5
"""Seconds past the limit (and past a Ctrl-C) the child has to stop by itself."""

SAID = "\0said"
"""The line the child writes once it has printed its stop line."""

_channel: int | None = None
"""In the child: the pipe to the parent (None when not watched)."""


def report(line: str) -> None:
    """Tell the watching parent ``line`` (a temporary file's path, or :data:`SAID`);
    nothing when this process is not watched."""
    if _channel is not None:
        with contextlib.suppress(OSError):
            os.write(_channel, (line + "\n").encode("utf-8", "surrogateescape"))


def watched(limit: float, stop_line: Callable[[], None]) -> int | None:
    """Fork.  In the child: return None (run the command).  In the parent: wait for the
    child and return the exit status of the whole command (module docstring);
    ``stop_line`` prints the stop line (and the JSON status) when the child could not."""
    global _channel
    if not hasattr(os, "fork"):
        return None
    sys.stdout.flush()
    sys.stderr.flush()
    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:
        os.close(read)
        _channel = write
        return None
    os.close(write)
    os.set_blocking(read, False)
    received = bytearray()
    deadline = time.monotonic() + limit + GRACE
    try:
        while True:
            received += _drain(read)
            done, status = os.waitpid(pid, os.WNOHANG)
            if done:
                received += _drain(read)
                return _exit_code(status)
            if time.monotonic() >= deadline:
                return _kill(pid, read, received, stop_line, 3)
            time.sleep(0.05)
    except KeyboardInterrupt:  # the child got it too: give it the grace to stop
        end = time.monotonic() + GRACE
        while time.monotonic() < end:
            done, status = os.waitpid(pid, os.WNOHANG)
            if done:
                return _exit_code(status)
            time.sleep(0.05)
        return _kill(pid, read, received, lambda: _say("interrupted"), 130)


def _exit_code(status: int) -> int:
    """The child's exit status as a shell reports it (128 + N if signal N ended it)."""
    code = os.waitstatus_to_exitcode(status)
    return code if code >= 0 else 128 - code


def _drain(fd: int) -> bytes:
    out = bytearray()
    while True:
        try:
            chunk = os.read(fd, 65536)
        except BlockingIOError:
            return bytes(out)
        if not chunk:
            return bytes(out)
        out += chunk


def _kill(pid: int, fd: int, received: bytearray, say: Callable[[], None], code: int) -> int:
    with contextlib.suppress(ProcessLookupError):
        os.kill(pid, signal.SIGKILL)
    os.waitpid(pid, 0)
    received += _drain(fd)
    lines = received.decode("utf-8", "surrogateescape").splitlines()
    for line in lines:
        if line and line != SAID:
            scratch = Path(line)
            with contextlib.suppress(OSError):
                if scratch.is_dir() and not scratch.is_symlink():
                    for inner in scratch.iterdir():
                        inner.unlink()
                    scratch.rmdir()
                else:
                    scratch.unlink()
    if SAID not in lines:
        say()
    return code


def _say(message: str) -> None:
    print(f"mitld-lp: {message}", file=sys.stderr, flush=True)
