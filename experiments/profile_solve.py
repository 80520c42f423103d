"""Profile: where the solve stage's CPU goes on QVBS instances, and what numba's load costs.

Per instance (posed as ``bench_qvbs.py`` poses it), in child processes of their own:

* ``bench_qvbs.measure``: our solve stage (``solve_cpu``, no profiler) beside Storm's
  best sound check on the same product (``storm_check_cpu``), the answer beside each;
* ``stages``: the same synthesis again with the entry point of each stage of the
  solve timed (``timed_solve_cpu`` its solve stage): the analysis (``analyse``), the
  interval iteration (``interval_iterations``: with numba's import and load where a
  block is swept compiled), the LP stage (``solve_lp``), the certificate
  (``certify``), and ``numba_import``: the first call of
  ``kernels.compiled_kernel`` (``import numba`` and the kernel module, at the first
  large block), inside the iteration's figure;
* with ``--numpy-sweeps``, ``stages`` once more with no block swept compiled (numba
  never loaded): what a size threshold above the instance would cost; with
  ``--compiled-sweeps``, once more with every block swept compiled (numba loaded
  whatever the sizes): what a threshold below it would cost;
* the level walks inside those stages (:data:`WALKS`: ``levels``, ``single_bounds``,
  ``single_values``, ``single_flow``, ``chain_singles``, ``repair``), timed alike;
* what is not a walk (:data:`SETUP`: ``components``, ``search``, ``single_setup``,
  ``chain``, ``bellman_check``), timed alike;
* ``numba``: a fresh interpreter with NumPy and SciPy loaded as the solve has them:
  ``import numba``, the first call of the sweep kernel on a 50-state block (the
  registries' set-up and its load from the cache), then a second kernel's first call.

::

    python experiments/profile_solve.py --qvbs qcomp/benchmarks --out experiments/results
    python experiments/profile_solve.py --qvbs qcomp/benchmarks --quick  # one small instance
    python experiments/profile_solve.py --qvbs qcomp/benchmarks --min-states 0 \
        --only consensus.4-4.c2 --bus bus_scaled_n64_d3 --numpy-sweeps --compiled-sweeps

``--compare DIR`` runs ``stages`` once more per instance with the library of another
checkout (``DIR``, e.g. ``git archive`` of the base; this script's harness, that
checkout's ``mitld_lp``), right after this one's, and writes its figures beside as
``base_*`` columns: the iteration, its sweeps, the timed solve stage and the value.

``--bus`` adds instances of ``bench_sweeps.py`` (posed as it poses them, Storm's best
check on our DRN beside); ``--min-states`` lets in QVBS instances below the benchmark's
1e5 states.

Written: ``profile_solve.csv``, ``profile_solve.md``.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

import _common  # noqa: E402
import bench_qvbs as bq  # noqa: E402  (the same instances, posed and measured the same way)
import bench_sweeps as bs  # noqa: E402

INSTANCES = ("zeroconf.20-4-false.correct_max", "csma.4-2.some_before")
STAGES = {"analysis": ("mitld_lp.solvers.analysis", "analyse"),
          "iteration": ("mitld_lp.solvers.iteration", "interval_iterations"),
          "lp": ("mitld_lp.solvers.lp", "solve_lp"),
          "certificate": ("mitld_lp.solvers.certify", "certify")}
NUMBA_IMPORT = ("mitld_lp.solvers.kernels", "compiled_kernel")  # imports numba, once
WALKS = {"levels": ("mitld_lp.solvers.graph", "levels"),
         "single_bounds": ("mitld_lp.solvers.topological", "SingleLevels.solve"),
         "single_values": ("mitld_lp.solvers.topological", "SingleLevels.values"),
         "single_flow": ("mitld_lp.solvers.topological", "SingleLevels.flow"),
         "chain_singles": ("mitld_lp.solvers.certify_chain", "_Singles.solve"),
         "repair": ("mitld_lp.solvers.certify_repair", "Repair.run")}
"""The level walks inside the stages, timed alike (each inside its stage's figure): the
component levels of the analysis, the single-state walks of the iteration (bounds) and
of the LP (values, flow), the certificate's chain and its repair."""
SETUP = {"components": ("mitld_lp.solvers.graph", "strong_components"),
         "search": ("mitld_lp.solvers.graph", "searched_levels"),
         "single_setup": ("mitld_lp.solvers.topological", "SingleLevels.__init__"),
         "chain": ("mitld_lp.solvers.certify", "chain"),
         "bellman_check": ("mitld_lp.solvers.certify", "_fails")}
"""What is not a walk, timed alike where the stages call it (each inside its stage's
figure, and ``search`` inside ``levels``): Tarjan's searches called from
:mod:`~mitld_lp.solvers.graph` (the levels' and the end components'), the search of thin
levels, the single levels' set-up (the iteration and the LP each build theirs), the
certificate's whole chain (its set-up, searches and walk: ``chain_singles`` inside it)
and its Bellman checks of each candidate."""
COLUMNS = ("instance", "value", "solve_cpu", "storm_check_cpu", "solve_over_storm_check",
           "timed_solve_cpu", "analysis", "iteration", "sweeps", "lp", "certificate",
           "numba_import", "numba_loaded", *WALKS, *SETUP)
BASE = ("base_value", "base_upper", "upper", "same_bracket", "base_timed_solve_cpu",
        "base_iteration", "base_sweeps")
"""The columns ``--compare`` adds (``upper`` this checkout's, beside the base's;
``same_bracket``: both ends equal to the bit)."""


def child_stages(job: dict[str, Any]) -> dict[str, Any]:
    """The synthesis with each stage's entry point timed (CPU seconds, no profiler:
    the functions the solve stage imports when it runs, wrapped)."""
    import importlib

    from mitld_lp import load_model, synthesize

    if "bus" in job:  # an instance of bench_sweeps.py's families, posed as it poses them
        from bench_scaling import Instance

        model = bs._model(Instance(*job["bus"]))
    else:
        model = load_model(job["model"], max_states=job["max_states"])
    bs.preload()
    if job.get("numpy_sweeps") or job.get("compiled_sweeps"):
        from mitld_lp.solvers import kernels

        if job.get("numpy_sweeps"):  # no block large enough for the compiled sweeps
            kernels.COMPILED_MIN_ENTRIES = sys.maxsize
        else:  # every block large enough
            kernels.COMPILED_MIN_ENTRIES = kernels.COMPILED_MIN_BLOCK_ENTRIES = 0
    spent = dict.fromkeys((*STAGES, "numba_import", *WALKS, *SETUP), 0.0)
    for stage, (module, name) in {**STAGES, "numba_import": NUMBA_IMPORT,
                                  **WALKS, **SETUP}.items():
        owner: Any = importlib.import_module(module)
        *path, name = name.split(".")  # a method: wrapped on its class
        for part in path:
            # a class's old private name in a checkout before it was made public
            owner = getattr(owner, part, None) or getattr(owner, "_" + part)
        setattr(owner, name, _timed(getattr(owner, name), stage, spent))
    iteration = importlib.import_module(STAGES["iteration"][0])
    timed_iteration = iteration.interval_iterations
    sweeps = [0]

    def counted(*args: Any, **kwargs: Any) -> Any:
        results = timed_iteration(*args, **kwargs)
        sweeps[0] += results[0].iterations if results else 0
        return results

    iteration.interval_iterations = counted
    r = synthesize(model)
    return dict(spent, value=r.lower, upper=r.upper, solve_cpu=r.solve_cpu,
                sweeps=sweeps[0], numba_loaded="numba" in sys.modules)


def _timed(func: Any, stage: str, spent: dict[str, float]) -> Any:
    def timed(*args: Any, **kwargs: Any) -> Any:
        c = time.process_time()
        try:
            return func(*args, **kwargs)
        finally:
            spent[stage] += time.process_time() - c
    return timed


def child_numba(job: dict[str, Any]) -> dict[str, Any]:
    """``import numba`` and the first calls of two cached kernels, in CPU seconds."""
    import numpy as np
    import scipy.sparse as sp

    bs.preload()
    c = time.process_time()
    import numba  # noqa: F401

    from mitld_lp.solvers.kernels import FLOOR, _new_track, compiled_kernel
    from mitld_lp.solvers.topological import level_kernels
    imported = time.process_time() - c
    n = 50
    a = sp.random_array((n, n), density=0.1, format="csr", rng=0)
    local = np.column_stack([np.zeros(n), np.ones(n)])
    c = time.process_time()
    done, _ = compiled_kernel()(a.indptr, a.indices, a.data, np.arange(n + 1), np.ones(n),
                                np.zeros((n, 2)), local, np.arange(n)[::-1].copy(), 5,
                                1e-6, False, -1.0, FLOOR, np.zeros((n, 2)),
                                _new_track(2, False))
    first = time.process_time() - c
    x = np.zeros((n, 1))
    c = time.process_time()
    level_kernels(1, 1, compiled=True).chain_solve(np.arange(n), a.indptr, a.indices,
                                                  a.data, a.diagonal(), np.ones((n, 1)), x)
    second = time.process_time() - c
    return dict(import_numba=imported, first_kernel=first, second_kernel=second,
                sweeps=int(done), x0=float(x[0, 0]))


def _run_child(kind: str, job: dict[str, Any], work: Path,
               script: str = __file__, library: Path | None = None) -> dict[str, Any]:
    """``job`` run by ``script --child kind work`` (this one's, or another experiment's
    that answers the same way: ``gate_blocks.py``), its answer read back; ``library``:
    another checkout whose ``mitld_lp`` the child imports (``--compare``)."""
    (work / "job.json").write_text(json.dumps(job), encoding="utf-8")
    env = None
    if library is not None:
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(
            [str(library.resolve()), *filter(None, [os.environ.get("PYTHONPATH")])]))
    proc = subprocess.run([sys.executable, script, "--child", kind, str(work)],
                          capture_output=True, text=True, timeout=bq.BUDGET, env=env)
    if proc.returncode != 0:
        return {"error": proc.stderr.strip().splitlines()[-1:]}
    return json.loads((work / f"{kind}.json").read_text(encoding="utf-8"))


