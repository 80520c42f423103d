"""Benchmark: the solve stage in units of one sweep, beside Storm's best sound check.

The machine is shared and noisy, so every figure is a ratio measured in one run, in CPU
seconds (wall seconds beside them).  The unit is one *sweep* of the product: a sparse
matrix-vector product and a maximum over each state's choices, timed in the same
process (the median of seven).  Per instance (the families of ``bench_scaling.py``:
``bus`` -- the case study's grid grown to ``n x n`` with deadline ``d`` -- and ``events``,
whose three clocks are not memoryless, so both truncation models are solved):

* ``ours``: a fresh child process runs ``synthesize`` with its defaults on the model
  (the whole default route: automaton, product, analysis, interval iteration, pruned
  block LPs through Clarabel, exact evaluation, certificate); the *solve stage* is
  everything after the product is built (``SynthesisResult.solve_cpu``).  Its peak
  memory over the resident size before the run, per transition, is
  ``bytes_per_transition``; it then writes the DRN;
* ``storm_check``: another child reads that DRN with stormpy and checks
  ``Pmax=? [F "target"]`` with each of Storm's sound methods (sound value iteration,
  interval iteration, optimistic value iteration, topological; ``force_soundness``,
  precision 1e-9 absolute); the fastest is Storm's best, and every method's value must
  agree with ours (lower model) within 1e-6;
* ``storm_prism`` (bus family): Storm's whole run from the PRISM encoding
  (``experiments/prism/bus.prism``, its constants filled in): parse, build, and the
  best sound check;
* the paper's case as whole processes: ``mitld-lp solve models/bus_grid.toml`` against
  a stormpy script on the PRISM encoding of the same task (CPU of each child process,
  imports included, from ``os.wait4``).

Written: ``bench_sweeps.csv`` and ``bench_sweeps.md`` (the printed table).  The full run::

    python experiments/bench_sweeps.py --out experiments/results

``--quick`` runs tiny instances into ``experiments/out/quick`` (or ``--out``).
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

from bench_scaling import Instance  # noqa: E402  (the same instances)

ROOT = HERE.parent
FULL = [("bus", n, d) for d in (3, 10) for n in (32, 64, 128)] + [
    ("events", n, 4) for n in (16, 32, 64)]
QUICK = [("bus", 8, 3), ("events", 8, 4)]
METHODS = ("SOUND_VALUE_ITERATION", "INTERVAL_ITERATION", "OPTIMISTIC_VALUE_ITERATION",
           "TOPOLOGICAL")
PRECISION = "1/1000000000"


def _cpu() -> float:
    return time.process_time()


def _peak_kb() -> int:
    return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)


def _rss_kb() -> int:
    with open("/proc/self/statm", encoding="ascii") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") // 1024


def work_ours(inst: Instance, work: Path) -> dict[str, Any]:
    import clarabel  # noqa: F401  (imports before the clock, as Storm's are)
    import numpy as np
    import scipy.sparse.csgraph  # noqa: F401

    from mitld_lp import Model, synthesize
    from mitld_lp.solvers import write_drn

    model = Model.from_game(inst.world(), inst.spec(), epsilon=inst.epsilon)
    before = _rss_kb()
    c, w = _cpu(), time.perf_counter()
    r = synthesize(model)
    whole_cpu, whole_wall = _cpu() - c, time.perf_counter() - w
    peak = _peak_kb()
    mdp = r.mdp
    v = np.random.default_rng(0).random(mdp.n_states)
    starts = np.asarray(mdp.row_groups[:-1])
    times = []
    for _ in range(7):
        c = _cpu()
        np.maximum.reduceat(mdp.matrix @ v, starts)
        times.append(_cpu() - c)
    write_drn(mdp, mdp.target, work / "model.drn", overwrite=True)
    return dict(states=mdp.n_states, transitions=mdp.n_transitions, value=r.lower,
                upper=r.upper, certified=r.certified, whole_cpu=whole_cpu,
                whole_wall=whole_wall, solve_wall=r.timings["solve"],
                solve_cpu=r.solve_cpu,
                sweep_cpu=float(np.median(times)),
                bytes_per_transition=(peak - before) * 1024 / max(mdp.n_transitions, 1))


def _checks(model: Any, prop: Any) -> dict[str, Any]:
    import stormpy
    import stormpy.environments as envs

    out: dict[str, Any] = {}
    for name in METHODS:
        env = stormpy.Environment()
        env.solver().force_soundness = True
        minmax = env.solver().min_max()
        minmax.method = getattr(envs.MinMaxMethod, name)
        minmax.precision = stormpy.Rational(PRECISION)
        minmax.relative_termination_criterion = False
        c = _cpu()
        result = stormpy.model_checking(model, prop, environment=env)
        out[name] = dict(cpu=_cpu() - c, value=float(result.get_value(model.initial_states[0])))
    best = min(out, key=lambda k: out[k]["cpu"])
    return dict(methods=out, best=best, best_cpu=out[best]["cpu"])


def work_storm_check(inst: Instance, work: Path) -> dict[str, Any]:
    import stormpy

    prop = stormpy.parse_properties('Pmax=? [F "target"]')[0]
    c = _cpu()
    model = stormpy.build_model_from_drn(str(work / "model.drn"))
    return dict(parse_cpu=_cpu() - c, **_checks(model, prop))


def work_storm_prism(inst: Instance, work: Path) -> dict[str, Any]:
    import stormpy

    path = work / "bus.prism"
    path.write_text(inst.prism(), encoding="utf-8")
    c = _cpu()
    program = stormpy.parse_prism_program(str(path))
    prop = stormpy.parse_properties('Pmax=? [F "target"]', program)[0]
    model = stormpy.build_model(program, [prop])
    build_cpu = _cpu() - c
    checks = _checks(model, prop)
    return dict(build_cpu=build_cpu, whole_cpu=build_cpu + checks["best_cpu"],
                states=model.nr_states, **checks)


WORKERS = {"ours": work_ours, "storm_check": work_storm_check,
           "storm_prism": work_storm_prism}


def _child(route: str, inst: Instance, work: Path) -> dict[str, Any]:
    out = work / f"{route}.json"
    done = subprocess.run([sys.executable, __file__, "--worker", route, inst.family,
                           str(inst.n), str(inst.d), str(work)], capture_output=True,
                          text=True, cwd=ROOT)
    if done.returncode != 0:
        raise RuntimeError(f"{route} on {inst.name} failed:\n{done.stderr[-2000:]}")
    return json.loads(out.read_text(encoding="utf-8"))


STORM_SCRIPT = """
import sys, stormpy
program = stormpy.parse_prism_program(sys.argv[1])
prop = stormpy.parse_properties('Pmax=? [F "target"]', program)[0]
model = stormpy.build_model(program, [prop])
env = stormpy.Environment()
env.solver().force_soundness = True
print(stormpy.model_checking(model, prop, environment=env).get_value(model.initial_states[0]))
"""


def whole_processes(work: Path, repeats: int) -> dict[str, float]:
    """``mitld-lp solve models/bus_grid.toml`` and the stormpy script, as processes
    (the least CPU of ``repeats`` runs each: the first run also compiles bytecode)."""
    case = Instance("bus", 4, 3)
    prism = work / "case.prism"
    prism.write_text(case.prism(), encoding="utf-8")
    ours, storm = [], []
    for _ in range(repeats):
        ours.append(_cpu_of([sys.executable, "-m", "mitld_lp", "solve",
                             str(ROOT / "models" / "bus_grid.toml"), "-q"]))
        storm.append(_cpu_of([sys.executable, "-c", STORM_SCRIPT, str(prism)]))
    return dict(ours=min(ours), storm=min(storm))


def _cpu_of(argv: list[str]) -> float:
    # bytecode is cached as on an installed package: with PYTHONDONTWRITEBYTECODE set
    # (some CI images set it), an editable checkout would recompile every module on every
    # run, while the installed stormpy's bytecode was written at installation
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    proc = subprocess.Popen(argv, cwd=ROOT, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, env=env)
    _, status, usage = os.wait4(proc.pid, 0)
    err = proc.stderr.read().decode() if proc.stderr else ""
    if os.waitstatus_to_exitcode(status) != 0:
        raise RuntimeError(f"{argv}: {err[-2000:]}")
    return usage.ru_utime + usage.ru_stime


def run(instances: list[tuple[str, int, int]], out: Path, repeats: int) -> list[dict]:
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench_sweeps_") as tmp:
        for family, n, d in instances:
            inst = Instance(family, n, d)
            work = Path(tmp) / inst.name
            work.mkdir()
            ours = _child("ours", inst, work)
            storm = _child("storm_check", inst, work)
            prism = _child("storm_prism", inst, work) if family == "bus" else None
            sweep = ours["sweep_cpu"]
            values = [m["value"] for m in storm["methods"].values()]
            row = dict(
                instance=inst.name, states=ours["states"], transitions=ours["transitions"],
                sweep_ms=1e3 * sweep, value=ours["value"], upper=ours["upper"],
                certified=ours["certified"],
                storm_agrees=all(abs(v - ours["value"]) <= 1e-6 for v in values),
                solve_cpu=ours["solve_cpu"], solve_wall=ours["solve_wall"],
                solve_sweeps=ours["solve_cpu"] / sweep, whole_cpu=ours["whole_cpu"],
                whole_wall=ours["whole_wall"], whole_sweeps=ours["whole_cpu"] / sweep,
                storm_best=storm["best"].lower(), storm_check_cpu=storm["best_cpu"],
                storm_check_sweeps=storm["best_cpu"] / sweep,
                solve_over_storm_check=ours["solve_cpu"] / storm["best_cpu"],
                storm_prism_cpu=prism["whole_cpu"] if prism else None,
                whole_over_storm_prism=(ours["whole_cpu"] / prism["whole_cpu"]
                                        if prism else None),
                bytes_per_transition=ours["bytes_per_transition"],
                **{f"storm_{k.lower()}_cpu": v["cpu"] for k, v in storm["methods"].items()},
            )
            rows.append(row)
            print(_line(row), flush=True)
        case = whole_processes(Path(tmp), repeats)
    rows.append(dict(instance="bus_grid.toml as a process", whole_cpu=case["ours"],
                     storm_prism_cpu=case["storm"],
                     whole_over_storm_prism=case["ours"] / case["storm"]))
    print(_line(rows[-1]))
    return rows


COLUMNS = ("instance", "states", "transitions", "sweep_ms", "solve_cpu", "solve_sweeps",
           "storm_check_cpu", "storm_check_sweeps", "storm_best", "solve_over_storm_check",
           "whole_cpu", "storm_prism_cpu", "whole_over_storm_prism", "bytes_per_transition",
           "storm_agrees", "certified")


def _fmt(x: Any) -> str:
    if x is None:
        return ""
    if isinstance(x, float):
        return f"{x:.3g}"
    return str(x)


def _line(row: dict) -> str:
    return "  ".join(f"{k}={_fmt(row.get(k))}" for k in COLUMNS if row.get(k) is not None)


def main(argv: list[str] | None = None) -> list[dict]:
    import _common

    ap = _common.parser(__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=None,
                    help="runs of each whole process for the case study (default 5, 2 "
                         "with --quick)")
    args = ap.parse_args(argv)
    out = _common.out_dir(args)
    rows = run(QUICK if args.quick else FULL, out, args.repeats or (2 if args.quick else 5))
    header = sorted({k for r in rows for k in r}, key=lambda k: (
        COLUMNS.index(k) if k in COLUMNS else len(COLUMNS), k))
    _common.write_csv(out / "bench_sweeps.csv", header,
                      [[_fmt(r.get(k)) for k in header] for r in rows])
    table = _common.markdown_table(COLUMNS, [[_fmt(r.get(k)) for k in COLUMNS]
                                             for r in rows])
    _common.write_text(out / "bench_sweeps.md", table)
    print(table)
    print(f"written: {_common.shown(out / 'bench_sweeps.csv')}, "
          f"{_common.shown(out / 'bench_sweeps.md')}")
    return rows


def worker(argv: list[str]) -> None:
    route, family, n, d, work = argv
    result = WORKERS[route](Instance(family, int(n), int(d)), Path(work))
    (Path(work) / f"{route}.json").write_text(json.dumps(result), encoding="utf-8")


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--worker":
        worker(sys.argv[2:])
    else:
        main()
