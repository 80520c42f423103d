"""Benchmark: the bus family's block LPs through Clarabel, before/after in one run.

The default route answers both blocks of ``bus_scaled`` n64/n128 d3 by the bounds'
greedy policy, certified (:mod:`mitld_lp.solvers.greedy_block`), so its LP stage calls
no solver; ``experiments/bench_sweeps.py --compare`` measures that route.  This script
measures the LP the route falls back to where that certificate fails: every block an
occupancy LP through Clarabel (``GREEDY_MIN_CHOICES`` raised past every block), its
single-choice states eliminated (:mod:`mitld_lp.solvers.eliminate`, and where the
compiled walk refuses, :mod:`mitld_lp.solvers.sparse_elimination`).

Per instance, in child processes, ``--repeats`` rounds of the checkout ``--compare DIR``
(before) and this one (after), alternating so the machine's load hits both: the
answer (the certified bracket), the solve stage's CPU seconds, the LP stage's and its
parts (eliminations, Clarabel, the crossover's polish).  Storm's best sound check
(``bench_sweeps.py``'s: every sound method on our DRN, 1e-9 absolute) in the same run,
its value beside.  Each figure the least CPU of the rounds.

    python experiments/bench_bus_lp.py --compare /tmp/base --stages --out /tmp/bus_lp

``--stages`` adds, per round, the default route (the greedy certificate on) in this
checkout with its stages' CPU (the analysis, the iteration, the LP stage and its greedy
certificate and flow, the certificate): ``bench_bus_lp_stages.csv``/``.md``.
``--quick``: ``bus_scaled`` n8 d3, one round, into ``experiments/out/quick``.
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

from bench_scaling import Instance  # noqa: E402  (the same instances)

FULL = [("bus_scaled", 64, 3), ("bus_scaled", 128, 3)]
QUICK = [("bus_scaled", 8, 3)]
PARTS = {"eliminate": "eliminate", "clarabel": "sensed", "polish": "polish"}
STAGES = (("analysis", "mitld_lp.solvers.analysis", "analyse"),
          ("iteration", "mitld_lp.solvers.iteration", "interval_iterations"),
          ("lp", "mitld_lp.solvers.lp", "solve_lp"),
          ("certificate", "mitld_lp.solvers.certify", "certify"),
          ("greedy", "mitld_lp.solvers.lp_blocks", "certified_greedy"),
          ("flow", "mitld_lp.solvers.lp_blocks", "policy_flow"),
          ("kernel", "mitld_lp.solvers.kernels", "compiled_kernel"),
          ("numba_import", "mitld_lp.util.numba_narrow", "import_numba"))
"""The default route's stages (and the LP stage's two parts there) timed by ``--stages``:
each function is imported by its caller when called, so wrapping it in its module
times every call.  ``kernel`` is the compiled sweeps' kernel asked for (its load from
numba's cache the first time, numba's import too where the analysis has not imported
it), ``numba_import`` ``import numba`` alone, wherever it happens (the analysis, where
it finds a component the compiled sweeps will take); both are inside the stage that
asks first."""


def work_lp(inst: Instance, stages: bool = False) -> dict[str, Any]:
    """``synthesize`` with every block an LP; the CPU of the LP stage and its parts.
    ``stages``: the default route instead (the greedy certificate on), its stages'
    CPU (:data:`STAGES`)."""
    import importlib

    import bench_sweeps

    import mitld_lp.solvers.lp as lp_stage
    import mitld_lp.solvers.lp_blocks as blocks
    from mitld_lp import synthesize

    model = bench_sweeps._model(inst)
    bench_sweeps.preload()
    if not stages:
        blocks.GREEDY_MIN_CHOICES = 1 << 62  # no block answered by the greedy certificate
    spent: dict[str, float] = {}

    def timed(module: Any, name: str, key: str) -> None:
        inner = getattr(module, name)

        def run(*a: Any, **k: Any) -> Any:
            c = time.process_time()
            try:
                return inner(*a, **k)
            finally:
                spent[key] = spent.get(key, 0.0) + time.process_time() - c

        setattr(module, name, run)

    if stages:
        for key, module, name in STAGES:
            timed(importlib.import_module(module), name, key)
    else:
        for key, name in PARTS.items():
            timed(blocks, name, key)
        timed(lp_stage, "solve_lp", "lp")
    r = synthesize(model)
    lp = r.lower_model.lp
    keys = [k for k, _, _ in STAGES] if stages else ["lp", *PARTS]
    return dict(value=r.lower, upper=r.upper, certified=r.certified,
                solve_cpu=r.solve_cpu, message=lp.message if lp is not None else "",
                **{f"{k}_cpu": spent.get(k, 0.0) for k in keys})


def _ours(inst: Instance, work: Path, code: Path | None, stages: bool = False
          ) -> dict[str, Any]:
    import bench_sweeps

    out = work / "lp.json"
    argv = [sys.executable, __file__, "--worker", inst.family, str(inst.n), str(inst.d),
            str(out), "stages" if stages else "lp"]
    cpu, err = bench_sweeps._cpu_of(argv, code)
    if cpu is None:
        raise RuntimeError(f"LP route on {inst.name} failed:\n{err[-2000:]}")
    return json.loads(out.read_text(encoding="utf-8"))


def measure(inst: Instance, work: Path, base: Path, repeats: int, stages: bool = False
            ) -> list[dict[str, Any]]:
    """The LP route before and after (a row each) and, with ``stages``, the default
    route's stages in this checkout (a third row, ``checkout`` "default route")."""
    import bench_sweeps

    runs: dict[str, list[dict[str, Any]]] = {"before": [], "after": []}
    if stages:
        runs["default route"] = []
    for _ in range(repeats):
        runs["before"].append(_ours(inst, work, base))
        runs["after"].append(_ours(inst, work, None))
        if stages:
            runs["default route"].append(_ours(inst, work, None, stages=True))
    bench_sweeps._child("export", inst, work)
    storm = bench_sweeps._child("storm_check", inst, work)
    (work / "model.drn").unlink()
    rows = []
    for which, got in runs.items():
        first = got[0]
        assert all((g["value"], g["upper"]) == (first["value"], first["upper"]) for g in got)
        least = {k: min(g[k] for g in got) for k in first if k.endswith("_cpu")}
        rows.append(dict(instance=inst.name, checkout=which, value=first["value"],
                         upper=first["upper"], certified=first["certified"], **least,
                         storm_best=storm["best"].lower(), storm_check_cpu=storm["best_cpu"],
                         storm_value=storm["methods"][storm["best"]]["value"],
                         solve_over_storm_check=least["solve_cpu"] / storm["best_cpu"],
                         message=first["message"]))
    return rows


