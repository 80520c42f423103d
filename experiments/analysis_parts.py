"""Where the solve stage's graph analysis goes, part by part, on QVBS instances; and what
it would cost compiled, beside numba's load.

Per instance (posed as ``bench_qvbs.py`` poses it), in a child process: the model
loaded, one ``synthesize`` whose call of ``analysis.analyse`` is kept (its product,
target and sense), then that call repeated ``--reps`` times (after one call not timed)
with the entry point of each part timed (CPU seconds, medians):

* ``analyse``: the whole analysis; ``levels``: the product's components and reach, and
  its levels where the compiled walk finds them at no cost (``graph.components_reaching``;
  0 in a checkout before it, whose ``state_components`` is not timed);
  ``quotient_levels``: the quotient's own components and levels, found on the quotient
  where the product's are not (``quotient_order.state_levels``); of ``levels``,
  ``components`` (SciPy's Tarjan, ``graph.strong_components``) and ``searched``
  (``graph.searched_levels``: Dijkstra where the levels are thin) and ``reach``
  (``graph.reaching``: a breadth-first search a target);
* ``end_components`` (maxima), ``ends_and_sure`` (a maximum's end components with,
  where none, its goal's value-1 states and their attractor first: ``analysis_ends``;
  0 in a checkout without it, whose ``end_components`` and the rest hold them),
  ``attractor`` (the minima's ``Prob0E``, and the
  maxima's value-1 states inside ``one``), ``one`` (the quotients' value-1 states),
  ``order`` (the quotient's blocks), ``prob1a_first`` / ``prob1e_first`` (the goal's
  value-1 states found before the quotient: ``solvers.value_one``; 0 in a checkout
  without them, where ``one`` finds them on the quotient), ``numba_load`` and
  ``walks_loaded`` (numba's import and the compiled walks' load where the analysis makes
  them, the sweeps to come being compiled); ``rest``: the quotient's arrays, the
  analysis less the parts above;
* the same parts of the *first* call, the route's own in ``synthesize`` (what
  ``bench_qvbs.py``'s ``analysis_cpu`` counts: numba's import and each kernel's load
  from the disk cache inside, and the first touch of every array);
* then, in the same child, the kernel loader's load paid (``numba_import``:
  ``kernel_loader.prepare``, its pieces or numba's import where they cannot be set up)
  and the compiled walks' module imported (``walks_load``), and every walk's gate
  forced on whatever the graph's size: the first analysis (``first_compiled``: each
  kernel's link inside) and the median of the next (``compiled``), with their parts
  (the third table).  Where the instance's load is paid already, ``numba_import`` is
  about 0.

The answer (the solve's lower bound) is printed beside.  ::

    python experiments/analysis_parts.py --qvbs qcomp/benchmarks --min-states 0 \\
        --only zeroconf_dl.1000-1-false-30.deadline_max csma.4-2.some_before --sensed

Written: ``analysis_parts.md``.
"""

from __future__ import annotations

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
import bench_qvbs as bq  # noqa: E402
import profile_solve as ps  # noqa: E402  (the same instances, posed the same way)

PARTS = {"levels": ("analysis", "components_reaching"),
         "quotient_levels": ("quotient_order", "state_levels"),
         "components": ("graph", "strong_components"),
         "searched": ("graph", "searched_levels"),
         "reach": ("graph", "reaching"),
         "end_components": ("analysis", "end_components"),
         "ends_and_sure": ("analysis", "ends_and_sure"),
         "attractor": ("analysis", "attractor"),
         "one": ("analysis", "_one"),
         "order": ("quotient_order", "order_of"),
         "prob1a_first": ("analysis", "prob1a_first"),
         "prob1e_first": ("analysis", "prob1e_first"),
         "numba_load": ("util.numba_narrow", "import_numba"),
         "walks_loaded": ("analysis", "load_walks")}
"""Each part: the module (of ``mitld_lp.solvers``, or the package path below ``mitld_lp`` where
it has a dot) whose name the analysis calls it by."""
OUTER = ("levels", "quotient_levels", "end_components", "ends_and_sure", "attractor", "order",
         "prob1a_first",
         "prob1e_first", "numba_load", "walks_loaded")
