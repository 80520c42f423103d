"""Benchmark: the solve stage's graph analysis by the NumPy walks and by the compiled
ones (numba), beside Storm's graph analysis (prob01) of the same product, one run.

Per instance (posed as ``bench_qvbs.py`` poses it), in a child process of its own: the
product built by :func:`mitld_lp.synthesize` up to its analysis, then
:func:`mitld_lp.solvers.analysis.analyse` timed (CPU seconds) three ways -- the NumPy
walks (numba not loaded; SciPy's ``csgraph`` imported before), the compiled walks at
their first call in the process (numba loaded and its sweep kernel run before, as the
sweeps of an earlier solve leave it: each walk's kernel read from its disk cache) and
at a second call -- with the answer beside each time: the states of value 0 and 1 the
graph decides and the end components found (the three must be the same sets,
checked); and Storm's
``compute_prob01_states`` for ``Pmax``/``Pmin`` of the same target on our DRN (its
counts and its CPU seconds).

::

    python experiments/bench_walks.py --qvbs qcomp/benchmarks --out experiments/results
    python experiments/bench_walks.py --qvbs qcomp/benchmarks --quick  # one small instance

Written: ``bench_walks.csv``, ``bench_walks.md`` and ``bench_walks_machine.txt``.
"""

from __future__ import annotations

import argparse
import json
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
import bench_qvbs as bq  # noqa: E402  (the same instances, posed the same way)

INSTANCES = ("zeroconf.20-4-false.correct_max", "csma.4-2.some_before", "consensus.4-4.c2")
COLUMNS = ("instance", "states", "transitions", "zero", "one", "mecs", "numpy_cpu",
           "compiled_first_cpu", "compiled_cpu", "storm_zero", "storm_one",
           "storm_prob01_cpu")


class _Captured(BaseException):  # past any handler of the route: the analysis is next
    pass


def child(job: dict[str, Any], work: Path) -> dict[str, Any]:
    import numpy as np

    from mitld_lp import load_model, synthesize
    from mitld_lp.solvers import analysis, kernels, walks, write_drn
    from mitld_lp.solvers.graph import Sense

    args: list[Any] = []
    inner = analysis.analyse

    def grab(*a: Any, **k: Any) -> Any:
        args.append((a, k))
        raise _Captured

    analysis.analyse = grab
    try:
        synthesize(load_model(job["model"], max_states=job["max_states"]))
    except _Captured:
        pass
    analysis.analyse = inner
    (mdp, goal, *_), kw = args[0]

    def run() -> tuple[float, Any]:
        c = time.process_time()
        q = inner(*args[0][0], **kw)[0]
        return time.process_time() - c, q

    import scipy.sparse.csgraph  # noqa: F401  (its import is no walk's cost)

    high = (walks.COMPILED_MIN_ENTRIES, walks.COMPILED_LOADED_MIN_ENTRIES,
            kernels.COMPILED_MIN_ENTRIES)
    walks.COMPILED_MIN_ENTRIES = walks.COMPILED_LOADED_MIN_ENTRIES = sys.maxsize
    kernels.COMPILED_MIN_ENTRIES = sys.maxsize  # nor numba loaded for the sweeps' sake
    numpy_cpu, want = run()
    assert "numba" not in sys.modules
    walks.COMPILED_MIN_ENTRIES, walks.COMPILED_LOADED_MIN_ENTRIES = 0, 0
    kernels.COMPILED_MIN_ENTRIES = high[2]
    walks.load_walks()
    _first_sweep()  # numba's own first-call set-up, which a solve's sweeps pay
    first_cpu, got = run()
    second_cpu, again = run()
    for q in (got, again):
        for name in ("zero", "one"):
            assert np.array_equal(getattr(q.qualitative, name), getattr(want.qualitative, name))
        assert np.array_equal(q.mecs.mec_of, want.mecs.mec_of)
    out = dict(states=mdp.n_states, transitions=mdp.n_transitions,
               zero=int(want.qualitative.zero.sum()), one=int(want.qualitative.one.sum()),
               mecs=want.mecs.n_mecs, numpy_cpu=numpy_cpu, compiled_first_cpu=first_cpu,
               compiled_cpu=second_cpu)
    import stormpy
    import stormpy.analysis

    path = write_drn(mdp, goal, work / "model.drn", overwrite=True, valuations=False)
    model = stormpy.build_model_from_drn(str(path))
    sense = Sense(kw.get("sense", Sense.MAX))
    prop = stormpy.parse_properties(f'P{sense.value}=? [F "target"]')[0]
    c = time.process_time()
    zero, one = stormpy.analysis.compute_prob01_states(model, prop)
    out.update(storm_prob01_cpu=time.process_time() - c, storm_zero=zero.get_number_of_set_bits(),
               storm_one=one.get_number_of_set_bits())
    return out


