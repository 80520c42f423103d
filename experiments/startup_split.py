"""Where a PRISM route's process spends its CPU outside the load and the synthesis.

For each QVBS instance chosen (posed as ``bench_qvbs.py`` poses it), one child process per
route, each phase's CPU seconds (user + system, ``getrusage``) in the order it runs:

* ``ours`` (``bench_qvbs.py``'s worker, default start: a program importing the package):
  ``interpreter`` (Python's start and ``site``, up to this script's first line), ``harness``
  (the benchmark's own imports, ``bench_sweeps``: paid alike by Storm's worker),
  ``numpy``, ``package`` (``from mitld_lp import load_model, synthesize``), ``load``
  (``load_model``: Storm's exploration with its imports, stormpy among them),
  ``preload`` (``bench_sweeps.preload()``: the solver modules and csgraph, so that the
  solve is timed without them), ``synthesis``; ``outside`` is every phase but the load
  and the synthesis (``process_cpu - whole_cpu`` in ``bench_qvbs.csv``);
* ``storm`` (``bench_qvbs.py``'s ``storm_prism`` worker, a stormpy script):
  ``interpreter``, ``harness``, ``stormpy`` (its import), ``build`` (parse and build),
  ``check`` (the sound method given by ``--method``); ``outside`` is the first three.

Each child runs ``--repeats`` times (the routes taking turns) and the median of each
phase is printed, with the answer beside it; the first round is left out when there are
two or more (it compiles numba kernels and warms the file cache).  ``--importtime``
also runs ``ours`` once under ``python -X importtime`` and prints the modules whose own
import time (self, microseconds, inflated by the measurement) is largest, and what each
top-level package sums to.  ``--modules`` prints the third-party modules ``ours`` left
imported (NumPy's, SciPy's, lark's, ...) at the end.

    python experiments/startup_split.py --qvbs /work/shared/qvbs --only consensus.4-4.c2 \\
        csma.4-2.some_before --importtime
    python experiments/startup_split.py --qvbs /work/shared/qvbs --quick  # one instance
    python experiments/startup_split.py --qvbs /work/shared/qvbs --compare ../base  # before too

``--parts`` runs ``ours`` (and ``base``) a further ``--repeats`` times with three meters
in the process (module :func:`_meters`): each import's own CPU (``time.process_time``
around the import system's ``_load_unlocked``, its nested imports taken out), the cyclic
collector's passes (``gc.callbacks``, thread CPU) and the compiled kernels' loads
(``kernel_loader._load``), and prints one table: each component's CPU seconds and share
of the process up to the end of the synthesis (``process_cpu``), Storm's whole run
beside it.  The meters cost a few ms of their own (in ``rest``).

Nothing is written: the figures are printed (``--quick`` keeps it so).
"""

from __future__ import annotations

import resource
import sys
from typing import Any

_T0 = resource.getrusage(resource.RUSAGE_SELF)


def _cpu() -> float:
    own, ended = (resource.getrusage(w) for w in (resource.RUSAGE_SELF,
                                                   resource.RUSAGE_CHILDREN))
    return own.ru_utime + own.ru_stime + ended.ru_utime + ended.ru_stime


def child(route: str, job_file: str, method: str) -> None:
    """One route's phases, printed as one JSON line."""
    phases = [("interpreter", _T0.ru_utime + _T0.ru_stime)]
    import json
    from pathlib import Path

    here = Path(__file__).resolve().parent
    sys.path.insert(0, str(here))
    import bench_qvbs
    import bench_sweeps as bs

    phases.append(("harness", _cpu()))
    job = json.loads(Path(job_file).read_text(encoding="utf-8"))
    out: dict = {}
    meters = _meters(phases) if route == "parts" else None
    if route in ("ours", "parts"):
        import numpy  # noqa: F401

        phases.append(("numpy", _cpu()))
        from mitld_lp import load_model, synthesize

        phases.append(("package", _cpu()))
        model = load_model(job["model"], max_states=job["max_states"])
        phases.append(("load", _cpu()))
        bs.preload()
        phases.append(("preload", _cpu()))
        r = synthesize(model)
        phases.append(("synthesis", _cpu()))
        out["answer"] = [r.lower, r.upper]
        out["solve"] = r.solve_cpu
        third = sorted(m for m in sys.modules if m.split(".")[0] in
                       ("numpy", "scipy", "lark", "regex", "cvxpy", "pandas", "numba",
                        "llvmlite", "clarabel", "highspy"))
        out["modules"] = third
    else:
        import stormpy

        phases.append(("stormpy", _cpu()))
        job = dict(job, best=method)
        c = _cpu()
        got = bench_qvbs.work_storm_prism(job, Path(job_file).parent)
        build = got["build_cpu"]
        phases.append(("build", c + build))
        phases.append(("check", _cpu()))
        out["answer"] = [got["value"], got["value"]]
        del stormpy
    split, before = {}, 0.0
    for name, at in phases:
        split[name] = at - before
        before = at
    if meters is not None:
        out["meters"] = meters()
    print(json.dumps(dict(out, split=split)))