"""The parts called by ``analyse`` itself (``one`` calls ``attractor`` on a maximum;
``rest`` is ``analyse`` less these and ``one``'s own time)."""
COLUMNS = ("instance", "value", "numba_before", "analyse", *PARTS, "rest", "numba_import",
           "walks_load", "first_compiled", "compiled")
FIRST = ("instance", "value", "analyse", *PARTS, "rest")
"""The first call's columns (the route's own, in ``synthesize``: numba's import and the
kernels' loads from the disk cache inside where the analysis makes them)."""


def _median(xs: list[float]) -> float:
    s = sorted(xs)
    return s[len(s) // 2] if len(s) % 2 else 0.5 * (s[len(s) // 2 - 1] + s[len(s) // 2])


def child(job: dict[str, Any]) -> dict[str, Any]:
    """One instance's parts (module docs), in this process."""
    import importlib

    import bench_sweeps as bs

    from mitld_lp import load_model, synthesize
    from mitld_lp.solvers import analysis
    from mitld_lp.util import kernel_loader

    if job.get("case") == "sensed":  # bench_qvbs.py's sensed case
        import bench_sensed

        model = bench_sensed.case_model(job["index"], job["quick"])
    else:
        model = load_model(job["model"], max_states=job["max_states"])
    bs.preload()
    inner = analysis.analyse
    kept: dict[str, Any] = {}

    def spy(*args: Any, **kwargs: Any) -> Any:
        kept.update(args=args, kwargs=kwargs)
        return inner(*args, **kwargs)

    spent: dict[str, float] = {}

    def timed(name: str, f: Any) -> Any:
        def call(*args: Any, **kwargs: Any) -> Any:
            c = time.process_time()
            try:
                return f(*args, **kwargs)
            finally:
                spent[name] = spent.get(name, 0.0) + time.process_time() - c
        return call

    originals = []
    for name, (module, attr) in PARTS.items():
        mod = importlib.import_module(f"mitld_lp.{module}" if "." in module
                                      else f"mitld_lp.solvers.{module}")
        if not hasattr(mod, attr):  # an older checkout first on PYTHONPATH: the part is 0
            continue
        originals.append((mod, attr, getattr(mod, attr)))
        setattr(mod, attr, timed(name, getattr(mod, attr)))
    analysis.analyse = timed("analyse", spy)
    try:  # the first call, in the route's solve: what bench_qvbs's analysis_cpu counts
        result = synthesize(model)
    finally:
        analysis.analyse = inner
    first_call = dict(spent, rest=spent.get("analyse", 0.0) - _inside(spent, kept))
    spent.clear()
    numba_before = "numba" in sys.modules

    def run() -> float:
        c = time.process_time()
        inner(*kept["args"], **kept["kwargs"])
        return time.process_time() - c

    def parts(reps: int) -> dict[str, float]:
        rows: list[dict[str, float]] = []
        for _ in range(reps):
            spent.clear()
            whole = run()
            rows.append(dict(spent, analyse=whole, rest=whole - _inside(spent, kept)))
        return {k: _median([r.get(k, 0.0) for r in rows]) for k in (*PARTS, "analyse", "rest")}

    from mitld_lp.solvers import walks
    gate = walks.compiled_walks
    try:
        run()
        out = parts(job["reps"])
        c = time.process_time()
        kernel_loader.prepare()
        loaded = time.process_time()
        walks.load_walks()
        walks_loaded = time.process_time()
        # every walk compiled, whatever the graph's size (the gate forced on)
        for mod in _callers():
            mod.compiled_walks = lambda entries: walks.load_walks()
        first = run()
        forced = parts(job["reps"])
    finally:
        for mod, attr, f in originals:
            setattr(mod, attr, f)
        for mod in _callers():
            mod.compiled_walks = gate
    return dict(out, value=result.lower, numba_before=numba_before, first_call=first_call,
                numba_import=loaded - c, walks_load=walks_loaded - loaded,
                first_compiled=first, compiled=forced["analyse"], forced=forced)


def _callers() -> list[Any]:
    """The modules that ask :func:`mitld_lp.solvers.walks.compiled_walks` by that name."""
    import importlib

    return [importlib.import_module(f"mitld_lp.solvers.{m}")
            for m in ("analysis", "graph", "end_components", "reach")]


def _inside(spent: dict[str, float], kept: dict[str, Any]) -> float:
    """The time of the parts :func:`analyse` calls itself (``one``'s own on a maximum:
    its attractor is counted once)."""
    return sum(spent.get(k, 0.0) for k in OUTER) + spent.get("one", 0.0) - (
        spent.get("attractor", 0.0) if str(kept["kwargs"].get("sense")) == "max" else 0.0)


def _answer(work: Path) -> int:
    job = json.loads((work / "job.json").read_text(encoding="utf-8"))
    (work / "out.json").write_text(json.dumps(child(job)), encoding="utf-8")
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = _common.parser(__doc__.splitlines()[0])
    ap.add_argument("--qvbs", type=Path, default=None,
                    help="a checkout's benchmarks/ folder of ahartmanns/qcomp")
    ap.add_argument("--only", nargs="*", default=None, metavar="NAME")
    ap.add_argument("--min-states", type=int, default=bq.MIN_STATES,
                    help="the least QVBS size of an instance (default: the benchmark's)")
    ap.add_argument("--reps", type=int, default=5, help="timed analyses an instance")
    ap.add_argument("--sensed", action="store_true",
                    help="also bench_qvbs.py's sensed case (--quick: its smallest)")
    ap.add_argument("--child", default=None, help=ps.argparse_hidden())
    args = ap.parse_args(argv)
    if args.child:  # one instance, in this process: its job and answer in that folder
        return _answer(Path(args.child))
    if args.qvbs is None:
        ap.error("--qvbs is required (a checkout's benchmarks/ folder)")
    out = _common.out_dir(args)
    reps = 2 if args.quick else args.reps
    rows, firsts, forced = [], [], []
    with tempfile.TemporaryDirectory(prefix="analysis_parts_") as tmp:
        work = Path(tmp)
        for inst, job in [*ps.chosen_jobs(args.qvbs, args.quick,
                                          set(args.only or ps.INSTANCES), work,
                                          args.min_states),
                          *(bq.case_jobs(["sensed"], args.quick, work) if args.sensed else [])]:
            (work / "job.json").write_text(json.dumps(dict(job, reps=reps)), encoding="utf-8")
            proc = subprocess.run([sys.executable, __file__, "--child", str(work)],
                                  capture_output=True, text=True, timeout=bq.BUDGET)
            if proc.returncode != 0:
                print(inst.name, "error:", proc.stderr.strip().splitlines()[-1:], flush=True)
                continue
            got = json.loads((work / "out.json").read_text(encoding="utf-8"))
            rows.append([inst.name, f"{got['value']:.6g}", got["numba_before"],
                         *(round(got[k], 4) for k in COLUMNS[3:])])
            firsts.append([inst.name, f"{got['value']:.6g}",
                           *(round(got["first_call"].get(k, 0.0), 4) for k in FIRST[2:])])
            print(_common.text_table(COLUMNS, rows[-1:]), flush=True)
            print(_common.text_table(FIRST, firsts[-1:]), flush=True)
            forced.append([inst.name, f"{got['value']:.6g}",
                           *(round(got["forced"].get(k, 0.0), 4) for k in FIRST[2:])])
            print(_common.text_table(FIRST, forced[-1:]), flush=True)
    text = ("## The graph analysis part by part, and compiled (CPU seconds, medians)\n\n"
            + _common.markdown_table(COLUMNS, rows)
            + f"\n\n{reps} timed analyses an instance after one untimed, in one process; "
              "the compiled ones after numba's import and the walks' load in the same "
              "process.\n\n"
              "## The first analysis of each process, part by part (CPU seconds)\n\n"
            + _common.markdown_table(FIRST, firsts)
            + "\n\nThe route's own call (what bench_qvbs.py's analysis_cpu counts): "
              "numba's import (numba_load) and each kernel's load from the disk cache "
              "inside the parts that make them.\n\n"
              "## Every walk compiled, part by part (CPU seconds, medians)\n\n"
            + _common.markdown_table(FIRST, forced)
            + "\n\nThe gate of the compiled walks forced on whatever the graph's size, "
              "after the kernel loader's load (numba_import: its pieces, or numba's "
              "import where they cannot be set up) and the walks' module.\n")
    _common.write_text(out / "analysis_parts.md", text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
