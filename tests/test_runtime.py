"""The runtime (issue 32, part 3): a saved controller acts with NumPy alone, and
``mitld-lp run`` answers JSON observations line by line.

Independent routes: the observations come from a simulation of the grid world and of
the bus arrivals written here (not :mod:`mitld_lp.running.simulate`), in lockstep with the
in-memory controller, whose actions the subprocess must reproduce; the import list of a
fresh interpreter is read from ``sys.modules``; the clock rule is compared with the
STA's own on random inputs."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from mitld_lp import Observation, synthesize
from mitld_lp.automata.sta import advance_clock
from mitld_lp.model import load_model
from mitld_lp.runtime import advance
from mitld_lp.synthesis import synthesize_constrained

ROOT = Path(__file__).resolve().parent.parent
MODELS = ROOT / "models"
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}
NOT_HERE = ("scipy", "cvxpy", "clarabel", "lark", "stormpy", "highspy", "numba")


@given(st.dictionaries(st.sampled_from("abcd"), st.integers(0, 6), min_size=1),
       st.dictionaries(st.sampled_from("abcd"), st.integers(1, 8)),
       st.integers(0, 8), st.data())
def test_the_clock_rule_is_the_stas(caps, cuts, clock, data) -> None:
    pending = data.draw(st.frozensets(st.sampled_from(sorted(caps))))
    cuts = {a: t for a, t in cuts.items() if a in caps}
    step = advance_clock(pending, clock, caps, cuts)
    assert advance(pending, clock, caps, cuts) == (step.clock, step.truncated)


PROBE = r"""
import json, sys
from mitld_lp.runtime import load
c = load(sys.argv[1])
a = c.act((0, 0))
print(json.dumps({"action": a, "modules": sorted(sys.modules)}))
"""


def test_runtime_imports_numpy_alone(tmp_path: Path) -> None:
    path = synthesize(load_model(MODELS / "bus_grid.toml")).controller.save(tmp_path / "c.npz")
    done = subprocess.run([sys.executable, "-c", PROBE, str(path)], env=ENV, cwd=tmp_path,
                          capture_output=True, text=True, timeout=120, check=True)
    reply = json.loads(done.stdout)
    assert reply["action"] in {"N", "E", "S", "W"}
    roots = {m.split(".")[0] for m in reply["modules"]}
    assert not roots & set(NOT_HERE), sorted(roots & set(NOT_HERE))
    ours = sorted(m for m in reply["modules"] if m.startswith("mitld_lp"))
    # files.rules: the bounded reader of files a user names (the standard library only);
    # files and controllers: their packages, a docstring each
    assert ours == ["mitld_lp", "mitld_lp.controllers", "mitld_lp.controllers.format",
                    "mitld_lp.controllers.reader", "mitld_lp.controllers.stepper",
                    "mitld_lp.controllers.tables", "mitld_lp.files", "mitld_lp.files.rules",
                    "mitld_lp.runtime", "mitld_lp.startup"]


# --------------------------------------------------------------------------- a world here

MOVES = {"N": (0, 1), "S": (0, -1), "E": (1, 0), "W": (-1, 0)}
SIDES = {"N": "EW", "S": "EW", "E": "NS", "W": "NS"}


def grid_step(rng, cell, action, size=4, slip=0.1):
    """The bus grid's move, written here: the intended direction with 1 - 2 slip, each
    perpendicular one with slip; a move off the grid stays put."""
    u = rng.random()
    d = action if u < 1 - 2 * slip else SIDES[action][0] if u < 1 - slip else SIDES[action][1]
    x, y = cell[0] + MOVES[d][0], cell[1] + MOVES[d][1]
    return (x, y) if 0 <= x < size and 0 <= y < size else cell


def bus_runs(controller, runs, seed, steps=30):
    """Observations of the bus grid in lockstep with ``controller``: bus i arrives at a
    geometric step (p 0.8 and 0.3), drawn here by inverse CDF."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(runs):
        arrive = {b: int(np.ceil(np.log1p(-rng.random()) / np.log1p(-p)))
                  for b, p in (("b1", 0.8), ("b2", 0.3))}
        controller.reset()
        cell, events, lines, actions = (0, 0), set(), [], []
        for t in range(steps):
            line = {"state": list(cell), "events": sorted(events)}
            if t == 0:
                line["reset"] = True
            action = controller.act(Observation(cell, frozenset(events)))
            lines.append(line)
            actions.append(action)
            if action is None:
                break
            cell = grid_step(rng, cell, action)
            events = {b for b, k in arrive.items() if k == t + 1}
        out.append((lines, actions))
    return out


