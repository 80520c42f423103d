"""Benchmark: our solve stage and whole run beside Storm's on the same model, one run.

The machine is shared and noisy, so every figure is a ratio measured in one run, in CPU
seconds.  The unit *sweep* of the product (a sparse matrix-vector product and a maximum
over each state's choices, the median of seven, timed in a process of its own) puts both
solvers' costs on one scale.  The families (``bench_scaling.Instance``):

* ``bus_scaled`` -- the case study's task on an ``n x n`` grid with both hazards scaled
  by ``4/n`` and ``B`` at ``(n - 1, 0)``: its optimum stays between 0.1 and 0.9 from
  ``n = 16`` to ``128`` (the plain ``bus`` family's falls to 1e-9 and below, where a
  solver has almost nothing to do: that family flattered every solver and is not used);
* ``events`` -- three non-memoryless clocks, both truncation models solved.

Every instance prints its optimum.  An instance whose optimum is below 1e-3 or above
1 - 1e-3 is *degenerate*: reported apart and never in a ratio.  Per instance, each in a
child process of its own:

* ``ours``: imports, the model, ``synthesize`` with its defaults (the whole default
  route: automaton, product, analysis, interval iteration, pruned block LPs through
  Clarabel, exact evaluation, certificate).  ``solve_cpu`` is everything after the
  product is built (``SynthesisResult.solve_cpu``; the solver modules are imported
  before, as stormpy is before Storm's check: :func:`preload`), ``whole_cpu`` the
  synthesize call, ``process_cpu`` the whole child (imports included, ``os.wait4``);
  ``bytes_per_transition`` its peak resident size over the size before ``synthesize``,
  per transition;
* ``export``: the same product written as DRN, and the sweep timed (untimed otherwise);
* ``storm_check``: stormpy reads that DRN and checks ``Pmax=? [F "target"]`` with each
  of Storm's sound methods (sound value iteration, interval iteration, optimistic value
  iteration, topological; ``force_soundness``, precision 1e-9 absolute); the fastest is
  Storm's best check, and every method's value must agree with ours (lower model) within
  1e-6.  Its states and transitions are Storm's count of the same file, its
  ``storm_bytes_per_transition`` the peak over the size before the DRN was read;
* ``storm_prism`` (bus families): Storm's whole run from the PRISM encoding
  (``experiments/prism/bus.prism``, its constants filled in) as a process: import
  stormpy, parse, build, check with the best method found on the DRN
  (``storm_process_cpu``, ``os.wait4``; ``storm_prism_cpu`` the parse, build and check
  alone);
* the paper's case as whole processes: ``mitld-lp solve models/bus_grid.toml`` against
  a stormpy script on the PRISM encoding of the same task (least CPU of ``--repeats``).

The targets checked on every non-degenerate instance of at least 1e5 states: solve <=
2x Storm's best check, whole process <= 1x Storm's whole process, <= 50 bytes per
transition on a product of at least 1e6 transitions (:data:`MEMORY_FROM`, the issue's
words; smaller rows print theirs with no target); the case as a process <= 2x the
stormpy script.  Each miss is listed with its factor.

``--compare DIR`` runs ``ours`` a second time on each instance, in the same run, with
the ``mitld_lp`` of another checkout ``DIR`` (an older commit, ``git archive``), and
adds its figures as ``base_*`` columns and a before/after table: both answers, whether
the bracket is the same, both solve stages and their ratios to Storm's best check.

Written: ``bench_sweeps.csv``, ``bench_sweeps.md`` (the tables and the misses) and
``bench_sweeps_machine.txt``.  The full run::

    python experiments/bench_sweeps.py --out experiments/results
    python experiments/bench_sweeps.py --only bus_scaled_n64_d3 --compare ../before \
        --out /tmp/sweeps  # before and after, one run

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
FULL = [("bus_scaled", n, d) for d in (3, 10) for n in (16, 32, 64, 128)] + [
    ("events", n, 4) for n in (16, 32, 64)]
QUICK = [("bus_scaled", 8, 3), ("events", 8, 4)]
DEGENERATE = 1e-3  # an optimum below this or above 1 - this is reported apart
BIG = 100_000  # states: the targets are checked from this size up
TARGETS = {"solve_over_storm_check": 2.0, "process_over_storm_process": 1.0,
           "bytes_per_transition": 50.0}
CASE_TARGET = 2.0
MEMORY_FROM = 1_000_000  # issue 45: "<= 50 bytes per transition at 1e6 transitions and more"
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


def _model(inst: Instance) -> Any:
    from mitld_lp import Model

    return Model.from_game(inst.world(), inst.spec(), epsilon=inst.epsilon)


def preload() -> None:
    """Import the modules the solve stage imports on first use (the analysis, the
    solvers, the certificate, the acceptance), so that ``solve_cpu`` is the solve and not a one-time
    library load (0.1-0.3 s): Storm's check is timed after stormpy is loaded too.  The
    process figures include it; numba, loaded only for a large product, stays inside.
    SciPy's csgraph is loaded by the solve of a product past the small-graph walks
    (``mitld_lp.util.traversal``), as every instance here is, and as the package loads
    it: without ``scipy.sparse.linalg``'s ``__init__`` and ``scipy.linalg``, which the
    route imports where it uses them (the direct solvers, 3 ms, at a chain's first
    factorisation; ``scipy.linalg`` whole only where something reads more of it), so
    they are not imported here."""
    import mitld_lp.routes.acceptance
    import mitld_lp.solvers.analysis
    import mitld_lp.solvers.certify
    import mitld_lp.solvers.iteration
    import mitld_lp.solvers.lp  # noqa: F401
    from mitld_lp.util import traversal

    if hasattr(traversal, "csgraph"):
        traversal.csgraph()
    else:  # a checkout from before it (``--compare``): its preload, as it was
        import scipy.sparse.csgraph
        import scipy.sparse.linalg  # noqa: F401


def work_ours(inst: Instance, work: Path) -> dict[str, Any]:
    from mitld_lp import synthesize

    model = _model(inst)
    preload()
    before = _rss_kb()
    c = _cpu()
    r = synthesize(model)
    whole_cpu = _cpu() - c
    peak = _peak_kb()
    mdp = r.mdp
    return dict(states=mdp.n_states, transitions=mdp.n_transitions, value=r.lower,
                upper=r.upper, certified=r.certified, whole_cpu=whole_cpu,
                solve_cpu=r.solve_cpu, status=r.status.value,
                bytes_per_transition=max(peak - before, 0) * 1024 / max(mdp.n_transitions, 1))


def work_export(inst: Instance, work: Path) -> dict[str, Any]:
    import numpy as np

    from mitld_lp.solvers import write_drn
    from mitld_lp.synthesis import build_product

    model = _model(inst)
    mdp = build_product(model.game, model.spec, model.distributions, epsilon=model.epsilon,
                        max_states=50_000_000, progress=False).mdp
    v = np.random.default_rng(0).random(mdp.n_states)
    starts = np.asarray(mdp.row_groups[:-1])
    times = []
    for _ in range(7):
        c = _cpu()
        np.maximum.reduceat(mdp.matrix @ v, starts)
        times.append(_cpu() - c)
    write_drn(mdp, mdp.target, work / "model.drn", overwrite=True)
    return dict(sweep_cpu=float(np.median(times)))


def storm_env(name: str) -> Any:
    """A sound Storm environment whose min-max method is ``name`` (of :data:`METHODS`)
    at :data:`PRECISION`, absolute."""
    import stormpy
    import stormpy.environments as envs

    env = stormpy.Environment()
    env.solver().force_soundness = True
    minmax = env.solver().min_max()
    minmax.method = getattr(envs.MinMaxMethod, name)
    minmax.precision = stormpy.Rational(PRECISION)
    minmax.relative_termination_criterion = False
    return env




def _checks(model: Any, prop: Any, methods: tuple[str, ...]) -> dict[str, Any]:
    import stormpy

    out: dict[str, Any] = {}
    for name in methods:
        env = storm_env(name)
        c = _cpu()
        result = stormpy.model_checking(model, prop, environment=env)
        out[name] = dict(cpu=_cpu() - c, value=float(result.get_value(model.initial_states[0])))
    best = min(out, key=lambda k: out[k]["cpu"])
    return dict(methods=out, best=best, best_cpu=out[best]["cpu"])


def work_storm_check(inst: Instance, work: Path) -> dict[str, Any]:
    import stormpy

    prop = stormpy.parse_properties('Pmax=? [F "target"]')[0]
    before = _rss_kb()
    c = _cpu()
    model = stormpy.build_model_from_drn(str(work / "model.drn"))
    parse_cpu = _cpu() - c
    checks = _checks(model, prop, METHODS)
    peak = _peak_kb()
    return dict(parse_cpu=parse_cpu, states=model.nr_states,
                transitions=model.nr_transitions,
                bytes_per_transition=max(peak - before, 0) * 1024 / max(model.nr_transitions, 1),
                **checks)


def work_storm_prism(inst: Instance, work: Path) -> dict[str, Any]:
    import stormpy

    method = (work / "storm_best.txt").read_text(encoding="utf-8").strip()
    path = work / "bus.prism"
    path.write_text(inst.prism(), encoding="utf-8")
    c = _cpu()
    program = stormpy.parse_prism_program(str(path))
    prop = stormpy.parse_properties('Pmax=? [F "target"]', program)[0]
    model = stormpy.build_model(program, [prop])
    build_cpu = _cpu() - c
    checks = _checks(model, prop, (method,))
    return dict(build_cpu=build_cpu, whole_cpu=build_cpu + checks["best_cpu"],
                states=model.nr_states, value=checks["methods"][method]["value"], **checks)


WORKERS = {"ours": work_ours, "export": work_export, "storm_check": work_storm_check,
           "storm_prism": work_storm_prism}


def _child(route: str, inst: Instance, work: Path, code: Path | None = None,
           ) -> dict[str, Any]:
    """The route in a child process; its result with ``process_cpu``, the child's whole
    CPU (user + system, imports included) from ``os.wait4``.  ``code``: the checkout
    whose ``mitld_lp`` the child imports (default this one)."""
    out = work / f"{route}.json"
    argv = [sys.executable, __file__, "--worker", route, inst.family, str(inst.n),
            str(inst.d), str(work)]
    # this checkout is put on the path too: run from elsewhere, the child would import
    # whatever mitld_lp is installed (an editable install of another checkout)
    cpu, err = _cpu_of(argv, code or ROOT)
    if cpu is None:
        raise RuntimeError(f"{route} on {inst.name} failed:\n{err[-2000:]}")
    return dict(json.loads(out.read_text(encoding="utf-8")), process_cpu=cpu)


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
        for argv, into in (([sys.executable, "-m", "mitld_lp", "solve",
                             str(ROOT / "models" / "bus_grid.toml"), "-q"], ours),
                           ([sys.executable, "-c", STORM_SCRIPT, str(prism)], storm)):
            cpu, err = _cpu_of(argv)
            if cpu is None:
                raise RuntimeError(f"{argv}: {err[-2000:]}")
            into.append(cpu)
    return dict(ours=min(ours), storm=min(storm))


def _cpu_of(argv: list[str], code: Path | None = None) -> tuple[float | None, str]:
    """The CPU seconds of the process ``argv`` (None if it failed) and its stderr;
    ``code``: a checkout put first on its ``PYTHONPATH`` (and its working directory)."""
    # bytecode is cached as on an installed package: with PYTHONDONTWRITEBYTECODE set
    # (some CI images set it), an editable checkout would recompile every module on every
    # run, while the installed stormpy's bytecode was written at installation
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    if code is not None:
        env["PYTHONPATH"] = os.pathsep.join([str(code),
                                             *filter(None, [env.get("PYTHONPATH")])])
    with tempfile.TemporaryFile() as errors:
        proc = subprocess.Popen(argv, cwd=code or ROOT, stdout=subprocess.DEVNULL,
                                stderr=errors, env=env)
        _, status, usage = os.wait4(proc.pid, 0)
        proc.returncode = os.waitstatus_to_exitcode(status)
        errors.seek(0)
        err = errors.read().decode(errors="replace")
    if proc.returncode != 0:
        return None, err
    return usage.ru_utime + usage.ru_stime, err


def degenerate(value: float) -> bool:
    """An optimum too close to 0 or 1 for a ratio to mean anything."""
    return not DEGENERATE <= value <= 1.0 - DEGENERATE


def measure(inst: Instance, work: Path, compare: Path | None = None) -> dict[str, Any]:
    """Every route on ``inst`` and the row of figures; ratios only if not degenerate.
    ``compare``: also ours from that checkout (``base_*`` columns)."""
    base = _child("ours", inst, work, compare) if compare is not None else None
    ours = _child("ours", inst, work)
    export = _child("export", inst, work)
    storm = _child("storm_check", inst, work)
    (work / "storm_best.txt").write_text(storm["best"], encoding="utf-8")
    prism = _child("storm_prism", inst, work) if inst.is_bus else None
    (work / "model.drn").unlink()
    sweep = export["sweep_cpu"]
    values = [m["value"] for m in storm["methods"].values()]
    flat = degenerate(ours["value"])

    def ratio(a: float, b: float | None) -> float | None:
        return None if flat or b is None or b <= 0 else a / b

    return dict(
        instance=inst.name, value=ours["value"], upper=ours["upper"],
        degenerate=flat, states=ours["states"], transitions=ours["transitions"],
        storm_states=storm["states"], storm_transitions=storm["transitions"],
        sweep_ms=1e3 * sweep, certified=ours["certified"],
        storm_agrees=all(abs(v - ours["value"]) <= 1e-6 for v in values),
        storm_prism_value=prism["value"] if prism else None,
        solve_cpu=ours["solve_cpu"], solve_sweeps=ours["solve_cpu"] / sweep,
        whole_cpu=ours["whole_cpu"], process_cpu=ours["process_cpu"],
        storm_best=storm["best"].lower(), storm_check_cpu=storm["best_cpu"],
        storm_check_sweeps=storm["best_cpu"] / sweep,
        solve_over_storm_check=ratio(ours["solve_cpu"], storm["best_cpu"]),
        storm_prism_cpu=prism["whole_cpu"] if prism else None,
        storm_process_cpu=prism["process_cpu"] if prism else None,
        whole_over_storm_prism=ratio(ours["whole_cpu"], prism["whole_cpu"] if prism else None),
        process_over_storm_process=ratio(ours["process_cpu"],
                                         prism["process_cpu"] if prism else None),
        bytes_per_transition=ours["bytes_per_transition"],
        storm_bytes_per_transition=storm["bytes_per_transition"],
        **{f"storm_{k.lower()}_cpu": v["cpu"] for k, v in storm["methods"].items()},
        **({} if base is None else dict(
            base_value=base["value"], base_upper=base["upper"],
            base_certified=base["certified"], base_solve_cpu=base["solve_cpu"],
            base_solve_over_storm_check=ratio(base["solve_cpu"], storm["best_cpu"]),
            same_bracket=(base["value"], base["upper"]) == (ours["value"], ours["upper"]),
            same_product=(base["states"], base["transitions"]) == (ours["states"],
                                                                     ours["transitions"]))),
    )


COMPARED = ("instance", "base_value", "value", "base_upper", "upper", "same_bracket",
            "same_product", "states", "base_solve_cpu", "solve_cpu", "storm_check_cpu",
            "storm_best", "base_solve_over_storm_check", "solve_over_storm_check",
            "base_certified", "certified")


def run(instances: list[tuple[str, int, int]], repeats: int,
        compare: Path | None = None, skip_case: bool = False) -> list[dict]:
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench_sweeps_") as tmp:
        for family, n, d in instances:
            inst = Instance(family, n, d)
            work = Path(tmp) / inst.name
            work.mkdir()
            rows.append(measure(inst, work, compare))
            print(_line(rows[-1]), flush=True)
        if skip_case:
            return rows
        case = whole_processes(Path(tmp), repeats)
    rows.append(dict(instance="bus_grid.toml as a process", value=0.9244053,
                     degenerate=False, process_cpu=case["ours"],
                     storm_process_cpu=case["storm"],
                     process_over_storm_process=case["ours"] / case["storm"]))
    print(_line(rows[-1]))
    return rows


COLUMNS = ("instance", "value", "states", "transitions", "sweep_ms", "solve_cpu",
           "solve_sweeps", "storm_check_cpu", "storm_check_sweeps", "storm_best",
           "solve_over_storm_check", "whole_cpu", "process_cpu", "storm_prism_cpu",
           "storm_process_cpu", "process_over_storm_process", "bytes_per_transition",
           "storm_bytes_per_transition", "storm_agrees", "certified")


def _fmt(x: Any) -> str:
    if x is None:
        return ""
    if isinstance(x, float):
        return f"{x:.4g}"
    return str(x)


def _full(key: str, x: Any) -> str:
    """A bound in full (a bracket's digits), anything else as :func:`_fmt`."""
    return f"{x:.12g}" if key.endswith(("value", "upper")) and isinstance(x, float) \
        else _fmt(x)


def _line(row: dict) -> str:
    return "  ".join(f"{k}={_fmt(row.get(k))}" for k in COLUMNS if row.get(k) is not None)


def misses(rows: list[dict]) -> list[str]:
    """The targets (module docs) each non-degenerate instance of at least :data:`BIG`
    states misses, with the factor by which."""
    out = []
    for r in rows:
        if r.get("degenerate"):
            continue
        if r.get("states") is None:  # the case as processes
            got = r["process_over_storm_process"]
            if got > CASE_TARGET:
                out.append(f"{r['instance']}: {got:.2f}x the stormpy script, target "
                           f"{CASE_TARGET:g}x (missed by {got / CASE_TARGET:.2f}x)")
            continue
        if r["states"] < BIG:
            continue
        out += target_misses(r)
    return out


def target_misses(r: dict) -> list[str]:
    """The row's ratios over :data:`TARGETS`, each with the factor by which it misses;
    the memory target only on a product of at least :data:`MEMORY_FROM` transitions
    (below it the row still prints its bytes per transition, and no target is
    claimed for it)."""
    out = []
    for key, target in TARGETS.items():
        got = r.get(key)
        if key == "bytes_per_transition" and (r.get("transitions") or 0) < MEMORY_FROM:
            continue
        if got is not None and got > target:
            out.append(f"{r['instance']}: {key} = {got:.3g}, target {target:g} "
                       f"(missed by {got / target:.2f}x)")
    return out


def report(rows: list[dict]) -> str:
    """The markdown: non-degenerate instances, degenerate ones apart, the misses."""
    def table(part: list[dict]) -> str:
        return _common.markdown_table(COLUMNS, [[_fmt(r.get(k)) for k in COLUMNS]
                                                for r in part])

    import _common

    good = [r for r in rows if not r.get("degenerate")]
    flat = [r for r in rows if r.get("degenerate")]
    text = table(good)
    if flat:
        text += ("\nDegenerate instances (optimum below 1e-3 or above 1 - 1e-3; no ratio "
                 "is taken from them):\n\n" + table(flat))
    compared = [r for r in rows if "base_value" in r]
    if compared:
        text += ("\nBefore (`base_*`: the package of the `--compare` checkout) and after "
                 "(this checkout), in the same run, CPU seconds; ratios only for the "
                 "non-degenerate instances:\n\n" + _common.markdown_table(
                     COMPARED, [[_full(k, r.get(k)) for k in COMPARED] for r in compared]))
    missed = misses(rows)
    text += (f"\nTargets on the non-degenerate instances of at least {BIG:,} states "
             "(solve <= 2x Storm's best check, whole process <= 1x Storm's, <= 50 bytes "
             f"per transition from {MEMORY_FROM:,} transitions; the case as a process <= 2x "
             "the stormpy script): "
             + ("all met.\n" if not missed else "missed:\n\n"
                + "".join(f"- {m}\n" for m in missed)))
    return text


def main(argv: list[str] | None = None) -> list[dict]:
    import _common
    from bench_scaling import machine_text

    ap = _common.parser(__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=None,
                    help="runs of each whole process for the case study (default 5, 2 "
                         "with --quick)")
    ap.add_argument("--only", nargs="*", default=None, metavar="NAME",
                    help="run only these instances (e.g. bus_scaled_n64_d3)")
    ap.add_argument("--compare", type=Path, default=None, metavar="DIR",
                    help="also run ours with the mitld_lp of this checkout (before/after)")
    ap.add_argument("--skip-case", action="store_true",
                    help="leave out the case study as whole processes")
    args = ap.parse_args(argv)
    if args.compare is not None and not (args.compare / "mitld_lp").is_dir():
        ap.error(f"--compare {args.compare}: no mitld_lp package in that directory")
    out = _common.out_dir(args)
    instances = QUICK if args.quick else FULL
    if args.only:
        instances = [i for i in instances if Instance(*i).name in set(args.only)]
    rows = run(instances, args.repeats or (2 if args.quick else 5),
               args.compare.resolve() if args.compare else None, args.skip_case)
    header = sorted({k for r in rows for k in r}, key=lambda k: (
        COLUMNS.index(k) if k in COLUMNS else len(COLUMNS), k))
    _common.write_csv(out / "bench_sweeps.csv", header,
                      [[_fmt(r.get(k)) for k in header] for r in rows])
    text = report(rows)
    _common.write_text(out / "bench_sweeps.md", text)
    _common.write_text(out / "bench_sweeps_machine.txt", machine_text(
        "shared 2-core machine, other processes running; one run, CPU seconds",
        [f"command: python experiments/bench_sweeps.py {' '.join(argv or sys.argv[1:])}",
         "storm: each sound method (force_soundness, 1e-9 absolute) on our DRN; the best "
         "one again from experiments/prism/bus.prism in a process of its own"]))
    print(text)
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
