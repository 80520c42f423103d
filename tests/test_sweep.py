"""Sweeps: rows equal ``solve`` on model files written here; serial, a process pool and a
Dask cluster give the same rows; an interrupted sweep resumes with the missing points;
failures are rows; a results file of another sweep is never overwritten."""

from __future__ import annotations

import csv
import itertools
import json
import math
from pathlib import Path

import pytest

from mitld_lp.cli import main
from mitld_lp.sweep import TIME_COLUMNS, SweepError, load_sweep, run_sweep, sweep
from mitld_lp.sweep.results import read_results

# A tiny world: a 3x2 grid, a bus (geometric) and a deadline after it.
MODEL = """\
name = "tiny"
spec = "D[mu] b & F(b & F[0,{T}] A)"
[constants]
T = 2
[grid]
size = [3, 2]
start = [0, 0]
slip = 0.1
[regions]
A = [[2, 1]]
[distributions]
mu = { geometric = 0.5 }
"""
# The same model written out by hand for one point (no constants, no sweep code).
BY_HAND = """\
name = "tiny"
spec = "D[mu] b & F(b & F[0,%d] A)"
[grid]
size = [3, 2]
start = [0, 0]
slip = %r
[regions]
A = [[2, 1]]
[distributions]
mu = { geometric = %r }
"""
T_VALUES, SLIPS, RATES = [1, 2, 3], [0.0, 0.2], [0.3, 0.6]
SWEEP = f"""\
name = "tiny_sweep"
model = "tiny.toml"
[vary]
constants.T = {T_VALUES}
grid.slip = {SLIPS}
distributions.mu.geometric = {RATES}
"""
PARAMS = ["constants.T", "grid.slip", "distributions.mu.geometric"]
COMPARED = ["status", "certified", "lower", "upper", "value", "states", "choices",
            "transitions", "dta_states", "epsilon_achieved"]


@pytest.fixture()
def files(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "tiny.toml").write_text(MODEL)
    (tmp_path / "tiny_sweep.toml").write_text(SWEEP)
    return tmp_path


def _strip(rows):
    return [{k: v for k, v in r.items() if k not in TIME_COLUMNS} for r in rows]


def _by_point(rows):
    return sorted(_strip(rows), key=lambda r: json.dumps([r[p] for p in PARAMS]))


def test_each_row_equals_solve_on_the_model_file_written_by_hand(files, capsys):
    run = run_sweep(files / "tiny_sweep.toml")
    assert run.computed == 12 and run.reused == 0 and len(run.rows) == 12
    points = list(itertools.product(T_VALUES, SLIPS, RATES))  # the grid, last fastest
    assert [tuple(r[p] for p in PARAMS) for r in run.rows] == points
    for (t, slip, rate), row in zip(points, run.rows, strict=True):
        model = files / f"point_{t}_{slip}_{rate}.toml"
        model.write_text(BY_HAND % (t, slip, rate))
        assert main(["solve", str(model), "--json", "-q"]) == 0
        solved = json.loads(capsys.readouterr().out)
        for column in COMPARED:
            assert row[column] == solved[column], (t, slip, rate, column)
        assert row["error"] is None and row["certified"] is True
    # a longer deadline never hurts, a faster bus never hurts here: a sanity check on
    # the numbers themselves, not only on their agreement
    lower = {tuple(r[p] for p in PARAMS): r["lower"] for r in run.rows}
    for t, slip, rate in points:
        if t > 1:
            assert lower[t, slip, rate] >= lower[t - 1, slip, rate] - 1e-9


def test_a_point_with_no_slip_has_the_hand_computed_value(files):
    # Without slip the robot walks E, E, N from (0, 0) and is at A = (2, 1) from step 3
    # on (pushing into the wall keeps it there).  The bus arrives at step k >= 1 with
    # probability p (1-p)^(k-1); the task holds when the robot is at A at a step in
    # [k, k + T].  T = 3: always (k + 3 >= 3).  T = 1: exactly when k >= 2, 1 - p.
    run = run_sweep(files / "tiny_sweep.toml")
    checked = 0
    for r in run.rows:
        p, slip = r["distributions.mu.geometric"], r["grid.slip"]
        if slip == 0.0 and r["constants.T"] in (1, 3):
            expected = 1.0 if r["constants.T"] == 3 else 1 - p
            assert r["lower"] == pytest.approx(expected, abs=1e-9)
            checked += 1
    assert checked == 4


