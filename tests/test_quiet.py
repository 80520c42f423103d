"""Nothing but the answer on standard output: native libraries (HiGHS's banner, Storm's
logger) write to file descriptor 1 under Python, so these run the command in a fresh
process and read its real stdout."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

MODELS = Path(__file__).resolve().parents[1] / "models"


def _run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "mitld_lp", *args], capture_output=True,
                          text=True, timeout=300, check=False)


def test_solve_with_highs_prints_only_json() -> None:
    done = _run("solve", str(MODELS / "bus_grid.toml"), "--solver", "HIGHS", "--json", "-q")
    assert done.returncode == 0, done.stderr
    data = json.loads(done.stdout)  # the whole of stdout is one JSON object
    assert data["lp"]["solver"] == "HIGHS" and data["certified"]
    assert "HiGHS" not in done.stderr  # -q: quiet on stderr too


def test_export_lp_prints_only_what_it_wrote(tmp_path: Path) -> None:
    out = tmp_path / "bus.lp"
    done = _run("export", str(MODELS / "bus_grid.toml"), "--lp", str(out), "-q")
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines() == [f"wrote {out}"]
    assert out.read_text().strip()


def test_highs_lines_go_to_the_verbose_log() -> None:
    done = _run("solve", str(MODELS / "bus_grid.toml"), "--solver", "HIGHS", "-v")
    assert done.returncode == 0, done.stderr
    assert "Running HiGHS" not in done.stdout
    assert "mitld-lp: highs: Running HiGHS" in done.stderr