def _first_sweep() -> None:
    """The sweeps' kernel called once on a 50-state block (as ``profile_solve.py``
    does): numba's registries set up, as an earlier solve's sweeps leave them."""
    import numpy as np
    import scipy.sparse as sp

    from mitld_lp.solvers.kernels import FLOOR, compiled_kernel

    n = 50
    a = sp.random_array((n, n), density=0.1, format="csr", rng=0)
    compiled_kernel()(a.indptr, a.indices, a.data, np.arange(n + 1), np.ones(n),
                      np.zeros((n, 2)), np.column_stack([np.zeros(n), np.ones(n)]),
                      np.arange(n)[::-1].copy(), 5, 1e-6, False, -1.0, FLOOR)


def main(argv: list[str] | None = None) -> int:
    ap = _common.parser(__doc__.splitlines()[0])
    ap.add_argument("--qvbs", type=Path, default=None,
                    help="the benchmarks/ folder of a checkout of github.com/ahartmanns/qcomp")
    ap.add_argument("--only", nargs="*", default=None, metavar="NAME")
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        work = Path(args.child)
        job = json.loads((work / "job.json").read_text(encoding="utf-8"))
        (work / "out.json").write_text(json.dumps(child(job, work)), encoding="utf-8")
        return 0
    if args.qvbs is None:
        ap.error("--qvbs is required (a checkout's benchmarks/ folder)")
    out = _common.out_dir(args)
    wanted = set(args.only or INSTANCES)
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench_walks_") as tmp:
        work = Path(tmp)
        high = bq.QUICK_MAX_STATES if args.quick else bq.MAX_STATES
        found, _ = bq.jobs(args.qvbs, 0, high, bq.FAMILIES, work)
        found.sort(key=lambda t: t[0].qvbs_states)
        chosen = found[-1:] if args.quick else [f for f in found if f[0].name in wanted]
        for inst, job in chosen:
            (work / "job.json").write_text(json.dumps(job), encoding="utf-8")
            proc = subprocess.run([sys.executable, __file__, "--child", str(work)],
                                  capture_output=True, text=True, timeout=bq.BUDGET)
            row = (json.loads((work / "out.json").read_text(encoding="utf-8"))
                   if proc.returncode == 0 else {"states": proc.stderr.strip()[-200:]})
            rows.append([inst.name, *(row.get(k) for k in COLUMNS[1:])])
            print(_common.text_table(COLUMNS, rows[-1:]), flush=True)
    shown = [[f"{v:.3g}" if isinstance(v, float) else v for v in r] for r in rows]
    text = ("## The analysis's walks, NumPy and compiled, beside Storm's prob01 (CPU seconds)"
            "\n\n" + _common.markdown_table(COLUMNS, shown) + "\n")
    _common.write_text(out / "bench_walks.md", text)
    _common.write_csv(out / "bench_walks.csv", COLUMNS, rows)
    from bench_scaling import machine_text

    _common.write_text(out / "bench_walks_machine.txt", machine_text(
        "shared 2-core machine, other processes running; one run, CPU seconds",
        [f"command: python experiments/bench_walks.py {' '.join(argv or sys.argv[1:])}",
         "storm: stormpy.analysis.compute_prob01_states on our DRN of the product"]))
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
