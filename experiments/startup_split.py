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

Nothing is written: the figures are printed (``--quick`` keeps it so).
"""

from __future__ import annotations

import resource
import sys

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
    if route == "ours":
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
    print(json.dumps(dict(out, split=split)))


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
            if args.importtime:
                done = subprocess.run(
                    [sys.executable, "-X", "importtime", __file__, "--child", "ours",
                     str(work / "job.json"), args.method], capture_output=True,
                    text=True, env=dict(env, PYTHONPATH=str(_common.ROOT)),
                    cwd=str(_common.ROOT), check=True)
                print("  ours under -X importtime (self us, inflated):")
                print(_importtime(done.stderr))


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