def run_cli(path: Path, lines: list[dict], *extra: str) -> subprocess.CompletedProcess:
    text = "".join(json.dumps(x) + "\n" for x in lines)
    return subprocess.run([sys.executable, "-m", "mitld_lp", "run", str(path), *extra],
                          input=text, env=ENV, capture_output=True, text=True, timeout=120,
                          check=False)


def test_mitld_lp_run_reproduces_the_controller(tmp_path: Path) -> None:
    r = synthesize(load_model(MODELS / "bus_grid.toml"))
    path = r.controller.save(tmp_path / "bus.npz")
    runs = bus_runs(r.controller, runs=60, seed=4)
    assert sum(a[-1] is None for _, a in runs) > 30  # most runs reach a verdict
    lines = [x for obs, _ in runs for x in obs]
    done = run_cli(path, lines)
    assert done.returncode == 0, done.stderr
    replies = [json.loads(x) for x in done.stdout.splitlines()]
    assert [x["action"] for x in replies] == [a for _, acts in runs for a in acts]
    assert {x["status"] for x in replies} >= {"running", "accepted"}


def test_mitld_lp_run_draws_a_randomised_controllers_actions(tmp_path: Path) -> None:
    m = load_model(MODELS / "bus_risk.toml")
    r = synthesize_constrained(m, ["P(F puddle) <= 0.05"])
    path = r.controller.save(tmp_path / "risk.npz")
    r.controller.reset(seed=17)
    runs = bus_runs(r.controller, runs=40, seed=6)
    lines = [x for obs, _ in runs for x in obs]
    done = run_cli(path, lines, "--seed", "17")
    assert done.returncode == 0, done.stderr
    replies = [json.loads(x)["action"] for x in done.stdout.splitlines()]
    assert replies == [a for _, acts in runs for a in acts]


def test_prism_states_by_their_variables(tmp_path: Path) -> None:
    pytest.importorskip("stormpy")
    m = load_model(MODELS / "corridor.toml")
    r = synthesize(m)
    path = r.controller.save(tmp_path / "corridor.npz")
    assert m.game.variables == ("open", "x")
    c = r.controller
    c.reset()
    want = [c.act(Observation((False, 0))), c.act(Observation((False, 1)))]
    done = run_cli(path, [{"state": {"x": 0, "open": False}},
                          {"state": [False, 1], "events": []}])
    assert done.returncode == 0, done.stderr
    assert [json.loads(x)["action"] for x in done.stdout.splitlines()] == want


def test_bad_lines_and_bad_files_are_one_line_each(tmp_path: Path) -> None:
    path = synthesize(load_model(MODELS / "bus_grid.toml")).controller.save(tmp_path / "c.npz")
    done = run_cli(path, [{"state": [0, 0]}, {"state": [9, 9]}, {"nope": 1},
                          {"state": [0, 1], "events": "b1"}, {"state": [0, 1]}])
    assert done.returncode == 2
    replies = [json.loads(x) for x in done.stdout.splitlines()]
    assert len(replies) == 5 and replies[0]["action"] and replies[4]["action"]
    assert replies[1]["error"].startswith("line 2: world state (9, 9): not a state")
    assert replies[2]["error"].startswith("line 3: unknown key 'nope'")
    assert replies[3]["error"].startswith("line 4: events:")
    assert "3 observation lines" in done.stderr and done.stderr.count("\n") == 1
    (tmp_path / "junk.npz").write_text("junk")
    bad = run_cli(tmp_path / "junk.npz", [])
    assert bad.returncode == 2 and bad.stderr.startswith("mitld-lp: error: ")
    assert "cannot load the controller" in bad.stderr and bad.stderr.count("\n") == 1


