"""The experiment scripts run (in their ``--quick`` setting) and reproduce what they claim.

Each script's ``main`` is called with ``--quick --out <tmp>``; the files must be written
and a few numbers must hold.  The reference values are independent of the code: Storm's
Pmax for the exact case-study models and the paper's epsilon formula (1 - p_slow)^T.
"""

from __future__ import annotations

import importlib
import shutil
import sys
from pathlib import Path

import pytest

EXPERIMENTS = Path(__file__).resolve().parent.parent / "experiments"
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"

# Storm (stormpy 2.0) on the DRN export of the exact product: Pmax=? [F "target"].
STORM = {"bus_grid": 0.9244053, "bus_grid_case2": 0.9138372}
# The buses' per-step probabilities (slower, faster) in each case (the paper's Sec. V).
P_SLOW = {"bus_grid": 0.3, "bus_grid_case2": 0.4}
P_FAST = {"bus_grid": 0.8, "bus_grid_case2": 0.7}


def _script(name: str):
    if str(EXPERIMENTS) not in sys.path:
        sys.path.insert(0, str(EXPERIMENTS))
    return importlib.import_module(name)


def _run(name: str, out: Path, capsys, *extra: str):
    result = _script(name).main(["--quick", "--out", str(out), *extra])
    return result, capsys.readouterr().out


def _is_png(path: Path) -> bool:
    return path.is_file() and path.read_bytes()[:8] == PNG_MAGIC and path.stat().st_size > 10_000


def test_paper_table(tmp_path, capsys):
    rows, text = _run("paper_table", tmp_path, capsys)
    assert (tmp_path / "paper_table.md").is_file()
    csv = (tmp_path / "paper_table.csv").read_text().splitlines()
    assert len(csv) == 1 + len(rows)
    assert "NOT expected to match" in text and "tail of the SLOWER bus" in text
    for model in STORM:
        mine = [r for r in rows if r.model == model]
        exact = mine[-1]
        assert exact.T is None
        assert exact.lower == pytest.approx(STORM[model], abs=1e-6)
        assert exact.upper == pytest.approx(STORM[model], abs=1e-6)
        trunc = mine[:-1]
        assert [r.T for r in trunc] == sorted(r.T for r in trunc) and len(trunc) >= 2
        for r in trunc:
            # the paper's epsilon column: the slower bus's tail
            assert r.eps_paper == pytest.approx((1 - P_SLOW[model]) ** r.T, rel=1e-12)
            # ours: P(some bus still pending after T), buses independent
            both = (1 - (1 - P_SLOW[model]) ** r.T) * (1 - (1 - P_FAST[model]) ** r.T)
            assert r.eps_ours == pytest.approx(1 - both, rel=1e-12)
            assert r.lower < STORM[model] < r.upper
            assert r.upper - r.lower <= r.eps_ours + 1e-7
            assert r.states < r.cartesian / 100
        for a, b in zip(trunc, trunc[1:], strict=False):
            assert a.lower < b.lower and a.upper > b.upper
    # the paper's own column is shown, labelled
    assert "0.43264" in text and "paper's value" in text


def test_convergence(tmp_path, capsys):
    points, text = _run("convergence", tmp_path, capsys)
    assert _is_png(tmp_path / "convergence.png")
    assert (tmp_path / "convergence.csv").is_file()
    assert "upper-lower" in text
    assert len(points) >= 3
    for p in points:
        assert p.certified
        assert p.truncation  # the Poisson event is truncated
        assert p.upper - p.lower <= p.epsilon_achieved + 1e-7
        assert p.epsilon_achieved <= p.epsilon
    for a, b in zip(points, points[1:], strict=False):
        assert b.lower >= a.lower - 1e-6 and b.upper <= a.upper + 1e-6
        assert b.states >= a.states
    assert points[-1].upper - points[-1].lower < points[0].upper - points[0].lower


def test_policy_map(tmp_path, capsys):
    panels_per_case, text = _run("policy_map", tmp_path, capsys)
    assert _is_png(tmp_path / "policy_map.png")
    waiting, after_b1, after_b2 = panels_per_case[0]
    assert waiting.pending == frozenset({"b1", "b2"})
    assert after_b1.pending == frozenset({"b2"}) and after_b2.pending == frozenset({"b1"})
    # a bus arriving while the robot is at its station satisfies the task at once
    assert after_b1.automaton[(1, 2)] is None and after_b2.automaton[(3, 0)] is None
    # every other cell of the three situations is a product state with an action
    for panel in (waiting, after_b1, after_b2):
        live = [c for c, q in panel.automaton.items() if q is not None]
        assert len(live) >= 15
        assert all(panel.actions[c] in {"N", "S", "E", "W"} for c in live)
        assert all(0.0 < panel.values[c] <= 1.0 for c in live)
    # with bus 1 just arrived, next to station A = (1, 2) the policy heads for it
    assert after_b1.actions[(1, 1)] == "N" and after_b1.actions[(1, 3)] == "S"
    assert "t=0  (((0, 0), {}, {b1, b2}), (q" in text


def test_dta_figure(tmp_path, capsys):
    sizes, text = _run("dta_figure", tmp_path, capsys)
    dot = (tmp_path / "paper_dta.dot").read_text()
    assert dot.startswith("digraph")
    assert sizes.locations == 5  # as the paper's Fig. 1
    assert sizes.clocks == 2  # the deadline clocks; the event clocks live in the STA
    assert sizes.sta_clocks == 0 and sizes.sta_clocks_paper == 2
    if shutil.which("dot"):
        assert _is_png(tmp_path / "paper_dta.png")
    else:
        assert "only the DOT file was written" in text


def test_bench_big_component_routes_agree(tmp_path, capsys):
    rows, text = _run("bench_big_component", tmp_path, capsys)
    assert (tmp_path / "bench_big_component.md").is_file()
    values = [float(r[2]) for r in rows]
    # the block-by-block Clarabel LP, HiGHS's simplex and interval iteration: one value
    assert max(values) - min(values) < 1e-6
    assert {r[3] for r in rows} == {"optimal"}
    assert "largest block" in text


def test_constraints(tmp_path, capsys):
    rows, points, (best, fast) = _run("constraints", tmp_path, capsys)[0]
    assert _is_png(tmp_path / "constraints_steps.png")
    assert (tmp_path / "constraints_risk.csv").is_file()
    for row in rows:
        assert row[7]  # certified
        assert abs(row[1] - row[3]) <= 1e-6  # ours against Storm's multi-objective value
        assert row[5] <= row[0] + 1e-6  # the risk bound holds on the policy
    # no risk bound: the puddle changes nothing, Storm's value of the plain bus case
    assert rows[-1][0] == 1.0 and rows[-1][1] == pytest.approx(STORM["bus_grid"], abs=1e-6)
    assert [p.lower for p in points] == sorted(p.lower for p in points)
    assert all(p.certified for p in points)
    assert fast.steps <= best.steps + 1e-9 and fast.lower >= best.lower - 2e-6