COLUMNS = ("instance", "checkout", "value", "upper", "certified", "solve_cpu", "lp_cpu",
           "eliminate_cpu", "clarabel_cpu", "polish_cpu", "storm_best", "storm_value",
           "storm_check_cpu", "solve_over_storm_check")
STAGE_COLUMNS = ("instance", "checkout", "value", "upper", "certified", "solve_cpu",
                 *(f"{k}_cpu" for k, _, _ in STAGES), "storm_check_cpu",
                 "solve_over_storm_check")


ANSWERS = ("value", "upper", "storm_value")


def _fmt(key: str, x: Any) -> str:
    """Answers to the last bit, times and ratios to three decimals."""
    return repr(x) if key in ANSWERS else f"{x:.3f}" if isinstance(x, float) else str(x)


def main(argv: list[str] | None = None) -> list[dict[str, Any]]:
    import _common
    from bench_scaling import machine_text

    ap = _common.parser(__doc__.splitlines()[0])
    ap.add_argument("--compare", type=Path, required=True, metavar="DIR",
                    help="the checkout whose mitld_lp is 'before'")
    ap.add_argument("--repeats", type=int, default=None,
                    help="rounds of before and after (default 3, 1 with --quick)")
    ap.add_argument("--stages", action="store_true",
                    help="also the default route's stages in this checkout (a table of "
                         "their own)")
    args = ap.parse_args(argv)
    if not (args.compare / "mitld_lp").is_dir():
        ap.error(f"--compare {args.compare}: no mitld_lp package in that directory")
    out = _common.out_dir(args)
    rows: list[dict[str, Any]] = []
    for spec in QUICK if args.quick else FULL:
        inst = Instance(*spec)
        with tempfile.TemporaryDirectory() as tmp:
            work = Path(tmp) / inst.name
            work.mkdir()
            rows += measure(inst, work, args.compare.resolve(),
                            args.repeats or (1 if args.quick else 3), args.stages)
        for r in rows[-3 if args.stages else -2:]:
            cols = STAGE_COLUMNS if r["checkout"] == "default route" else COLUMNS
            print(" ".join(f"{k}={_fmt(k, r[k])}" for k in cols), flush=True)
    lp_rows = [r for r in rows if r["checkout"] != "default route"]
    _common.write_tables(out, "bench_bus_lp", COLUMNS,
                         [[_fmt(k, r[k]) for k in COLUMNS] for r in lp_rows])
    if args.stages:
        _common.write_tables(out, "bench_bus_lp_stages", STAGE_COLUMNS, [
            [_fmt(k, r[k]) for k in STAGE_COLUMNS] for r in rows if r not in lp_rows])
    _common.write_text(out / "bench_bus_lp_messages.txt", "".join(
        f"{r['instance']} {r['checkout']}: {r['message']}\n" for r in rows))
    _common.write_text(out / "bench_bus_lp_machine.txt", machine_text(
        "shared 2-core machine, other processes running; CPU seconds, least of the rounds",
        [f"command: python experiments/bench_bus_lp.py {' '.join(argv or sys.argv[1:])}",
         "storm: bench_sweeps.py's best sound check on our DRN (1e-9 absolute)"]))
    return rows


def worker(argv: list[str]) -> None:
    family, n, d, out, route = argv
    Path(out).write_text(json.dumps(work_lp(Instance(family, int(n), int(d)),
                                            stages=route == "stages")), encoding="utf-8")


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--worker":
        worker(sys.argv[2:])
    else:
        main()
