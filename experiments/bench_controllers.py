"""Controllers outside the toolchain: how fast the runtime starts, how small the tree is.

1. Start-up: a fresh interpreter loads a saved controller of ``models/bus_grid.toml`` and
   answers the first observation, through :mod:`mitld_lp.runtime` (NumPy alone) and
   through :meth:`mitld_lp.Controller.load` (the full package); beside them the bare
   interpreter, NumPy's import, the command line's module and the solver stack.  Wall
   seconds, best of N runs; each line prints the action answered.
2. The tree: per model, the policy table's rows, the tree's nodes (value-keeping choices
   and ``same_actions``) and the value of the tree's controller by Storm on its chain
   (the peer, in the same run) beside the synthesis's ``lower``.
Written: ``bench_controllers.csv`` (start-up) and ``bench_trees.csv``.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import _common

from mitld_lp import load_model, synthesize
from mitld_lp.running.chain import write_chain
from mitld_lp.running.tree import tree_controller, tree_of

PROBES = {
    "interpreter": "print(None)",
    "numpy": "import numpy; print(None)",
    "runtime": "from mitld_lp.runtime import load; print(load(PATH).act((0, 0)))",
    "Controller.load": ("from mitld_lp import Controller, Observation; "
                        "print(Controller.load(PATH).act(Observation((0, 0))))"),
    "command line module": "import mitld_lp.cli; print(None)",
    "solver stack": ("import mitld_lp.synthesis, mitld_lp.solvers.lp, clarabel, cvxpy; "
                     "print(None)"),
}


def _start(code: str, path: Path, runs: int) -> tuple[float, str]:
    env = {**os.environ, "PYTHONPATH": str(_common.ROOT)}
    best, answer = float("inf"), ""
    for _ in range(runs):
        t = time.perf_counter()
        done = subprocess.run([sys.executable, "-c", code.replace("PATH", repr(str(path)))],
                              env=env, capture_output=True, text=True, check=True)
        best = min(best, time.perf_counter() - t)
        answer = done.stdout.strip()
    return best, answer


def _storm(path: Path) -> float:
    import stormpy
    import stormpy.environments as env_mod

    model = stormpy.build_model_from_drn(str(path))
    env = stormpy.Environment()
    solver = env.solver()
    solver.set_linear_equation_solver_type(env_mod.EquationSolverType.NATIVE)
    solver.native().method = env_mod.NativeLinearEquationSolverMethod.SOUND_VALUE_ITERATION
    solver.native().precision = stormpy.Rational("1/1000000000000")
    solver.native().relative_termination_criterion = False
    prop = stormpy.parse_properties('P=? [F "accept"]')[0]
    return float(stormpy.model_checking(model, prop, environment=env).get_value(
        model.initial_states[0]))


def main(argv: list[str] | None = None):
    args = _common.parser(__doc__.splitlines()[0]).parse_args(argv)
    out = _common.out_dir(args)
    runs = 3 if args.quick else 15
    with tempfile.TemporaryDirectory() as scratch:
        path = synthesize(load_model(_common.model_path("bus_grid.toml"))).controller.save(
            Path(scratch) / "bus.npz")
        starts = []
        for name, code in PROBES.items():
            seconds, answer = _start(code, path, runs)
            starts.append([name, round(seconds, 3), answer])
    full = dict((n, s) for n, s, _ in starts)
    for row in starts:
        row.append(round(row[1] / full["Controller.load"], 2))
    print(f"start-up, wall seconds, best of {runs}:")
    print(_common.text_table(["what", "seconds", "answer", "vs Controller.load"], starts))
    _common.write_csv(out / "bench_controllers.csv",
                      ["what", "seconds", "answer", "over_controller_load"], starts)

    trees = []
    names = ["corridor.toml", "bus_grid.toml"] if args.quick else [
        "corridor.toml", "red_light.toml", "bus_grid.toml", "bus_puddle.toml", "patrol.toml"]
    with tempfile.TemporaryDirectory() as scratch:
        for name in names:
            r = synthesize(load_model(_common.model_path(name)))
            t0 = time.process_time()
            tree = tree_of(r)
            cpu = time.process_time() - t0
            same = tree_of(r, same_actions=True)
            chain = write_chain(r, Path(scratch) / "t.drn", overwrite=True,
                                controller=tree_controller(r, tree))
            storm = _storm(chain)
            rows = len(r.policy_table())
            trivial = r.lower <= 1e-3 or r.lower >= 1 - 1e-3
            trees.append([name, rows, tree.size, same.size, round(rows / tree.size, 1),
                          round(cpu, 2), r.lower, storm, abs(storm - r.lower),
                          "trivial" if trivial else ""])
    print("\ntrees (nodes) against the policy table (rows); Storm on the tree's chain:")
    header = ["model", "table rows", "tree", "same actions", "rows/tree", "grow cpu s",
              "lower", "Storm", "|diff|", "note"]
    print(_common.text_table(header, trees))
    _common.write_csv(out / "bench_trees.csv",
                      ["model", "table_rows", "tree_nodes", "same_actions_nodes",
                       "rows_over_nodes", "grow_cpu_s", "lower", "storm", "abs_diff", "note"],
                      trees)
    return starts, trees


if __name__ == "__main__":
    main()
