"""Where the LP stage's CPU goes, part by part, on QVBS instances and the bus family:
each part's entry point timed in place (process time, inclusive) while ``solve_lp``
runs, in a child process of its own a checkout, one synthesis each (the first of the
process, as ``bench_qvbs.py`` and ``bench_sweeps.py`` time it: numba's cached kernels
loaded where the stage first calls them), the answer beside::

    python experiments/lp_stage_parts.py <checkout> <QVBS benchmarks dir> <instance>... \\
        [--compare <other checkout>] [--out FILE.md]

An instance is a QVBS name (``zeroconf.1000-4-false.correct_max``), a
``bench_sweeps.py`` one (``bus_scaled_n64_d3``) or ``sensed`` (``bench_qvbs.py``'s
sensed bus case, ``bench_sensed.py``'s first: its two truncation models' LPs summed, and
``solve CPU`` the sensed route's solve as ``bench_qvbs.py`` counts it). The parts
(:data:`PARTS`) nest: the chain walks (``ChainLevels``: a policy's chain, its components
found and levels factorised, and its forward solves) are inside whichever part makes
them (the greedy check's policy chain, the crossover's, a flow's cyclic level), the
numba loads inside whichever part first calls a kernel; ``other`` is the stage less the
top-level parts; ``singles`` holds the single states' level walk and, where the
iteration's bounds already answer it, their check (``settled_by_bounds``). ``jump``,
outside the LP stage, is the interval iteration's policy jumps
(:func:`mitld_lp.solvers.policy_jump.jump`: their policy iterations' factorisations and
look-ahead sweeps), which the LP stage's bounds come from.
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from lp_stage_peak import arguments, finish, run_child  # noqa: E402  (the same harness)

#: (module, attribute (``Class.method`` for a method), part); the top-level parts
#: first, then the nested ones
PARTS = (("mitld_lp.solvers.lp_blocks", "certified_greedy", "greedy"),
         ("mitld_lp.solvers.topological", "Block.of", "blocks"),
         ("mitld_lp.solvers.lp_blocks", "solve_single_states", "singles"),
         ("mitld_lp.solvers.lp_blocks", "settled_by_bounds", "singles"),
         ("mitld_lp.solvers.topological", "SingleLevels.values", "singles"),
         ("mitld_lp.solvers.lp_blocks", "tightened", "tighten"),
         ("mitld_lp.solvers.lp_blocks", "solve_block", "solver"),
         ("mitld_lp.solvers.lp_blocks", "polish", "crossover"),
         ("mitld_lp.solvers.lp_blocks", "policy_flow", "flow"),
         ("mitld_lp.solvers.lp", "_result", "mapped back"),
         ("mitld_lp.solvers.chain_levels", "ChainLevels.__init__", "chain walks"),
         ("mitld_lp.solvers.chain_levels", "ChainLevels.solve", "chain walks"))
TOP = ("greedy", "blocks", "singles", "tighten", "solver", "crossover", "flow",
       "mapped back")
COLUMNS = TOP + ("chain walks", "numba loads", "other", "jump")


def _model(root: Path, benchmarks: Path, name: str) -> Any:
    if name == "sensed":
        import bench_qvbs as bq
        import bench_sensed

        model = bench_sensed.case_model(bq.SENSED, False)
        bq.bs.preload()
        return model
    if name.startswith("bus_scaled_"):
        import bench_sweeps as bs

        n, d = (int(p[1:]) for p in name.split("_")[2:4])
        model = bs._model(bs.Instance("bus_scaled", n, d))
        bs.preload()
        return model
    import bench_qvbs as bq

    from mitld_lp import load_model

    work = Path(tempfile.mkdtemp(prefix="lp_stage_parts_"))
    found, _ = bq.jobs(benchmarks, 0, bq.MAX_STATES, bq.FAMILIES, work)
    job = next(j for i, j in found if i.name == name)
    model = load_model(job["model"], max_states=job["max_states"])
    bq.bs.preload()
    return model


def child(root: Path, benchmarks: Path, name: str) -> dict[str, Any]:
    """One instance with ``root``'s package: the LP stage's parts (module docs)."""
    sys.path[:0] = [str(root), str(root / "experiments")]
    import importlib

    model = _model(root, benchmarks, name)
    import mitld_lp.solvers.lp as lpm
    from mitld_lp import synthesize

    cpu: dict[str, float] = {}
    inside = [False]

    def timed(part: str, f: Any) -> Any:
        def run(*a: Any, **k: Any) -> Any:
            if not inside[0]:
                return f(*a, **k)
            t = time.process_time()
            try:
                return f(*a, **k)
            finally:
                cpu[part] = cpu.get(part, 0.0) + time.process_time() - t
        return run

    for module, attr, part in PARTS:
        mod = importlib.import_module(module)
        owner, _, name_ = attr.rpartition(".")
        host = getattr(mod, owner) if owner else mod
        f = getattr(host, name_, None)
        if f is None:  # a checkout from before the part (a base of --compare)
            continue
        wrapped = timed(part, f)
        setattr(host, name_, staticmethod(wrapped) if owner and attr == "Block.of"
                else wrapped)
    try:  # numba's loads of cached kernels (where numba is installed)
        import numba.core.dispatcher as nd

        nd.Dispatcher._compile_for_args = timed("numba loads",
                                                nd.Dispatcher._compile_for_args)
    except ImportError:
        pass
    import mitld_lp.solvers.iteration as iteration

    jump = iteration.jump

    def jump_timed(*a: Any, **k: Any) -> Any:  # the iteration's, outside the LP stage
        t = time.process_time()
        try:
            return jump(*a, **k)
        finally:
            cpu["jump"] = cpu.get("jump", 0.0) + time.process_time() - t
    iteration.jump = jump_timed
    solve_lp = lpm.solve_lp

    def lp_timed(*a: Any, **k: Any) -> Any:
        inside[0] = True
        t = time.process_time()
        try:
            return solve_lp(*a, **k)
        finally:
            cpu["lp"] = cpu.get("lp", 0.0) + time.process_time() - t
            inside[0] = False
    for mod in list(sys.modules.values()):
        if getattr(mod, "solve_lp", None) is solve_lp:
            mod.solve_lp = lp_timed
    sensed_cpu = None
    if name == "sensed":  # the route leaves Result.solve_cpu unset: bench_qvbs's timer
        import bench_qvbs as bq

        sensed_cpu = bq._timed_sensed_solve()
    r = synthesize(model)
    cpu["other"] = cpu["lp"] - sum(cpu.get(p, 0.0) for p in TOP)
    return {"instance": name, "lower": repr(r.lower), "upper": repr(r.upper),
            "solve_cpu": (r.solve_cpu if sensed_cpu is None else sum(sensed_cpu)),
            "cpu": cpu}


def main(argv: list[str]) -> None:
    if argv and argv[0] == "--child":
        print(json.dumps(child(Path(argv[1]).resolve(), Path(argv[2]), argv[3])))
        return
    args, roots = arguments(argv, __doc__)
    lines = ["| instance | lower | upper | solve CPU | LP CPU | "
             + " | ".join(COLUMNS) + " | checkout |",
             "|---|---|---|---|---|" + "---|" * len(COLUMNS) + "---|"]
    for name in args.instances:
        for root in roots:
            row = run_child(root, args.benchmarks, name, __file__)
            if "error" in row:
                print(row["error"], file=sys.stderr)
                lines.append(f"| {name} | error | | | |" + " |" * len(COLUMNS) + f" {root} |")
                continue
            cpu = row["cpu"]
            lines.append(f"| {name} | {row['lower']} | {row['upper']} | "
                         f"{row['solve_cpu']:.3f} | {cpu['lp']:.3f} | "
                         + " | ".join(f"{cpu.get(c, 0.0):.3f}" for c in COLUMNS)
                         + f" | {root} |")
            print(lines[-1], flush=True)
    finish(lines, args.out)


if __name__ == "__main__":
    main(sys.argv[1:])
