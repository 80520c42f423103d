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
figures as shares.  ``--timed K`` solves more, unprofiled, between the first and the
profiled ones: their median and least CPU, a warm solve's time.  ``--compare DIR``: each
instance also with the package of the checkout ``DIR`` (a base), the two children
alternated ``--rounds`` times (the base's first), both lists printed.

::

    python experiments/solve_calls.py --qvbs <QVBS> --only firewire_dl.3-600.deadline \\
        zeroconf_dl.1000-1-false-30.deadline_max csma.4-2.some_before
    python experiments/solve_calls.py --qvbs <QVBS> --quick   # firewire_dl, one solve
    python experiments/solve_calls.py --qvbs <QVBS> --only csma.4-2.some_before \
        --compare <base> --timed 10 --rounds 3

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
    timed = [synthesize(model).solve_cpu for _ in range(job.get("timed", 0))]
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
    return dict(first_solve_cpu=first.solve_cpu, solve_cpu=r.solve_cpu, timed=timed,
                bracket=[r.lower, r.upper], rows=rows)


def _answer(work: Path) -> None:
    job = json.loads((work / "job.json").read_text(encoding="utf-8"))
    (work / "out.json").write_text(json.dumps(child(job)), encoding="utf-8")


def _run(qvbs: Path, work: Path, root: Path) -> dict[str, Any]:
    """One child on the job in ``work`` with the package of the checkout ``root``."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(root), *filter(None, [os.environ.get("PYTHONPATH")])]))
    subprocess.run([sys.executable, __file__, "--qvbs", str(qvbs), "--child", str(work)],
                   check=True, env=env)
    return json.loads((work / "out.json").read_text(encoding="utf-8"))


def _listed(title: str, got: dict[str, Any]) -> list[str]:
    """A child's answer as markdown lines: the bracket, the solves' CPU, the calls."""
    lo, hi = got["bracket"]
    timed = sorted(got.get("timed") or [])
    warm = (f"; {len(timed)} warm solves unprofiled: median {timed[len(timed) // 2]:.4f} s, "
            f"least {timed[0]:.4f} s" if timed else "")
    out = [f"### {title}: [{lo!r}, {hi!r}]", "",
           f"first solve {got['first_solve_cpu']:.4f} s unprofiled{warm}; a profiled "
           f"solve {got['solve_cpu']:.4f} s", "", "```text",
           "   cum ms   own ms  calls  function"]
    out += [f"{c:9.2f} {o:8.2f} {n:6.0f}  {f}" for c, o, n, f in got["rows"]]
    return [*out, "```", ""]


def _summary(runs: list[tuple[str, str, dict[str, Any]]]) -> list[str]:
    """Each instance's and tree's solves in one table: the first solve's CPU and the
    warm solves' median (``--timed``) of each round, the bracket."""
    out = ["### Summary (CPU s a solve; each round's figure, in run order)", "",
           "| instance | tree | bracket | first solve | warm median |", "|---|---|---|---|---|"]
    for name in dict.fromkeys(n for n, _, _ in runs):
        for label in dict.fromkeys(t for n, t, _ in runs if n == name):
            mine = [g for n, t, g in runs if n == name and t == label]
            warm = [sorted(g["timed"])[len(g["timed"]) // 2] for g in mine if g.get("timed")]
            out.append(f"| {name} | {label} | {mine[0]['bracket']} | "
                       + ", ".join(f"{g['first_solve_cpu']:.4f}" for g in mine) + " | "
                       + (", ".join(f"{w:.4f}" for w in warm) or "-") + " |")
    return [*out, ""]


def main(argv: list[str] | None = None) -> None:
    import bench_qvbs as bq

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--qvbs", type=Path, required=True)
    ap.add_argument("--only", nargs="*", default=[QUICK], metavar="NAME")
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--min-ms", type=float, default=1.0)
    ap.add_argument("--quick", action="store_true", help=f"{QUICK}, one profiled solve")
    ap.add_argument("--timed", type=int, default=0, metavar="K",
                    help="K unprofiled warm solves before the profiled ones (their CPU)")
    ap.add_argument("--compare", type=Path, default=None, metavar="DIR",
                    help="also each instance with the checkout DIR's package, alternated")
    ap.add_argument("--rounds", type=int, default=1,
                    help="with --compare: the two children alternated this many times")
    ap.add_argument("--out", type=Path, default=HERE / "out")
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child is not None:  # the child's side: its job read, its answer written
        _answer(Path(args.child))
        return
    names = [QUICK] if args.quick else args.only
    reps = 1 if args.quick else args.reps
    lines = ["## The package's calls over a millisecond in a warm solve (CPU ms a solve)", ""]
    runs: list[tuple[str, str, dict[str, Any]]] = []
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        found, _ = bq.jobs(args.qvbs, 0, bq.MAX_STATES, bq.FAMILIES, work)
        jobs = {inst.name: job for inst, job in found}
        for name in names:
            if name not in jobs:
                raise SystemExit(f"--only: {name} is not a QVBS instance posed here")
            job = dict(jobs[name], reps=reps, min_ms=args.min_ms, timed=args.timed)
            (work / "job.json").write_text(json.dumps(job), encoding="utf-8")
            trees = [("base", args.compare), ("this", HERE.parent)] if args.compare \
                else [("this", HERE.parent)]
            for k in range(args.rounds if args.compare else 1):
                for label, root in trees:
                    got = _run(args.qvbs, work, root)
                    lines += _listed(f"{name} ({label}, round {k + 1})", got)
                    runs.append((name, label, got))
    lines += _summary(runs)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "solve_calls.md").write_text("\n".join(lines), encoding="utf-8")
    print("\n".join(lines))
    print(f"written: {args.out / 'solve_calls.md'}")


if __name__ == "__main__":
    main()
