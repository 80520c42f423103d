"""experiments/bench_scaling.py: its --quick run writes well-formed outputs, every route
agrees on the value, the independent PRISM encoding reproduces Storm's reference, a
route over its budget is stopped, and bad arguments are refused.

The script runs as a user runs it, in a subprocess (the tests never import
``experiments/``); a single route runs through its ``--worker`` interface, as the
script's own parent runs it.  No wall-clock assertion: the times are what the script
reports, not what it is tested on.  The reference 0.9244053 is Storm's Pmax on the
case study (4x4 bus grid, deadline 3), the same number tests/test_synthesis.py uses.
"""

from __future__ import annotations

import csv
import datetime as dt
import importlib.metadata as md
import json
import os
import platform
import signal
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SCRIPT = ROOT / "experiments" / "bench_scaling.py"
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
STORM_CASE1 = 0.9244053
ROUTES = ("build", "default", "topo_lp", "mono_lp", "highs_lp", "ii", "storm_drn",
          "storm_prism")
VALUE_ROUTES = ROUTES[1:]


def _bench(*argv: str, timeout: float = 900) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])}
    return subprocess.run([sys.executable, str(SCRIPT), *argv], capture_output=True,
                          text=True, timeout=timeout, env=env, cwd=ROOT)


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("scaling")
    done = _bench("--quick", "--out", str(out))
    assert done.returncode == 0, done.stderr
    with (out / "scaling.csv").open(newline="", encoding="utf-8") as f:
        table = list(csv.DictReader(f))
    return out, table


def _values(record: dict[str, str]) -> dict[str, float]:
    return {r: float(record[f"{r}_value"]) for r in VALUE_ROUTES if record[f"{r}_value"]}


def test_outputs_are_written(quick):
    out, table = quick
    assert len(table) == 2
    header = list(table[0])
    assert header[:4] == ["family", "n", "deadline", "budget_s"]
    for route in ROUTES:
        for column in ("status", "s", "mb", "value", "note"):
            assert f"{route}_{column}" in header
    assert {"max_diff", "max_rel_diff"} <= set(header)
    png = out / "scaling.png"
    assert png.read_bytes()[:8] == PNG_MAGIC and png.stat().st_size > 10_000


def test_the_machine_file_says_what_this_machine_is(quick):
    # every fact read again here, another way: the sidecar must be true, not just present
    out, _ = quick
    facts = dict(line.split(": ", 1) for line in
                 (out / "scaling_machine.txt").read_text().splitlines() if ": " in line)
    assert facts["cores"] == str(os.cpu_count())
    assert facts["python"] == platform.python_version()
    for package in ("numpy", "scipy", "cvxpy", "clarabel", "stormpy"):
        assert facts[package] == md.version(package), package
    kb = int(Path("/proc/meminfo").read_text().split("MemTotal:")[1].split()[0])
    assert float(facts["ram"].removesuffix(" GiB")) == pytest.approx(kb / 2**20, abs=0.06)
    written = dt.datetime.fromisoformat(facts["date"])
    assert abs((dt.datetime.now(dt.UTC) - written).total_seconds()) < 3600
    assert facts["note"]


def test_every_route_ran_and_agrees(quick):
    _, table = quick
    allowed = {"optimal", "unavailable", "n/a"}
    for rec in table:
        assert rec["build_status"] == "built"
        states = int(rec["build_states"])
        assert states > 0 and int(rec["build_transitions"]) >= int(rec["build_choices"])
        # the default route built the same product as the build route
        assert int(rec["default_states"]) == states
        assert rec["default_certified"] == "True"
        for route in VALUE_ROUTES:
            assert rec[f"{route}_status"] in allowed, (route, rec[f"{route}_note"])
            if rec[f"{route}_status"] == "optimal":
                assert float(rec[f"{route}_s"]) >= 0 and float(rec[f"{route}_mb"]) > 0
        # the decomposed LP is either there and solved, or reported unavailable
        assert rec["topo_lp_status"] in ("optimal", "unavailable")
        values = _values(rec)
        assert {"default", "mono_lp", "highs_lp", "ii", "storm_drn"} <= set(values)
        spread = max(values.values()) - min(values.values())
        assert spread <= 1e-6
        assert float(rec["max_diff"]) == pytest.approx(spread, abs=2e-10)  # CSV: 10 decimals
        # interval iteration's sound bracket holds the LP's value, up to the interior
        # point solver's accuracy (a few 1e-9 at tolerance 1e-9)
        lo, hi = float(rec["ii_value"]), float(rec["ii_upper"])
        assert lo - 1e-7 <= values["mono_lp"] <= hi + 1e-7
        assert lo - 1e-7 <= values["storm_drn"] <= hi + 1e-7


