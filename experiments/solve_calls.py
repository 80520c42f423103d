"""Profile: every call of the package's code over a millisecond in a QVBS instance's solve.

Per instance (posed as ``bench_qvbs.py`` poses it), in a child process of its own: the
model loaded, the solver modules imported (``bench_sweeps.preload``), one synthesis
unprofiled (the first solve of the process: it pays the kernels' links and the lazy
imports, and its ``solve_cpu`` is printed apart), then ``--reps`` more under
``cProfile`` with the process's CPU clock, and each of the package's functions whose
cumulative CPU a solve is at least ``--min-ms`` listed (cumulative and own ms a solve,
calls a solve), the bracket beside.  What the list shows is a warm solve's per-call
costs; the first solve's extra over it is the process's fixed costs (links, imports).
cProfile adds its own cost to every Python call (about 1.3x on these solves): read the
figures as shares, and time a change with ``bench_qvbs.py --compare``.

::

    python experiments/solve_calls.py --qvbs <QVBS> --only firewire_dl.3-600.deadline \\
        zeroconf_dl.1000-1-false-30.deadline_max csma.4-2.some_before
    python experiments/solve_calls.py --qvbs <QVBS> --quick   # firewire_dl, one solve

Written: ``solve_calls.md`` in ``--out`` (default: ``experiments/out``, a scratch folder).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

QUICK = "firewire_dl.3-600.deadline"


def child(job: dict[str, Any]) -> dict[str, Any]:
    """The first solve's CPU, then ``reps`` solves profiled: the package's calls."""
    import cProfile
    import pstats
    import time

    import bench_sweeps as bs

    from mitld_lp import load_model, synthesize

    model = load_model(job["model"], max_states=job["max_states"])
    bs.preload()
    first = synthesize(model)
    prof = cProfile.Profile(time.process_time)
    reps = job["reps"]
    for _ in range(reps):
        prof.enable()
        r = synthesize(model)
        prof.disable()
    stats = pstats.Stats(prof).stats  # type: ignore[attr-defined]
    rows = []
    for (path, line, name), (_, calls, own, cum, _) in stats.items():
        if "mitld_lp" in path and cum / reps * 1000 >= job["min_ms"]:
            where = path.split("mitld_lp/")[-1]
            rows.append((cum / reps * 1000, own / reps * 1000, calls / reps,
                         f"{where}:{line}({name})"))
    rows.sort(reverse=True)
    return dict(first_solve_cpu=first.solve_cpu, solve_cpu=r.solve_cpu,
                bracket=[r.lower, r.upper], rows=rows)


def _answer(work: Path) -> None:
    job = json.loads((work / "job.json").read_text(encoding="utf-8"))
    (work / "out.json").write_text(json.dumps(child(job)), encoding="utf-8")


def main(argv: list[str] | None = None) -> None:
    import bench_qvbs as bq

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--qvbs", type=Path, required=True)
    ap.add_argument("--only", nargs="*", default=[QUICK], metavar="NAME")
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--min-ms", type=float, default=1.0)
    ap.add_argument("--quick", action="store_true", help=f"{QUICK}, one profiled solve")
    ap.add_argument("--out", type=Path, default=HERE / "out")
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child is not None:  # the child's side: its job read, its answer written
        _answer(Path(args.child))
        return
    names = [QUICK] if args.quick else args.only
    reps = 1 if args.quick else args.reps
    lines = ["## The package's calls over a millisecond in a warm solve (CPU ms a solve)", ""]
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        found, _ = bq.jobs(args.qvbs, 0, bq.MAX_STATES, bq.FAMILIES, work)
        jobs = {inst.name: job for inst, job in found}
        for name in names:
            if name not in jobs:
                raise SystemExit(f"--only: {name} is not a QVBS instance posed here")
            job = dict(jobs[name], reps=reps, min_ms=args.min_ms)
            (work / "job.json").write_text(json.dumps(job), encoding="utf-8")
            # the child imports this checkout's package, wherever it is run from
            env = dict(os.environ, PYTHONPATH=os.pathsep.join(
                [str(HERE.parent), *filter(None, [os.environ.get("PYTHONPATH")])]))
            subprocess.run([sys.executable, __file__, "--qvbs", str(args.qvbs), "--child",
                            str(work)], check=True, env=env)
            got = json.loads((work / "out.json").read_text(encoding="utf-8"))
            lo, hi = got["bracket"]
            lines += [f"### {name}: [{lo!r}, {hi!r}]", "",
                      f"first solve {got['first_solve_cpu']:.4f} s unprofiled; a profiled "
                      f"solve {got['solve_cpu']:.4f} s", "", "```text",
                      "   cum ms   own ms  calls  function"]
            lines += [f"{c:9.2f} {o:8.2f} {n:6.0f}  {f}" for c, o, n, f in got["rows"]]
            lines += ["```", ""]
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "solve_calls.md").write_text("\n".join(lines), encoding="utf-8")
    print("\n".join(lines))
    print(f"written: {args.out / 'solve_calls.md'}")


if __name__ == "__main__":
    main()