#: Top-level packages whose imports the parts table names apart (the rest: ``other``).
NAMED = ("numpy", "scipy", "lark", "stormpy", "numba", "llvmlite", "mitld_lp")


def _meters(phases: list) -> Any:
    """Install the three meters (module docs, ``--parts``); the function returning, per
    phase of ``phases`` (filled meanwhile), the CPU of imports by top-level package, of
    the collector and of kernel loads."""
    import _frozen_importlib as boot
    import gc
    import time

    clock, thread = time.process_time, time.thread_time
    events: list[tuple[float, str, float]] = []  # (process CPU at the end, kind, seconds)
    stack: list[float] = []
    load_unlocked = boot._load_unlocked

    def timed_load(spec: Any) -> Any:
        stack.append(0.0)
        t = clock()
        try:
            return load_unlocked(spec)
        finally:
            spent = clock() - t
            nested = stack.pop()
            if stack:
                stack[-1] += spent
            top = spec.name.partition(".")[0]
            events.append((_cpu(), "import " + (top if top in NAMED else "other"),
                           spent - nested))

    boot._load_unlocked = timed_load
    started = [0.0]

    def collected(phase: str, info: dict) -> None:
        if phase == "start":
            started[0] = thread()
        else:
            spent = thread() - started[0]
            if stack:  # inside an import: the pass is the collector's, not the import's
                stack[-1] += spent
            events.append((_cpu(), f"gc {info['generation']}", spent))

    gc.callbacks.append(collected)
    wrapped: list = []

    def kernels_timed() -> None:  # once the loader is imported (by the package)
        kernel_loader = sys.modules.get("mitld_lp.util.kernel_loader")
        if wrapped or not hasattr(kernel_loader, "_load"):  # (not imported, or half)
            return
        inner = kernel_loader._load

        def timed(*args: Any) -> Any:
            t = clock()
            try:
                return inner(*args)
            finally:
                events.append((_cpu(), "kernel loads", clock() - t))

        kernel_loader._load = timed
        wrapped.append(inner)

    def report() -> dict:
        boot._load_unlocked = load_unlocked
        gc.callbacks.remove(collected)
        per: dict[str, dict[str, float]] = {name: {} for name, _ in phases}
        for at, kind, spent in events:
            name = next((n for n, end in phases if at <= end + 1e-9), phases[-1][0])
            per[name][kind] = per[name].get(kind, 0.0) + spent
        return per

    sys.meta_path.insert(0, _Watch(kernels_timed))
    return report


class _Watch:
    """A finder finding nothing: after each import is looked for, ``then`` runs."""

    def __init__(self, then: Any) -> None:
        self.then = then

    def find_spec(self, name: str, path: Any = None, target: Any = None) -> None:
        self.then()
        return None


def main() -> None:
    import json
    import os
    import statistics
    import subprocess
    import tempfile
    from pathlib import Path

    import _common

    p = _common.parser(__doc__.splitlines()[0])
    p.add_argument("--qvbs", type=Path, required=True, help="QVBS benchmarks/ folder")
    p.add_argument("--only", nargs="*", default=None, help="instances by name")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--method", default="OPTIMISTIC_VALUE_ITERATION",
                   help="Storm's sound method for its check")
    p.add_argument("--importtime", action="store_true")
    p.add_argument("--modules", action="store_true")
    p.add_argument("--parts", action="store_true",
                   help="one table of the process's components (module docs)")
    p.add_argument("--compare", type=Path, default=None,
                   help="another checkout: its mitld_lp as the route 'base' (ours' phases)")
    args = p.parse_args()
    import bench_qvbs

    names = args.only or (["consensus.4-4.c2"] if args.quick else
                          ["consensus.4-4.c2", "csma.4-2.some_before"])
    repeats = 1 if args.quick else args.repeats
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    with tempfile.TemporaryDirectory() as tmp:
        found, _ = bench_qvbs.jobs(args.qvbs, 0, bench_qvbs.MAX_STATES, bench_qvbs.FAMILIES,
                                   Path(tmp))
        for inst, job in found:
            if inst.name not in names:
                continue
            work = Path(tmp) / inst.name
            work.mkdir()
            (work / "job.json").write_text(json.dumps(job), encoding="utf-8")
            runs: dict[str, list[dict]] = {"ours": [], "storm": []}
            if args.compare is not None:
                runs = {"base": [], **runs}
            for _ in range(repeats):
                for route in runs:
                    code = args.compare if route == "base" else _common.ROOT
                    with_code = dict(env, PYTHONPATH=os.pathsep.join(
                        [str(code), *filter(None, [os.environ.get("PYTHONPATH")])]))
                    done = subprocess.run(
                        [sys.executable, __file__, "--child",
                         "ours" if route == "base" else route, str(work / "job.json"),
                         args.method], capture_output=True, text=True, env=with_code,
                        cwd=str(code), check=True)
                    runs[route].append(json.loads(done.stdout.strip().splitlines()[-1]))
            print(f"\n{inst.name}")
            for route, got in runs.items():
                kept = got[1:] if len(got) > 1 else got
                split = {k: statistics.median(g["split"][k] for g in kept)
                         for k in kept[0]["split"]}
                inside = {"load", "synthesis", "build", "check"}
                outside = sum(v for k, v in split.items() if k not in inside)
                text = "  ".join(f"{k} {v:.3f}" for k, v in split.items())
                print(f"  {route:5s} {text}  | outside {outside:.3f}  total "
                      f"{sum(split.values()):.3f}  answer {kept[-1]['answer']}")
                if args.modules and route != "storm":
                    tops: dict[str, int] = {}
                    for m in kept[-1]["modules"]:
                        tops[m.split(".")[0]] = tops.get(m.split(".")[0], 0) + 1
                    print(f"  ours' third-party modules: {tops}")
            if args.parts:
                _parts_table(args, work, env, runs.get("storm", []), repeats)
            if args.importtime:
                done = subprocess.run(
                    [sys.executable, "-X", "importtime", __file__, "--child", "ours",
                     str(work / "job.json"), args.method], capture_output=True,
                    text=True, env=dict(env, PYTHONPATH=str(_common.ROOT)),
                    cwd=str(_common.ROOT), check=True)
                print("  ours under -X importtime (self us, inflated):")
                print(_importtime(done.stderr))


