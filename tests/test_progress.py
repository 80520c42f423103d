"""Progress bars: on a terminal, and nowhere else (issue 41).

A bar is drawn on standard error only where that is a terminal, never under ``-q`` or
``--json``, never on standard output: what a command prints there is byte for byte the
same with or without the bars.  The terminal here is a pseudo-terminal with a window
size (a terminal of 0 columns draws no bar); :data:`mitld_lp.util.progress.DELAY` is set
to 0 so that a bar is drawn however fast its stage runs."""

from __future__ import annotations

import fcntl
import io
import os
import struct
import subprocess
import sys
import termios
import threading
from pathlib import Path

import pytest

from mitld_lp.cli import main
from mitld_lp.util import progress

ROOT = Path(__file__).resolve().parents[1]
BUS = str(ROOT / "models" / "bus_grid.toml")

#: How tqdm draws a bar: its description, then the count with a rate.
BAR_MARKS = ("simulate:", "block LPs:", "product:")

#: The command line with every bar drawn at once (no delay), as a fresh process.
_NO_DELAY = ("import sys\nfrom mitld_lp.util import progress\nprogress.DELAY = 0.0\n"
             "from mitld_lp.cli import run\nrun()\n")


class _Terminal:
    """A pseudo-terminal of 100 columns whose output is read as it comes."""

    def __init__(self) -> None:
        self.master, self.slave = os.openpty()
        fcntl.ioctl(self.slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))
        self.chunks: list[bytes] = []
        self.reader = threading.Thread(target=self._read, daemon=True)
        self.reader.start()

    def _read(self) -> None:
        while True:
            try:
                data = os.read(self.master, 65536)
            except OSError:  # the other end closed
                return
            if not data:
                return
            self.chunks.append(data)

    def text(self) -> str:
        """Everything written to the terminal, once its writers have closed it."""
        os.close(self.slave)
        self.reader.join(timeout=10)
        os.close(self.master)
        return b"".join(self.chunks).decode("utf-8", "replace")


def _run(args: list[str], terminal: bool) -> tuple[int, bytes, str]:
    """``mitld-lp ARGS`` in a fresh process, stderr on a terminal or a pipe: the exit
    status, standard output (bytes) and standard error."""
    if not terminal:
        done = subprocess.run([sys.executable, "-c", _NO_DELAY, *args], capture_output=True,
                              timeout=300, cwd=ROOT, check=False)
        return done.returncode, done.stdout, done.stderr.decode()
    tty = _Terminal()
    child = subprocess.Popen([sys.executable, "-c", _NO_DELAY, *args], cwd=ROOT,
                             stdout=subprocess.PIPE, stderr=tty.slave,
                             stdin=subprocess.DEVNULL)
    out, _ = child.communicate(timeout=300)
    return child.returncode, out, tty.text()


def _bars(err: str) -> list[str]:
    """The bars drawn in ``err`` (tqdm redraws a bar in place after a carriage return)."""
    return [part for part in err.split("\r") if part.startswith(BAR_MARKS)]


SIMULATE = ["simulate", BUS, "-n", "1500", "--seed", "4"]


def test_a_terminal_shows_the_bars_and_stdout_is_the_same_without_them():
    code, shown_out, shown_err = _run(SIMULATE, terminal=True)
    assert code == 0, shown_err
    drawn = _bars(shown_err)
    assert any(b.startswith("simulate:") for b in drawn), shown_err[-2000:]
    assert any(b.startswith("block LPs:") for b in drawn)
    assert any(b.startswith("product:") for b in drawn)
    assert "1500/1500" not in shown_out.decode()  # nothing of a bar on stdout
    # the same command with stderr a pipe: no bar, the same stdout byte for byte
    code, piped_out, piped_err = _run(SIMULATE, terminal=False)
    assert code == 0 and _bars(piped_err) == [] and "\r" not in piped_err
    assert piped_out == shown_out
    # -q on the terminal: not a character on stderr, the same stdout
    code, quiet_out, quiet_err = _run([*SIMULATE, "-q"], terminal=True)
    assert code == 0 and quiet_err == "" and quiet_out == shown_out


def test_json_on_a_terminal_draws_no_bar():
    code, out, err = _run([*SIMULATE, "--json"], terminal=True)
    assert code == 0, err
    assert _bars(err) == [] and "\r\x1b" not in err
    assert out.decode().count("\n") == 1 and out.decode().startswith("{")


# --------------------------------------------------------------------------- in process


