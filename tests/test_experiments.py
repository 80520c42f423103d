"""The experiment scripts run (in their ``--quick`` setting) and reproduce what they claim.

Each script runs as a user runs it, ``python experiments/NAME.py --quick --out <tmp>``,
in a subprocess (the tests never import ``experiments/``); the files it writes and the
table it prints must hold a few numbers.  The reference values are independent of the
code: Storm's Pmax for the exact case-study models and the paper's epsilon formula
(1 - p_slow)^T.
"""

from __future__ import annotations

import csv
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
EXPERIMENTS = ROOT / "experiments"
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"

# Storm (stormpy 2.0) on the DRN export of the exact product: Pmax=? [F "target"].
STORM = {"bus_grid": 0.9244053, "bus_grid_case2": 0.9138372}
# The buses' per-step probabilities (slower, faster) in each case (the paper's Sec. V).
P_SLOW = {"bus_grid": 0.3, "bus_grid_case2": 0.4}
P_FAST = {"bus_grid": 0.8, "bus_grid_case2": 0.7}


def run_script(name: str, *argv: str, timeout: float = 900) -> subprocess.CompletedProcess:
    """``python experiments/NAME.py ARGV`` with this checkout's package first."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])}
    return subprocess.run([sys.executable, str(EXPERIMENTS / f"{name}.py"), *argv],
                          capture_output=True, text=True, timeout=timeout, env=env, cwd=ROOT)


def _run(name: str, out: Path, *extra: str) -> str:
    done = run_script(name, "--quick", "--out", str(out), *extra)
    assert done.returncode == 0, done.stderr
    return done.stdout


def _csv(path: Path) -> list[dict[str, str]]:
    with path.open(newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def _is_png(path: Path) -> bool:
    return path.is_file() and path.read_bytes()[:8] == PNG_MAGIC and path.stat().st_size > 10_000


def test_paper_table(tmp_path):
    text = _run("paper_table", tmp_path)
    assert (tmp_path / "paper_table.md").is_file()
    rows = _csv(tmp_path / "paper_table.csv")
    assert "NOT expected to match" in text and "tail of the SLOWER bus" in text
    for model in STORM:
        mine = [r for r in rows if r["model"] == model]
        exact = mine[-1]
        assert exact["T"] == "exact"
        assert float(exact["lower"]) == pytest.approx(STORM[model], abs=1e-6)
        assert float(exact["upper"]) == pytest.approx(STORM[model], abs=1e-6)
        trunc = mine[:-1]
        ts = [int(r["T"]) for r in trunc]
        assert ts == sorted(ts) and len(trunc) >= 2
        for r, t in zip(trunc, ts, strict=True):
            lower, upper = float(r["lower"]), float(r["upper"])
            # the paper's epsilon column: the slower bus's tail
            assert float(r["eps_paper_def"]) == pytest.approx((1 - P_SLOW[model]) ** t,
                                                              rel=1e-12)
            # ours: P(some bus still pending after T), buses independent
            both = (1 - (1 - P_SLOW[model]) ** t) * (1 - (1 - P_FAST[model]) ** t)
            assert float(r["eps_achieved"]) == pytest.approx(1 - both, rel=1e-12)
            assert lower < STORM[model] < upper
            assert upper - lower <= float(r["eps_achieved"]) + 1e-7
            assert int(r["states"]) < int(r["cartesian_Z"]) / 100
            assert r["certified"] == "True"
        for a, b in zip(trunc, trunc[1:], strict=False):
            assert float(a["lower"]) < float(b["lower"]) and float(a["upper"]) > float(b["upper"])
    # the paper's own column is shown, labelled
    assert "0.43264" in text and "paper's value" in text


def test_convergence(tmp_path):
    text = _run("convergence", tmp_path)
    assert _is_png(tmp_path / "convergence.png")
    assert "upper-lower" in text
    points = _csv(tmp_path / "convergence.csv")
    assert len(points) >= 3
    num = [{k: float(p[k]) for k in ("epsilon", "epsilon_achieved", "states", "lower",
                                      "upper")} for p in points]
    for p, q in zip(points, num, strict=True):
        assert p["certified"] == "True"
        assert p["truncation_points"]  # the Poisson event is truncated
        assert q["upper"] - q["lower"] <= q["epsilon_achieved"] + 1e-7
        assert q["epsilon_achieved"] <= q["epsilon"]
    for a, b in zip(num, num[1:], strict=False):
        assert b["lower"] >= a["lower"] - 1e-6 and b["upper"] <= a["upper"] + 1e-6
        assert b["states"] >= a["states"]
    assert num[-1]["upper"] - num[-1]["lower"] < num[0]["upper"] - num[0]["lower"]


def _panels(text: str) -> dict[str, dict[tuple[int, int], str]]:
    """The printed policy of case 1: situation -> cell -> action."""
    out = {}
    for line in text.split("policy per cell")[1].split("A sampled run")[0].splitlines()[1:]:
        name, _, cells = line.strip().partition(": ")
        out[name] = {(int(x), int(y)): a
                     for x, y, a in re.findall(r"\((\d+), (\d+)\):([NSEW])", cells)}
    return out


def test_policy_map(tmp_path):
    text = _run("policy_map", tmp_path)
    assert _is_png(tmp_path / "policy_map.png")
    panels = _panels(text)
    waiting = panels["waiting for both buses"]
    after_b1, after_b2 = panels["bus 1 (b1) just arrived"], panels["bus 2 (b2) just arrived"]
    every = {(x, y) for x in range(4) for y in range(4)}
    # waiting, every cell of the 4x4 grid is undecided; a bus arriving while the robot is
    # at its station (A = (1, 2), B = (3, 0)) satisfies the task at once: no action there
    assert set(waiting) == every
    assert set(after_b1) == every - {(1, 2)} and set(after_b2) == every - {(3, 0)}
    # with bus 1 just arrived, next to station A = (1, 2) the policy heads for it
    assert after_b1[(1, 1)] == "N" and after_b1[(1, 3)] == "S"
    assert after_b1[(0, 2)] == "E" and after_b1[(2, 2)] == "W"
    assert "t=0  (((0, 0), {}, {b1, b2}), (q" in text


def test_dta_figure(tmp_path):
    text = _run("dta_figure", tmp_path)
    dot = (tmp_path / "paper_dta.dot").read_text()
    assert dot.startswith("digraph")
    table = dict(re.findall(r"^\s*(locations|clocks)\s+\S+\s+(\d+)$", text, flags=re.M))
    assert table == {"locations": "5", "clocks": "2"}  # as the paper's Fig. 1: 5 locations;
    # two deadline clocks (the event clocks live in the STA)
    clocked = re.search(r"STA:\s*(\d+) with clock reduction; (\d+) with clock_reduction=False",
                        text)
    assert clocked is not None and clocked.groups() == ("0", "2")
    if shutil.which("dot"):
        assert _is_png(tmp_path / "paper_dta.png")
    else:
        assert "only the DOT file was written" in text


def test_bench_big_component_routes_agree(tmp_path):
    text = _run("bench_big_component", tmp_path)
    table = (tmp_path / "bench_big_component.md").read_text()
    rows = [[c.strip() for c in line.strip("|").split("|")]
            for line in table.splitlines() if line.startswith("| ")][1:]
    assert len(rows) == 3
    values = [float(r[2]) for r in rows]
    # the block-by-block Clarabel LP, HiGHS's simplex and interval iteration: one value
    assert max(values) - min(values) < 1e-6
    assert {r[3] for r in rows} == {"optimal"}
    assert "largest block" in text


def test_safety_tasks(tmp_path):
    """Storm's Pmax [F "accept"] on the exported product equals our bracket's lower end
    (exact models) and lies in the bracket; the figure is written."""
    _run("safety_tasks", tmp_path)
    lines = (tmp_path / "safety_tasks.md").read_text(encoding="utf-8").splitlines()
    rows = [[c.strip() for c in line.strip("|").split("|")] for line in lines
            if line.startswith("| ") and not line.startswith("| model")]
    assert {r[0] for r in rows} == {"bus_grid", "bus_puddle"}
    for _, _, lower, _, certified, storm, *_ in rows:
        assert certified == "True"
        assert float(storm) == pytest.approx(float(lower), abs=1e-6)
    puddle = next(r for r in rows if r[0] == "bus_puddle")
    assert puddle[1] == "obligation" and float(puddle[3]) < 0.9244053 - 0.1
    assert _is_png(tmp_path / "safety_policy.png")


def test_constraints(tmp_path):
    text = _run("constraints", tmp_path)
    assert _is_png(tmp_path / "constraints_steps.png")
    rows = _csv(tmp_path / "constraints_risk.csv")
    assert rows
    for row in rows:
        assert row["certified"] == "True"
        # ours against Storm's multi-objective value on the same model
        assert abs(float(row["lower"]) - float(row["storm"])) <= 1e-6
        assert float(row["risk_value"]) <= float(row["risk_bound"]) + 1e-6
    # no risk bound: the puddle changes nothing, Storm's value of the plain bus case
    assert float(rows[-1]["risk_bound"]) == 1.0
    assert float(rows[-1]["lower"]) == pytest.approx(STORM["bus_grid"], abs=1e-6)
    points = _csv(tmp_path / "constraints_steps.csv")
    lows = [float(p["probability_lower"]) for p in points]
    assert lows == sorted(lows) and all(p["certified"] == "True" for p in points)
    best, fast = re.findall(r"P = ([0-9.]+), E\(steps\) = ([0-9.]+)", text)
    assert float(fast[1]) <= float(best[1]) and float(fast[0]) >= float(best[0]) - 2e-6


def test_robust_coverage(tmp_path):
    """The coverage study from data: every robust bound is at most the true value of its
    policy (the band held, or the policy did better than its guarantee), which is at most
    the true optimum (Storm's value of the exact bus case); Storm's robust value iteration
    on the exported interval DRN agrees; the figure is written."""
    _run("robust_coverage", tmp_path)
    assert _is_png(tmp_path / "robust_coverage.png")
    runs = _csv(tmp_path / "robust_coverage_runs.csv")
    assert len(runs) == 3 * 8
    for r in runs:
        assert float(r["p_lo"]) <= float(r["p_hat"]) <= float(r["p_hi"])
        if r["band_holds"] == "True":
            assert float(r["robust_lower"]) <= float(r["true_value"]) + 1e-9
        assert float(r["true_value"]) <= STORM["bus_grid"] + 1e-6
    for row in _csv(tmp_path / "robust_coverage.csv"):
        assert 0 <= float(row["band_coverage"]) <= float(row["value_at_least_bound"]) <= 1
        assert float(row["true_optimum"]) == pytest.approx(STORM["bus_grid"], abs=1e-6)
        assert float(row["storm_abs_diff_first"]) <= 1e-6


def test_bench_drn(tmp_path):
    """The DRN writer's benchmark: every size written and read back by Storm."""
    _run("bench_drn", tmp_path)
    rows = _csv(tmp_path / "bench_drn.csv")
    assert [int(r["n"]) for r in rows] == [8, 16]
    for r in rows:
        assert int(r["transitions"]) > int(r["states"]) > 0
        assert float(r["storm_read_cpu_s"]) > 0
    assert not list(tmp_path.glob("*.drn"))  # the scratch files are removed


def test_bench_sweeps(tmp_path):
    """The sweeps benchmark: every instance solved, certified and agreeing with each of
    Storm's sound methods on the DRN; costs counted in sweeps; the case as processes;
    a ratio only beside a non-degenerate optimum."""
    _run("bench_sweeps", tmp_path)
    rows = _csv(tmp_path / "bench_sweeps.csv")
    solved = [r for r in rows if r["states"]]
    assert [r["instance"] for r in solved] == ["bus_scaled_n8_d3", "events_n8_d4"]
    for r in solved:
        assert r["storm_agrees"] == "True" and r["certified"] == "True"
        assert r["states"] == r["storm_states"]  # Storm read the same model
        assert 1e-3 <= float(r["value"]) <= 1 - 1e-3 and r["degenerate"] == "False"
        assert float(r["solve_over_storm_check"]) > 0
        assert float(r["sweep_ms"]) > 0 and float(r["solve_sweeps"]) > 0
        assert float(r["storm_check_cpu"]) > 0
        assert r["storm_best"] in {"sound_value_iteration", "interval_iteration",
                                   "optimistic_value_iteration", "topological"}
    (case,) = [r for r in rows if not r["states"]]
    assert float(case["process_cpu"]) > 0 and float(case["storm_process_cpu"]) > 0
    assert (tmp_path / "bench_sweeps.md").read_text().startswith("| instance |")


def test_bench_startup(tmp_path):
    """The start-up benchmark: the case's certified bracket and both stormpy scripts'
    values beside Storm's reference for the case, the trivial command's line, a CPU
    figure and a ratio for every process."""
    from mitld_lp import __version__

    _run("bench_startup", tmp_path, "--repeats", "1")
    rows = {r["command"]: r for r in _csv(tmp_path / "bench_startup.csv")}
    assert set(rows) >= {"ours", "version", "check", "storm_prism", "storm_drn", "python",
                         "numpy_scipy_sparse", "stormpy_import", "ours_corridor",
                         "storm_corridor"}
    lower, upper = (float(x) for x in rows["ours"]["answer"].strip("[]").split(","))
    assert abs(lower - STORM["bus_grid"]) < 1e-6 and abs(upper - STORM["bus_grid"]) < 1e-6
    for storm in ("storm_prism", "storm_drn"):
        assert abs(float(rows[storm]["answer"]) - STORM["bus_grid"]) < 1e-6
    # the corridor's Pmax=? [F<=6 "goal"] with the door open: 2816/3125 (README)
    lower, upper = (float(x) for x in rows["ours_corridor"]["answer"].strip("[]").split(","))
    assert lower - 1e-9 <= 2816 / 3125 <= upper + 1e-9
    assert abs(float(rows["storm_corridor"]["answer"]) - 2816 / 3125) < 1e-6
    assert rows["version"]["answer"] == f"mitld-lp {__version__}"
    assert all(float(r["cpu_min"]) > 0 and float(r["over_storm_prism"]) > 0
               for r in rows.values())
    assert "the case as a process is" in (tmp_path / "bench_startup.md").read_text()


def test_startup_answers(tmp_path):
    """The command line's start-up (its own SciPy and lark imports) and the library in a
    plain interpreter give the same status and bracket; the case's holds Storm's value.
    In a git checkout, also the command line of this commit's ``mitld_lp`` taken by
    ``git archive`` (``--compare HEAD``)."""
    git = shutil.which("git") is not None and (ROOT / ".git").exists()
    _run("startup_answers", tmp_path, *(["--compare", "HEAD"] if git else []))
    rows = _csv(tmp_path / "startup_answers.csv")
    ways = ("command", "library", "base") if git else ("command", "library")
    assert {(r["model"], r["way"]) for r in rows} == {
        (m, w) for m in ("bus_grid.toml", "bus_fit.toml") for w in ways}
    for model in ("bus_grid.toml", "bus_fit.toml"):
        answers = [[r[k] for k in ("status", "lower", "upper")] for r in rows
                   if r["model"] == model]
        assert all(a == answers[0] for a in answers) and answers[0][0] == "optimal"
    case = next(r for r in rows if r["model"] == "bus_grid.toml")
    assert float(case["lower"]) - 1e-6 <= STORM["bus_grid"] <= float(case["upper"]) + 1e-6


def test_bench_controllers(tmp_path):
    """The controllers' benchmark: every start-up probe answers (the two loaders the
    same action), and the tree's controller keeps lower by Storm on its chain."""
    _run("bench_controllers", tmp_path)
    starts = {r["what"]: r for r in _csv(tmp_path / "bench_controllers.csv")}
    assert starts["runtime"]["answer"] == starts["Controller.load"]["answer"] != "None"
    trees = _csv(tmp_path / "bench_trees.csv")
    assert [r["model"] for r in trees] == ["corridor.toml", "bus_grid.toml"]
    for r in trees:
        assert float(r["abs_diff"]) <= 1e-9
        assert int(r["tree_nodes"]) <= int(r["same_actions_nodes"]) <= int(r["table_rows"])


def test_sensors(tmp_path):
    """The bus case with a camera: detect 1 is the fully observed answer (Storm's value
    on the exact product, above), a missing camera can only lose, and the bracket's
    width is within the truncation's epsilon achieved."""
    text = _run("sensors", tmp_path)
    assert "camera on b1" in text and _is_png(tmp_path / "sensors.png")
    rows = {float(r["detect"]): r for r in _csv(tmp_path / "sensors.csv")}
    seen, camera = rows[1.0], rows[0.5]
    assert seen["route"] == "plain" and camera["route"] == "sensed"
    assert float(seen["lower"]) == pytest.approx(STORM["bus_grid"], abs=1e-6)
    assert float(camera["upper"]) <= STORM["bus_grid"] + 1e-7
    assert float(camera["upper"]) - float(camera["lower"]) <= float(
        camera["eps_achieved"]) + 1e-9
    if camera["storm_value"]:  # Storm on the same information-state MDP
        assert float(camera["storm_value"]) == pytest.approx(float(camera["lower"]),
                                                             abs=1e-6)


def test_bench_explore(tmp_path):
    """The explored-world benchmark: the big grid's bounded task explored to its horizon,
    the same bracket as the whole build and the small grid, Storm's value inside."""
    text = _run("bench_explore", tmp_path, "--n", "101")
    rows = {r["route"]: r for r in _csv(tmp_path / "bench_explore.csv")}
    assert set(rows) == {"ours auto (12x12)", "ours auto", "ours full", "storm"}
    answers = {rows[k]["answer"] for k in ("ours auto (12x12)", "ours auto", "ours full")}
    assert len(answers) == 1  # the same bracket, bit for bit
    lower, upper = (float(x) for x in answers.pop().strip("[]").split(", "))
    assert lower <= float(rows["storm"]["answer"]) <= upper
    assert int(rows["ours full"]["explored"]) == 101 * 101 == int(rows["storm"]["explored"])
    assert int(rows["ours auto"]["explored"]) < 101 * 101
    assert "auto / small-grid CPU" in text


def test_sensed_export(tmp_path):
    """The bus case with a camera and a risk budget: Storm's exact values on the exported
    chain meet ``lower`` and the constraint's certified bound (the script compares them
    in exact arithmetic)."""
    pytest.importorskip("stormpy")
    _run("sensed_export", tmp_path)
    (row,) = _csv(tmp_path / "sensed_export.csv")
    assert row["route"] == "sensed-constrained"
    assert row["accept>=lower"] == "True" and row["risk<=certified"] == "True"
    assert float(row["storm_risk"]) <= float(row["bound"])


def test_false_alarms(tmp_path):
    """The bus case with a camera on bus 2 with and without false alarms: Storm's exact
    value of each exported chain is the answer's ``lower`` (to the DRN's decimals)."""
    pytest.importorskip("stormpy")
    _run("false_alarms", tmp_path)
    rows = _csv(tmp_path / "false_alarms.csv")
    assert [float(row["false_alarm"]) for row in rows] == [0.0, 0.05]
    for row in rows:
        assert float(row["lower"]) <= float(row["upper"])
        assert abs(float(row["storm_accept"]) - float(row["lower"])) <= 1e-7


def test_bus_camera_band(tmp_path):
    """The bus case with a camera on bus 1, bus 2's law a band and the puddles to avoid
    always: Storm's robust check of the exported interval chain is the answer's lower
    end, within the bracket."""
    pytest.importorskip("stormpy")
    _run("bus_camera_band", tmp_path)
    (row,) = _csv(tmp_path / "bus_camera_band.csv")
    lower, upper, storm = float(row["lower"]), float(row["upper"]), float(row["storm_worst"])
    assert 0.0 < lower <= upper <= 1.0
    assert abs(storm - lower) <= 1e-9


def test_bench_sensed(tmp_path):
    """The sensed build's benchmark: each case answered on the sensed route, its
    bracket beside Storm's Pmax of the same product (Storm's value is our lower: the
    truncated runs lose in both), the build's CPU seconds apart from the whole."""
    _run("bench_sensed", tmp_path)
    rows = _csv(tmp_path / "bench_sensed.csv")
    assert [r["case"] for r in rows] == ["bus_grid b1@0.5 eps=0.01",
                                         "bus_grid b1@0.7+b2@0.7 eps=0.05",
                                         "bus_grid b2@0.8 fa=0.05 eps=0.1"]
    for r in rows:
        lower, upper = float(r["lower"]), float(r["upper"])
        assert 0 < lower <= upper < 1
        if r["storm_value"]:
            assert float(r["storm_value"]) == pytest.approx(lower, abs=1e-6)
        assert 0 < float(r["build_cpu"]) < float(r["process_cpu"])
        assert int(r["states"].replace(",", "")) > 100