def main(argv: list[str] | None = None) -> int:
    ap = _common.parser(__doc__.splitlines()[0])
    ap.add_argument("--qvbs", type=Path, required=False,
                    help="a checkout's benchmarks/ folder of ahartmanns/qcomp")
    ap.add_argument("--only", nargs="*", default=None, metavar="NAME")
    ap.add_argument("--min-states", type=int, default=bq.MIN_STATES,
                    help="the least QVBS size of an instance (default: the benchmark's)")
    ap.add_argument("--bus", nargs="*", default=(), metavar="NAME",
                    help="also these instances of bench_sweeps.py (e.g. bus_scaled_n64_d3), "
                         "its Storm check beside")
    ap.add_argument("--numpy-sweeps", action="store_true",
                    help="a second row per instance with the NumPy sweeps only (numba "
                         "never loaded): what a size threshold would give")
    ap.add_argument("--compiled-sweeps", action="store_true",
                    help="a row per instance with every block swept compiled (numba "
                         "loaded whatever the sizes): the gate's other side")
    ap.add_argument("--compare", type=Path, default=None, metavar="DIR",
                    help="also the stages with another checkout's mitld_lp (base_* "
                         "columns; warm its numba cache with one run first)")
    ap.add_argument("--child", nargs=2, default=None, help=argparse_hidden())
    args = ap.parse_args(argv)
    if args.child:
        kind, work = args.child[0], Path(args.child[1])
        job = json.loads((work / "job.json").read_text(encoding="utf-8"))
        run = child_stages if kind == "stages" else child_numba
        (work / f"{kind}.json").write_text(json.dumps(run(job)), encoding="utf-8")
        return 0
    if args.qvbs is None:
        ap.error("--qvbs is required (a checkout's benchmarks/ folder)")
    out = _common.out_dir(args)
    columns = COLUMNS + (BASE if args.compare else ())
    rows = []
    with tempfile.TemporaryDirectory(prefix="profile_solve_") as tmp:
        work = Path(tmp)
        wanted = set(args.only or ([] if args.bus else INSTANCES))
        chosen = [*chosen_jobs(args.qvbs, args.quick, wanted, work, args.min_states),
                  *bus_jobs(args.bus)]
        numba_row = _run_child("numba", {}, work)
        for inst, job in chosen:
            (work / inst.name).mkdir()
            row = (bs.measure(inst, work / inst.name) if "bus" in job
                   else bq.measure(inst, job, work / inst.name, bq.BUDGET))
            stages = _run_child("stages", job, work / inst.name)
            base = {}
            if args.compare:  # right after this checkout's run: the same noise on both
                base = _run_child("stages", job, work / inst.name, library=args.compare)
                if "error" in base:
                    print(f"{inst.name}: the base's stages failed: {base['error']}")
            first = len(rows)
            rows.append([inst.name, row.get("value"), row.get("solve_cpu"),
                         row.get("storm_check_cpu"), row.get("solve_over_storm_check"),
                         stages.get("solve_cpu"), *(stages.get(k) for k in COLUMNS[6:]),
                         *([base.get("value"), base.get("upper"), stages.get("upper"),
                            "yes" if (base.get("value"), base.get("upper"))
                            == (stages.get("value"), stages.get("upper")) else "no",
                            base.get("solve_cpu"), base.get("iteration"),
                            base.get("sweeps")] if args.compare else [])])
            for flag, label in (("numpy_sweeps", "NumPy sweeps"),
                                ("compiled_sweeps", "compiled sweeps")):
                if not getattr(args, flag):
                    continue
                alone = _run_child("stages", dict(job, **{flag: True}), work / inst.name)
                rows.append([f"{inst.name} ({label})", alone.get("value"), None,
                             row.get("storm_check_cpu"), None, alone.get("solve_cpu"),
                             *(alone.get(k) for k in COLUMNS[6:]),
                             *([None] * len(BASE) if args.compare else [])])
            print(_common.text_table(columns, rows[first:]), flush=True)
    exact = {columns.index(c) for c in ("value", "base_value", "base_upper", "upper")
             if c in columns}  # the answers in full: each beside its time
    shown = [[f"{v:.3g}" if isinstance(v, float) and i not in exact else v
              for i, v in enumerate(r)] for r in rows]
    text = ("## The solve stage by stage, and numba's load (CPU seconds)\n\n"
            + _common.markdown_table(columns, shown)
            + "\n\nnumba in a fresh interpreter with NumPy and SciPy loaded: "
            + ", ".join(f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}"
                        for k, v in numba_row.items()) + "\n")
    _common.write_text(out / "profile_solve.md", text)
    _common.write_csv(out / "profile_solve.csv", columns, rows)
    print(text)
    return 0