@pytest.fixture
def terminal(monkeypatch: pytest.MonkeyPatch):
    """A function that makes standard error a pseudo-terminal and standard output a
    buffer, bars drawn at once, and returns the function reading both once the command
    is done.  (Called inside the test: pytest sets its own streams before each phase.)"""
    opened: list[io.TextIOWrapper] = []

    def start():
        tty = _Terminal()
        err = open(tty.slave, "w", encoding="utf-8", closefd=False)  # noqa: SIM115
        opened.append(err)
        out = io.StringIO()
        monkeypatch.setattr(sys, "stderr", err)
        monkeypatch.setattr(sys, "stdout", out)
        monkeypatch.setattr(progress, "DELAY", 0.0)

        def read() -> tuple[str, str]:
            err.flush()
            return out.getvalue(), tty.text()

        return read

    yield start
    monkeypatch.undo()
    for err in opened:
        err.close()


def _sensed_model(tmp_path: Path) -> Path:
    """The bus case with bus 1 (geometric(0.8)) reported by a sensor that misses."""
    path = tmp_path / "bus_sensed.toml"
    path.write_text(Path(BUS).read_text() + "\n[sensors]\nb1 = { detect = 0.5 }\n")
    return path


def test_the_sensed_build_says_its_size_first_and_shows_a_bar(terminal, tmp_path):
    read = terminal()
    code = main(["solve", str(_sensed_model(tmp_path))])
    out, err = read()
    assert code == 0, err
    lines = [ln for ln in err.replace("\r\n", "\n").split("\n") if "information" in ln]
    first = next(i for i, ln in enumerate(lines) if "may be far larger" in ln)
    built = next(i for i, ln in enumerate(lines)
                 if "information-state product: " in ln and "choices" in ln)
    assert first < built  # said before the build, which draws its bar in between
    assert any(b.startswith("information states:") for b in err.split("\r"))
    # b1 ~ geometric(0.8) is truncated where 0.2^T <= epsilon 0.01: T = 3, so a state
    # holds at most 4 hypotheses of b1's step (not yet, 1, 2, 3)
    assert "up to 4 hypotheses of when b1 happened (b1 truncated at step 3)" in lines[first]
    assert "optimum in:" in out


def test_a_batch_and_its_lines_share_the_terminal(terminal):
    read = terminal()
    code = main(["solve", BUS, BUS.replace("bus_grid", "red_light")])
    out, err = read()
    assert code == 0, err
    assert any(b.startswith("batch:") for b in err.split("\r"))
    assert [ln.split(":")[0] for ln in out.splitlines()] == [
        BUS, BUS.replace("bus_grid", "red_light")]  # one line each, nothing else


def test_quiet_and_json_silence_every_bar(terminal):
    read = terminal()
    assert main(["solve", BUS, BUS, "-q"]) == 0
    _, quiet = read()
    assert quiet == ""  # -q: not a character
    read = terminal()
    assert main(["simulate", BUS, "-n", "50", "--json"]) == 0
    _, err = read()
    assert "mitld-lp: product:" in err  # the stage lines, whole lines, and no bar
    assert "\r" not in err.replace("\r\n", "") and _bars(err) == []


def test_a_line_written_over_a_bar_clears_it_and_draws_it_again(terminal):
    read = terminal()
    shown = progress.bar(True, total=10, desc="work", leave=False)
    shown.update(3)
    progress.write("a line", sys.stdout)
    progress.write("a note", sys.stderr)
    shown.close()
    out, err = read()
    assert out == "a line\n"  # the line itself, nothing of the bar
    before, after = err.replace("\r\n", "\n").split("a note\n")
    assert "work:" in before and "work:" in after  # cleared, then drawn again


def test_abandon_erases_the_bars_and_draws_them_no_more(terminal):
    read = terminal()
    shown = progress.bar(True, total=10, desc="left", leave=False)
    progress.abandon()
    shown.update(6)  # the stopped command's thread goes on: nothing more is drawn
    shown.close()
    _, err = read()
    assert "left:" in err and "6/10" not in err
    assert err.rstrip(" ").endswith("\r")  # the last thing written: the erasure


def test_bars_follow_the_terminal_rule_and_the_silence(monkeypatch):
    monkeypatch.delitem(sys.modules, "ipykernel", raising=False)
    assert isinstance(progress.bar(None, total=1), progress._Off)  # pytest: a pipe
    assert isinstance(progress.bar(False, total=1), progress._Off)
    with progress.silenced():
        assert isinstance(progress.bar(True, total=1), progress._Off)
        with progress.silenced(False):  # a quiet block stays quiet inside
            assert isinstance(progress.bar(True, total=1), progress._Off)
    forced = progress.bar(True, total=1, disable=True)  # disable: tqdm draws nothing
    assert not isinstance(forced, progress._Off)
    forced.close()
