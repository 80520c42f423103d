"""Ctrl-C while the command line starts (the package still importing): one line on
stderr and exit 130, never a traceback, whichever moment the signal lands."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent
MODEL = str(ROOT / "models" / "bus_grid.toml")


def _commands() -> list[list[str]]:
    out = [[sys.executable, "-m", "mitld_lp"]]
    script = Path(sys.executable).with_name("mitld-lp")
    if script.exists():
        out.append([str(script)])
    return out


@pytest.mark.parametrize("command", _commands(), ids=lambda c: Path(c[-1]).name)
def test_ctrl_c_during_startup_is_one_line_and_exit_130(command: list[str]) -> None:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    # The signals land within the time a whole run takes on this machine now, so that
    # most of them hit the start whether the machine is fast or loaded.
    t = time.perf_counter()
    subprocess.run([*command, "solve", MODEL, "-q"], cwd=ROOT, env=env, check=True,
                   capture_output=True, timeout=120)
    whole = time.perf_counter() - t
    delays = np.random.default_rng(7).uniform(0.05, 0.8, size=12) * whole
    interrupted = 0
    for delay in delays:
        proc = subprocess.Popen([*command, "solve", MODEL, "-q"], cwd=ROOT, env=env,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        time.sleep(float(delay))
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=120)
        if "Traceback" in err and str(ROOT / "mitld_lp") not in err:
            continue  # the signal beat Python's own start (site, runpy): no code of ours ran
        if proc.returncode == -signal.SIGINT and not err:
            continue  # it beat even Python's own handler (a loaded machine): nothing ran
        assert "Traceback" not in err, (delay, err)
        assert proc.returncode in (0, 130), (delay, proc.returncode, err)
        if proc.returncode == 130:
            interrupted += 1
            lines = err.strip().splitlines()
            assert lines and lines[-1] == "mitld-lp: interrupted", (delay, err)
            assert all(line.startswith("mitld-lp: ") for line in lines), (delay, err)
    assert interrupted >= 6  # most signals land during the start, which is what is tested