def test_prism_encoding_reproduces_the_case_study(quick):
    _, table = quick
    (bus,) = [r for r in table if r["family"] == "bus"]
    assert (bus["n"], bus["deadline"]) == ("4", "3")
    assert bus["storm_prism_status"] == "optimal"
    assert float(bus["storm_prism_value"]) == pytest.approx(STORM_CASE1, abs=1e-6)
    for route, value in _values(bus).items():
        assert value == pytest.approx(STORM_CASE1, abs=1e-6), route
    # PRISM's state space is its own (no automaton, no collapsing): not ours
    assert int(bus["storm_prism_states"]) > 0
    assert float(bus["ratio_default_over_storm_prism"]) > 0
    (events,) = [r for r in table if r["family"] == "events"]
    assert events["storm_prism_status"] == "n/a" and events["storm_prism_value"] == ""
    assert events["ratio_default_over_storm_prism"] == ""
    # the events family is truncated: its upper model is not below its lower one
    assert float(events["default_upper"]) >= float(events["default_value"]) - 1e-9


def _worker(route: str, family: str, n: int, d: int, work: Path, budget: float):
    instance = json.dumps({"family": family, "n": n, "d": d})
    return _bench("--worker", route, "--instance", instance, "--work", str(work),
                  "--budget", str(budget), timeout=120)


def test_a_route_over_budget_is_stopped_and_the_prism_constants_are_filled_in(tmp_path):
    # Storm building a ~2.7M-state PRISM model cannot finish in 0.3 s: the child's timer
    # (SIGALRM, default action) ends it, which the parent records as skipped.
    done = _worker("storm_prism", "bus", 128, 10, tmp_path, 0.3)
    assert done.returncode == -signal.SIGALRM, done.stderr
    assert not (tmp_path / "storm_prism.json").exists()
    # the PRISM program it was given: the template with the instance's constants, the
    # stations at the 4x4 layout scaled (A = (n//4, n//2), B = (3n//4, 0))
    text = (tmp_path / "bus_n128_d10.prism").read_text()
    for line in ("const int N = 128;", "const int D = 10;", "const int AX = 32;",
                 "const int AY = 64;", "const int BX = 96;", "const int BY = 0;",
                 "const double P1 = 0.8;", "const double P2 = 0.3;"):
        assert line in text
    assert "const int N;" not in text


def test_only_the_bus_family_has_a_prism_encoding(tmp_path):
    done = _worker("storm_prism", "events", 8, 4, tmp_path, 60)
    assert done.returncode == 0, done.stderr
    report = json.loads((tmp_path / "storm_prism.json").read_text())
    assert report["status"] == "failed" and "only the bus family" in report["note"]


def test_quick_never_writes_into_the_results():
    done = _bench("--quick", "--out", str(ROOT / "experiments" / "results"))
    assert done.returncode == 2 and "--quick never writes into" in done.stderr


@pytest.mark.parametrize(("argv", "says"), [
    (["--budget", "0"], "--budget: must be positive"),
    (["--bus-sizes", "0"], "--bus-sizes: must be positive"),
])
def test_bad_arguments_are_refused(argv, says):
    done = _bench(*argv)
    assert done.returncode == 2 and says in done.stderr