RUN_PATH = r"""
import io, json, sys
sys.stdin = io.StringIO('{"state": [0, 0]}\n')
from mitld_lp.cli import main
code = main(["run", sys.argv[1]])
heavy = ("cvxpy", "clarabel", "highspy", "stormpy", "scipy.sparse.linalg", "scipy.linalg",
         "mitld_lp.solvers")
print(json.dumps({"code": code, "heavy": sorted(m for m in sys.modules
      if any(m == h or m.startswith(h + ".") for h in heavy))}), file=sys.stderr)
"""


def test_the_run_verb_loads_no_solver_stack(tmp_path: Path) -> None:
    path = synthesize(load_model(MODELS / "bus_grid.toml")).controller.save(tmp_path / "c.npz")
    done = subprocess.run([sys.executable, "-c", RUN_PATH, str(path)], env=ENV, cwd=tmp_path,
                          capture_output=True, text=True, timeout=120, check=True)
    reply = json.loads(done.stderr.strip().splitlines()[-1])
    assert reply == {"code": 0, "heavy": []}
    assert json.loads(done.stdout)["action"] in {"N", "E", "S", "W"}


def test_a_policy_table_state_is_what_run_reads(tmp_path: Path) -> None:
    """The policy table names a PRISM world's state by its variables; that record,
    written as JSON, is an observation ``mitld-lp run`` reads."""
    pytest.importorskip("stormpy")
    r = synthesize(load_model(MODELS / "corridor.toml"))
    rows = r.policy_table()
    first = next(row for row in rows if row["clock"] == 0
                 and row["game_state"] == {"open": False, "x": 0})
    path = r.controller.save(tmp_path / "c.npz")
    done = run_cli(path, [{"state": first["game_state"], "events": []}])
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["action"] == first["action"]


# --------------------------------------------------------------------------- issue 41


@pytest.fixture(scope="module")
def bus_file(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("bus")
    return synthesize(load_model(MODELS / "bus_grid.toml")).controller.save(folder / "c.npz")


def test_a_line_beyond_the_budget_is_an_error_and_the_loop_goes_on(bus_file: Path) -> None:
    import io

    from mitld_lp.runtime import load, serve

    first = '{"state": [0, 0]}'
    exact = first[:-1] + " " * (200 - len(first)) + "}"  # 200 characters: within
    lines = [first, '{"state": "' + "x" * 500 + '"}', exact, first + " " * 190]
    out = io.StringIO()
    bad = serve(load(bus_file), io.StringIO("\n".join(lines) + "\n"), out, budget=200)
    replies = [json.loads(x) for x in out.getvalue().splitlines()]
    assert bad == 2 and len(replies) == 4
    assert replies[1]["error"] == ("line 2: longer than 200 characters, the most an "
                                   "observation line may have; the line was skipped")
    assert replies[3]["error"].startswith("line 4: longer than 200 characters")
    # the loop went on: line 3 is a new observation at step 1 (no reset), as a
    # controller that never saw line 2 answers it
    c = load(bus_file)
    assert replies[0]["action"] == c.act((0, 0)) and replies[2]["action"] == c.act((0, 0))
    # a list of lines is held to the same budget
    out = io.StringIO()
    assert serve(load(bus_file), lines, out, budget=200) == 2


MEASURED = r"""
import sys
from mitld_lp.cli import main
try:
    code = main(["run", sys.argv[1]])
finally:  # this process's peak resident memory (ru_maxrss keeps the forking parent's)
    with open("/proc/self/status") as f:
        peak = next(line.split()[1] for line in f if line.startswith("VmHWM:"))
    print(int(peak) // 1024, file=sys.stderr)
sys.exit(code)
"""


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="reads /proc (Linux)")
def test_a_huge_line_is_never_held_in_memory(bus_file: Path) -> None:
    size = 128 << 20  # characters: read whole, it would take at least 128 MiB
    text = b'{"state": [0, 0]}\n{"state": "' + b"x" * size + b'"}\n{"state": [0, 0]}\n'
    done = subprocess.run([sys.executable, "-c", MEASURED, str(bus_file)], input=text,
                          env=ENV, capture_output=True, timeout=120, check=False)
    assert done.returncode == 2, done.stderr  # one bad line, said on stderr
    replies = [json.loads(x) for x in done.stdout.splitlines()]
    assert [("error" in x) for x in replies] == [False, True, False]
    peak_mib = int(done.stderr.decode().strip().splitlines()[-1])
    assert peak_mib < 100, peak_mib  # was 2.4 GB for a 200 MB line