@pytest.fixture(scope="module")
def cluster():
    distributed = pytest.importorskip("dask.distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                  protocol="tcp", dashboard_address=":0") as local:
        yield local


def test_serial_pool_and_dask_give_the_same_rows(files, capsys, cluster):
    serial = run_sweep(files / "tiny_sweep.toml", "serial.csv")
    assert main(["sweep", "tiny_sweep.toml", "-o", "pool.csv", "--workers", "2", "-q"]) == 0
    address = cluster.scheduler_address
    assert address.startswith("tcp://127.0.0.1:")
    assert main(["sweep", "tiny_sweep.toml", "-o", "dask.csv", "--dask", address, "-q"]) == 0
    out = capsys.readouterr().out
    assert "12 solved now, 0 already in dask.csv" in out
    expected = _by_point(serial.rows)
    assert len(expected) == 12
    for name in ("serial.csv", "pool.csv", "dask.csv"):
        columns, rows, dropped = read_results(files / name)
        assert dropped == 0 and len(rows) == 12
        assert _by_point(rows) == expected, name


def test_an_interrupted_sweep_computes_only_the_missing_points(files):
    seen = []

    def stop_after_five(row):
        seen.append(row)
        if len(seen) == 5:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_sweep(files / "tiny_sweep.toml", "r.csv", on_row=stop_after_five)
    assert len(read_results(files / "r.csv")[1]) == 5
    again = run_sweep(files / "tiny_sweep.toml", "r.csv")
    assert (again.computed, again.reused) == (7, 5)
    assert _by_point(read_results(files / "r.csv")[1]) == _by_point(
        run_sweep(files / "tiny_sweep.toml").rows)
    third = run_sweep(files / "tiny_sweep.toml", "r.csv")
    assert (third.computed, third.reused) == (0, 12)


def test_a_line_cut_short_is_dropped_and_its_point_computed_again(files):
    run_sweep(files / "tiny_sweep.toml", "r.csv")
    text = (files / "r.csv").read_text()
    lines = text.splitlines()
    cut = "\n".join(lines[:-1]) + "\n" + lines[-1][: len(lines[-1]) // 2]  # no newline
    (files / "r.csv").write_text(cut)
    again = run_sweep(files / "tiny_sweep.toml", "r.csv")
    assert (again.computed, again.reused) == (1, 11)
    columns, rows, dropped = read_results(files / "r.csv")
    assert dropped == 0 and len(rows) == 12


def test_a_sweep_extended_with_values_reuses_its_points(files):
    run_sweep(files / "tiny_sweep.toml", "r.csv")
    (files / "tiny_sweep.toml").write_text(SWEEP.replace("[1, 2, 3]", "[1, 2, 3, 4]"))
    more = run_sweep(files / "tiny_sweep.toml", "r.csv")
    assert (more.computed, more.reused) == (4, 12)


def test_failed_points_are_rows_and_the_sweep_goes_on(files, capsys):
    (files / "bad.toml").write_text(
        'name = "bad"\nmodel = "tiny.toml"\n[vary]\ngrid.slip = [0.1, 0.7, 0.2]\n')
    assert main(["sweep", "bad.toml", "-o", "bad.csv", "-q"]) == 2
    out = capsys.readouterr().out
    assert "1 model_error" in out and "2 optimal" in out
    assert "grid.slip = 0.7: " in out and "grid.slip: must be in [0, 0.5], got 0.7" in out
    rows = read_results(files / "bad.csv")[1]
    assert [r["status"] for r in rows] == ["optimal", "model_error", "optimal"]
    bad = rows[1]
    assert bad["certified"] is False and bad["lower"] is None
    assert bad["error"].endswith("tiny.toml: grid.slip: must be in [0, 0.5], got 0.7")
    # a rerun leaves the failure alone; --retry-failed solves it again (and fails again)
    assert run_sweep(files / "bad.toml", "bad.csv").computed == 0
    assert run_sweep(files / "bad.toml", "bad.csv", retry_failed=True).computed == 1


def test_a_budget_stop_is_a_row(files):
    (files / "small.toml").write_text(SWEEP.replace('name = "tiny_sweep"', 'name = "small"')
                                      + "[solve]\nmax_states = 2\n")
    run = run_sweep(files / "small.toml")
    assert {r["status"] for r in run.rows} == {"budget"}
    assert all("more than 2 " in r["error"] for r in run.rows)  # the budget is named


def test_a_results_file_of_another_sweep_is_never_overwritten(files, capsys):
    run_sweep(files / "tiny_sweep.toml", "r.csv")
    before = (files / "r.csv").read_bytes()
    (files / "other.toml").write_text(SWEEP.replace('name = "tiny_sweep"', 'name = "other"'))
    assert main(["sweep", "other.toml", "-o", "r.csv", "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "holds results of sweep 'tiny_sweep'" in err[0]
    assert "--force" in err[0]
    assert (files / "r.csv").read_bytes() == before
    # a file that is no results file at all is refused too
    (files / "data.csv").write_text("x,y\n1,2\n")
    with pytest.raises(SweepError, match="is not the results file of a sweep"):
        run_sweep(files / "other.toml", "data.csv")
    assert (files / "data.csv").read_text() == "x,y\n1,2\n"
    # a changed base model is another sweep
    (files / "tiny.toml").write_text(MODEL.replace("slip = 0.1", "slip = 0.15"))
    with pytest.raises(SweepError, match="holds results of sweep 'tiny_sweep'"):
        run_sweep(files / "tiny_sweep.toml", "r.csv")
    # --force starts anew
    assert main(["sweep", "other.toml", "-o", "r.csv", "-q", "--force"]) == 0
    rows = read_results(files / "r.csv")[1]
    assert len(rows) == 12 and {r["sweep"] for r in rows} == {"other"}


def test_parquet_results_equal_the_csv_ones(files):
    pytest.importorskip("pyarrow")
    a = run_sweep(files / "tiny_sweep.toml", "r.csv")
    b = run_sweep(files / "tiny_sweep.toml", "r.parquet")
    assert b.computed == 12
    assert _by_point(read_results(files / "r.parquet")[1]) == _by_point(a.rows)
    assert run_sweep(files / "tiny_sweep.toml", "r.parquet").computed == 0


def test_sweep_returns_a_data_frame_or_records(files, monkeypatch):
    pd = pytest.importorskip("pandas")
    frame = sweep(files / "tiny_sweep.toml")
    assert isinstance(frame, pd.DataFrame) and len(frame) == 12
    assert list(frame.columns[:5]) == ["sweep", "sweep_id", *PARAMS]
    assert frame["certified"].all()
    monkeypatch.setitem(__import__("sys").modules, "pandas", None)  # not installed
    records = sweep(files / "tiny_sweep.toml")
    assert isinstance(records, list) and len(records) == 12
    assert math.isclose(records[0]["lower"], frame["lower"].iloc[0])


def test_the_csv_is_tidy(files):
    run_sweep(files / "tiny_sweep.toml", "r.csv")
    with (files / "r.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 12
    assert rows[0]["constants.T"] == "1" and rows[0]["grid.slip"] == "0.0"
    assert rows[0]["certified"] == "True" and float(rows[0]["lower"]) > 0


@pytest.mark.parametrize(
    "text, message",
    [
        ('name = "s"\nmodel = "tiny.toml"\nvaryy = 1\n', "s.toml: varyy: unknown key"),
        ('model = "tiny.toml"\n', "s.toml: name: missing (required)"),
        ('name = "s"\nmodel = "nope.toml"\n', "s.toml: model: cannot read the model file "
                                              "nope.toml"),
        ('name = "s"\nmodel = "tiny.toml"\n[vary]\ngrid.slipp = [0.1]\n',
         "s.toml: vary.grid.slipp: the model file has no key grid.slipp (allowed: obstacles, "
         "size, slip, start, stay)"),
        ('name = "s"\nmodel = "tiny.toml"\n[vary]\nregions.B.x = [0.1]\n',
         "s.toml: vary.regions.B.x: the model (tiny.toml with [set]) has no regions.B; give it"
         " a value under [set] first"),
        ('name = "s"\nmodel = "tiny.toml"\n[vary]\ngrid.slip = 0.1\n',
         "s.toml: vary.grid.slip: must be a list of values, got 0.1"),
        ('name = "s"\nmodel = "tiny.toml"\n[points]\ngrid.slip = [0.1]\nepsilon = [0.1, 0.2]\n',
         "s.toml: points.epsilon: has 2 values, points.grid.slip has 1"),
        ('name = "s"\nmodel = "tiny.toml"\n[solve]\nmethod = "simplex"\n',
         's.toml: solve.method: must be "lp" or "vi", got "simplex"'),
        ('name = "s"\nmodel = "tiny.toml"\n[set]\ngrid.slip = 0.9\n',
         "s.toml: model: tiny.toml with [set] does not load: "),
        # one key-path context for sweep and model files (model_keys): the same wording
        ('name = "s"\nmodel = "tiny.toml"\n[solve]\nmethd = "lp"\n',
         "s.toml: solve.methd: unknown key (allowed: backend, bands, certify_tol, "
         "clock_reduction, "),
        ('name = "s"\nmodel = "tiny.toml"\nvary = 3\n',
         "s.toml: vary: must be a table, got an integer 3"),
        ('name = "s"\nmodel = "tiny.toml"\n"a b" = 1\n', 's.toml: "a b": unknown key'),
    ],
)
def test_sweep_file_errors_are_one_line_with_the_key_path(files, capsys, text, message):
    (files / "s.toml").write_text(text)
    assert main(["sweep", "s.toml", "-q"]) == 2
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("mitld-lp: error: " + message), err
    assert captured.out == "" and not (files / "s.csv").exists()


def test_a_model_file_error_in_a_sweep_names_both_key_paths(files, capsys):
    """A value under [set] that the model file refuses: the sweep's key path and the
    model file's own (the same context words both)."""
    (files / "s.toml").write_text('name = "s"\nmodel = "tiny.toml"\n[set]\ngrid.slip = "x"\n')
    assert main(["sweep", "s.toml", "-q"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("mitld-lp: error: s.toml: model: tiny.toml with [set] does not load")
    assert err.endswith('tiny.toml: grid.slip: must be a number, got a string "x"')
    assert "\n" not in err


def test_points_and_set_and_a_whole_law_varied(files):
    (files / "s.toml").write_text(
        'name = "s"\nmodel = "tiny.toml"\n'
        "[set]\nconstants.T = 3\n"
        "[points]\ngrid.slip = [0.0, 0.0]\nepsilon = [0.01, 0.2]\n"
        "[vary]\ndistributions.mu = [{ geometric = 0.5 }, { uniform = [1, 4] }]\n")
    sw = load_sweep(files / "s.toml")
    assert sw.columns == ("grid.slip", "epsilon", "distributions.mu")
    assert len(sw.points) == 4
    run = run_sweep(sw)
    # slip 0 and T = 3: the robot is at A from step 3 on, in time for any arrival
    assert all(r["lower"] == pytest.approx(1.0, abs=1e-9) for r in run.rows)
    assert [r["distributions.mu"] for r in run.rows][:2] == [{"geometric": 0.5},
                                                            {"uniform": [1, 4]}]


SLOW_WORLD = """\
import time
from mitld_lp import GridWorld

def corridor(n=3, pause=0.0):
    time.sleep(pause)
    return GridWorld.make(n, 1, start=(0, 0), regions={"goal": [(n - 1, 0)]})
"""


def test_a_killed_sweep_run_again_computes_only_the_missing_points(files, capsys):
    import os
    import signal
    import subprocess
    import sys
    import time

    (files / "slow_world.py").write_text(SLOW_WORLD)
    (files / "slow.toml").write_text('name = "slow"\nspec = "F[0,6] goal"\n[python]\n'
                                     'world = "slow_world:corridor"\n'
                                     "kwargs = { n = 2, pause = 0.25 }\n")
    (files / "s.toml").write_text('name = "s"\nmodel = "slow.toml"\n[vary]\n'
                                  f"python.kwargs.n = {list(range(2, 14))}\n")
    root = Path(__file__).resolve().parent.parent
    env = {**os.environ, "PYTHONPATH": str(root)}
    proc = subprocess.Popen([sys.executable, "-m", "mitld_lp", "sweep", "s.toml", "-o", "r.csv",
                             "-q"], cwd=files, env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and proc.poll() is None:
            path = files / "r.csv"
            if path.exists() and path.read_text().count("\n") >= 4:  # header + 3 rows
                break
            time.sleep(0.02)
        assert proc.poll() is None, "the sweep ended before it could be killed"
        proc.send_signal(signal.SIGKILL)
    finally:
        proc.wait()
    present = len(read_results(files / "r.csv")[1])
    assert 3 <= present < 12
    assert main(["sweep", "s.toml", "-o", "r.csv", "-q"]) == 0
    out = capsys.readouterr().out
    assert f"{12 - present} solved now, {present} already in r.csv" in out
    columns, rows, dropped = read_results(files / "r.csv")
    assert dropped == 0 and len(rows) == 12
    assert sorted(r["python.kwargs.n"] for r in rows) == list(range(2, 14))
    # a corridor of n cells is crossed in n - 1 moves: within 6 steps for n <= 7
    assert all(r["lower"] == pytest.approx(1.0 if r["python.kwargs.n"] <= 7 else 0.0)
               for r in rows)


DYING_WORLD = """\
import os
from pathlib import Path
from mitld_lp import GridWorld

def corridor(n=3, marker=""):
    if n == 3 and not Path(marker).exists():  # the first worker to load it dies
        Path(marker).write_text("died once")
        os._exit(1)
    return GridWorld.make(n, 1, start=(0, 0), regions={"goal": [(n - 1, 0)]})
"""


def test_a_lost_dask_worker_s_point_runs_again_elsewhere(files):
    distributed = pytest.importorskip("dask.distributed")
    (files / "dying_world.py").write_text(DYING_WORLD)
    marker = files / "died"
    (files / "dying.toml").write_text(
        'name = "dying"\nspec = "F[0,3] goal"\n[python]\nworld = "dying_world:corridor"\n'
        f'kwargs = {{ n = 2, marker = "{marker}" }}\n')
    (files / "s.toml").write_text('name = "s"\nmodel = "dying.toml"\n[vary]\n'
                                  "python.kwargs.n = [2, 3, 4]\n")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=":0") as local:
        run = run_sweep(files / "s.toml", "r.csv", dask=local.scheduler_address)
    assert marker.exists()  # a worker did die
    assert [r["status"] for r in run.rows] == ["optimal"] * 3
    assert [r["lower"] for r in run.rows] == pytest.approx([1.0, 1.0, 1.0])


def test_a_sweep_asks_its_precision_and_keeps_its_identity_at_the_default(files):
    plain = load_sweep(files / "tiny_sweep.toml")
    (files / "fine.toml").write_text(SWEEP + "[solve]\nprecision = 1e-3\n")
    (files / "same.toml").write_text(SWEEP + "[solve]\nprecision = 1e-6\n")
    fine, same = load_sweep(files / "fine.toml"), load_sweep(files / "same.toml")
    assert fine.settings.precision == 1e-3 and plain.settings.precision == 1e-6
    # the default's identity is the one results files were written under before
    assert same.sweep_id == plain.sweep_id != fine.sweep_id
    (files / "bad.toml").write_text(SWEEP + "[solve]\nprecision = 2\n")
    with pytest.raises(SweepError, match="solve.precision: must be a number in"):
        load_sweep(files / "bad.toml")