def chosen_jobs(benchmarks: Path, quick: bool, wanted: set[str], work: Path,
                low: int = bq.MIN_STATES) -> list[tuple[Any, dict[str, Any]]]:
    """The QVBS instances to run, posed as ``bench_qvbs.py`` poses them (their model
    files written to ``work``): with ``quick`` the largest under its quick bound, else
    those ``wanted`` (names) of at least ``low`` QVBS states, smallest first."""
    high = bq.QUICK_MAX_STATES if quick else bq.MAX_STATES
    found, _ = bq.jobs(benchmarks, 0 if quick else low, high, bq.FAMILIES, work)
    found.sort(key=lambda t: t[0].qvbs_states)
    return found[-1:] if quick else [f for f in found if f[0].name in wanted]


def bus_jobs(names: Any) -> list[tuple[Any, dict[str, Any]]]:
    """``bench_sweeps.py``'s instances named in ``names`` (e.g. ``bus_scaled_n64_d3``)."""
    from bench_scaling import Instance

    known = {Instance(*i).name: i for i in bs.FULL}
    unknown = sorted(set(names) - set(known))
    if unknown:
        raise SystemExit(f"--bus: no such instance of bench_sweeps.py: {unknown}")
    return [(Instance(*known[n]), {"bus": list(known[n])}) for n in names]


def argparse_hidden() -> str:
    import argparse

    return argparse.SUPPRESS


if __name__ == "__main__":
    raise SystemExit(main())