def test_python_m_runtime_serves_or_refuses(bus_file: Path) -> None:
    line = '{"state": [0, 0]}\n'
    done = subprocess.run([sys.executable, "-m", "mitld_lp.runtime", str(bus_file)],
                          input=line, env=ENV, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr  # was: exit 0 with no answer
    assert json.loads(done.stdout)["action"] in {"N", "E", "S", "W"}
    bare = subprocess.run([sys.executable, "-m", "mitld_lp.runtime"], input=line, env=ENV,
                          capture_output=True, text=True, timeout=120)
    assert bare.returncode == 2 and bare.stdout == ""
    assert bare.stderr == ("mitld-lp: error: the following arguments are required: "
                           "CONTROLLER (see python -m mitld_lp.runtime --help)\n")


def _numpy_only_python(folder: Path) -> Path:
    """A fresh virtual environment that can import NumPy (this environment's, linked
    in: no network) and this repository, and nothing else of this environment."""
    import venv

    import numpy

    venv.EnvBuilder(with_pip=False, symlinks=True).create(folder / "env")
    python = folder / "env" / "bin" / "python"
    if not python.exists():
        pytest.skip("no POSIX virtual environment layout on this platform")
    site = subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_path"
                           "('purelib'))"], capture_output=True, text=True, check=True)
    only = folder / "numpy_only"
    only.mkdir()
    installed = Path(numpy.__file__).parent.parent
    for name in ("numpy", "numpy.libs"):  # the package and its bundled libraries
        if (installed / name).exists():
            (only / name).symlink_to(installed / name)
    Path(site.stdout.strip(), "mitld.pth").write_text(f"{only}\n{ROOT}\n")
    return python


def test_mitld_lp_run_runs_with_numpy_alone_in_a_fresh_environment(tmp_path: Path) -> None:
    import tomllib

    python = _numpy_only_python(tmp_path)
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTHON")}
    probe = ("import importlib.util as u, numpy; print([m for m in ('lark', 'scipy', "
             "'cvxpy', 'clarabel', 'stormpy', 'tqdm') if u.find_spec(m)])")
    absent = subprocess.run([str(python), "-s", "-c", probe], env=env, capture_output=True,
                            text=True, check=True)
    assert absent.stdout.strip() == "[]"  # NumPy alone (and the standard library)
    # the console script as pip writes it from pyproject.toml's [project.scripts]
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    module, function = scripts["mitld-lp"].split(":")
    shim = (f"import sys; sys.argv[0] = 'mitld-lp'; from {module} import {function}; "
            f"sys.exit({function}())")
    r = synthesize(load_model(MODELS / "bus_grid.toml"))
    path = r.controller.save(tmp_path / "bus.npz")
    runs = bus_runs(r.controller, runs=5, seed=3)
    text = "".join(json.dumps(x) + "\n" for obs, _ in runs for x in obs)
    for command in ([str(python), "-s", "-c", shim, "run", str(path)],
                    [str(python), "-s", "-m", "mitld_lp.runtime", str(path)]):
        done = subprocess.run(command, input=text, env=env, cwd=tmp_path,
                              capture_output=True, text=True, timeout=120)
        assert done.returncode == 0, done.stderr  # was: No module named 'lark'
        assert [json.loads(x)["action"] for x in done.stdout.splitlines()] == [
            a for _, acts in runs for a in acts]