def _parts_table(args: Any, work: Any, env: dict, storm: list, repeats: int) -> None:
    """``--parts``: the metered children's medians as one table per route (module docs)."""
    import json
    import os
    import statistics
    import subprocess

    import _common

    routes = {"ours": _common.ROOT}
    if args.compare is not None:
        routes = {"base": args.compare, **routes}
    storm_total = (statistics.median(sum(g["split"].values()) for g in storm[1:] or storm)
                   if storm else None)
    for route, code in routes.items():
        got = []
        for _ in range(repeats):
            done = subprocess.run(
                [sys.executable, __file__, "--child", "parts", str(work / "job.json"),
                 args.method], capture_output=True, text=True, cwd=str(code),
                env=dict(env, PYTHONPATH=os.pathsep.join(
                    [str(code), *filter(None, [os.environ.get("PYTHONPATH")])])), check=True)
            got.append(json.loads(done.stdout.strip().splitlines()[-1]))
        kept = got[1:] if len(got) > 1 else got
        rows: dict[str, list[float]] = {}
        for g in kept:
            one: dict[str, float] = {}
            for phase, spent in g["split"].items():
                metered = g["meters"].get(phase, {})
                if phase == "synthesis":  # its solve stage, the rest its product and more
                    one["synthesis: solve stage"] = g["solve"]
                    spent -= g["solve"]
                for kind, t in metered.items():
                    one[f"{phase}: {kind}"] = one.get(f"{phase}: {kind}", 0.0) + t
                    spent -= t
                one[f"{phase}: rest"] = spent
            for k, v in one.items():
                rows.setdefault(k, []).append(v)
        total = statistics.median(sum(g["split"].values()) for g in kept)
        table = [(k, f"{statistics.median(v):.4f}",
                  f"{100 * statistics.median(v) / total:.1f}%") for k, v in rows.items()
                 if statistics.median(v) >= 0.0005]
        table.append(("process (to the synthesis's end)", f"{total:.4f}", "100%"))
        if storm_total is not None:
            table.append(("Storm's whole run", f"{storm_total:.4f}",
                          f"{100 * storm_total / total:.0f}% of ours"))
        print(f"  {route}: components, CPU s (median of {len(kept)}), answer "
              f"{kept[-1]['answer']}")
        print(_common.markdown_table(("component", "CPU s", "share"), table))


def _importtime(text: str, top: int = 15) -> str:
    """The modules of largest own import time, and the sums per top-level package."""
    import re

    rows = []
    for line in text.splitlines():
        m = re.match(r"import time:\s+(\d+) \|\s+(\d+) \|( *)(\S.*)", line)
        if m:
            rows.append((int(m[1]), m[4].strip()))
    sums: dict[str, int] = {}
    for own, name in rows:
        sums[name.split(".")[0]] = sums.get(name.split(".")[0], 0) + own
    lines = ["    by package: " + ", ".join(
        f"{k} {v / 1e3:.0f} ms" for k, v in sorted(sums.items(), key=lambda kv: -kv[1])[:10])]
    lines += [f"    {own / 1e3:6.1f} ms  {name}" for own, name in sorted(rows)[::-1][:top]]
    return "\n".join(lines)


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        child(*sys.argv[2:5])
    else:
        main()
