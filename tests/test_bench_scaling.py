"""experiments/bench_scaling.py: its --quick run writes well-formed outputs, every route
agrees on the value, and the independent PRISM encoding reproduces Storm's reference.

No wall-clock assertion: the times are what the script reports, not what it is tested on.
The reference 0.9244053 is Storm's Pmax on the case study (4x4 bus grid, deadline 3),
the same number tests/test_synthesis.py uses.
"""

from __future__ import annotations

import csv
import importlib
import math
import sys
from pathlib import Path

import pytest

EXPERIMENTS = Path(__file__).resolve().parent.parent / "experiments"
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
STORM_CASE1 = 0.9244053
VALUE_ROUTES = ("default", "topo_lp", "mono_lp", "highs_lp", "ii", "storm_drn",
                "storm_prism")


def _bench():
    if str(EXPERIMENTS) not in sys.path:
        sys.path.insert(0, str(EXPERIMENTS))
    return importlib.import_module("bench_scaling")


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("scaling")
    rows = _bench().main(["--quick", "--out", str(out)])
    with (out / "scaling.csv").open(newline="", encoding="utf-8") as f:
        table = list(csv.DictReader(f))
    return out, rows, table


def _values(record: dict[str, str]) -> dict[str, float]:
    return {r: float(record[f"{r}_value"]) for r in VALUE_ROUTES if record[f"{r}_value"]}


def test_outputs_are_written(quick):
    out, rows, table = quick
    bench = _bench()
    assert len(table) == len(rows) == 2
    assert list(table[0]) == bench.csv_header()
    png = out / "scaling.png"
    assert png.read_bytes()[:8] == PNG_MAGIC and png.stat().st_size > 10_000
    machine = (out / "scaling_machine.txt").read_text()
    for key in ("date:", "cpu:", "cores:", "ram:", "python:", "numpy:", "scipy:",
                "cvxpy:", "clarabel:", "stormpy:", "note:"):
        assert key in machine


def test_every_route_ran_and_agrees(quick):
    _, _, table = quick
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
    _, _, table = quick
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


def test_prism_constants_are_filled_in():
    bench = _bench()
    text = bench.Instance("bus", 16, 5).prism()
    assert "const int N = 16;" in text and "const int D = 5;" in text
    assert "const int AX = 4;" in text and "const int AY = 8;" in text
    assert "const int BX = 12;" in text and "const double P2 = 0.3;" in text
    assert "const int N;" not in text
    with pytest.raises(ValueError, match="only the bus family"):
        bench.Instance("events", 8, 4).prism()


def test_route_over_budget_is_skipped(tmp_path):
    bench = _bench()
    # Storm building a ~2.7M-state PRISM model cannot finish in 0.3 s: the child's timer
    # ends it and the route is recorded as skipped, with the budget.
    run = bench.run_route("storm_prism", bench.Instance("bus", 128, 10), tmp_path, 0.3, None)
    assert run.status == "skipped" and "0.3 s budget" in run.note
    assert run.value is None and run.peak_mb is not None and run.peak_mb > 0


def test_quick_never_writes_into_the_results():
    bench = _bench()
    with pytest.raises(SystemExit) as exc:
        bench.main(["--quick", "--out", str(bench.RESULTS)])
    assert exc.value.code == 2


def test_bad_arguments_are_refused(capsys):
    bench = _bench()
    with pytest.raises(SystemExit):
        bench.main(["--budget", "0"])
    assert "--budget: must be positive" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        bench.main(["--bus-sizes", "0"])
    assert "--bus-sizes: must be positive" in capsys.readouterr().err
    assert math.isfinite(bench.AGREE_TOL)
