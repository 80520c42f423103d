"""Solve stage before and after, in turns: two checkouts solve the same QVBS instances.

A change of a few percent of the solve stage is below what one ``bench_qvbs.py --compare``
run resolves on a loaded machine (its before and after run minutes apart, once each).
Here each round runs a process of the ``--compare`` checkout and then one of this
checkout, each posing the instance as ``bench_qvbs.py`` poses it, loading the model once
and calling ``synthesize`` ``--reps`` times.  The script prints each checkout's solve
stage (CPU seconds, ``SynthesisResult.solve_cpu``): the minimum and the median over
every call of every round, and the median of its graph analysis (the calls of
``mitld_lp.solvers.analysis.analyse`` inside it, timed by this script in both
checkouts), and how many states its quotient kept (the first model's).  It prints the
bracket beside them, as the hex of both floats in each checkout, and whether the two
checkouts gave the same bracket to the bit.  Unless ``--no-storm``, Storm's best
sound check of the same product (``bench_qvbs.py``'s route: our DRN export read by
stormpy, each of its sound methods, the cheapest kept) is measured once an instance,
its value beside.

::

    python experiments/solve_alternating.py --qvbs qcomp/benchmarks --compare /tmp/base \\
        --only zeroconf_dl.1000-1-false-30.deadline_max --out experiments/results
    python experiments/solve_alternating.py --qvbs qcomp/benchmarks --compare /tmp/base --quick

Written: ``solve_alternating.md``.
"""

from __future__ import annotations

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

import _common  # noqa: E402
import bench_qvbs as bq  # noqa: E402
import profile_solve as ps  # noqa: E402  (the same instances, posed the same way)

ROOT = HERE.parent
COLUMNS = ("instance", "value", "maybe_before", "maybe_after", "calls", "before_min",
           "before_median", "after_min", "after_median", "after_over_before_median",
           "analysis_before_median",
           "analysis_after_median", "storm_check_cpu", "storm_value", "same_bracket",
           "certified")


def child(job: dict[str, Any], reps: int) -> dict[str, Any]:
    """``reps`` solves of the posed instance in this process (the package on the path)."""
    import time

    import bench_sweeps as bs

    from mitld_lp import load_model, synthesize
    from mitld_lp.solvers import analysis

    model = load_model(job["model"], max_states=job["max_states"])
    bs.preload()
    inner = analysis.analyse
    timed: list[float] = []

    kept: list[int] = []  # the states of the quotient (the first model's)

    def analyse(*args: Any, **kwargs: Any) -> Any:  # the route imports it at each call
        c = time.process_time()
        try:
            got = inner(*args, **kwargs)
        finally:
            timed[-1] += time.process_time() - c
        kept.append(int(got[0].n_states))
        return got

    analysis.analyse = analyse
    spent = []
    for _ in range(reps):
        timed.append(0.0)
        r = synthesize(model)
        spent.append(r.solve_cpu)
    return dict(solve=spent, analysis=timed, lower=r.lower, maybe=kept[-1] if kept else None,
                bracket=[r.lower.hex(), r.upper.hex()], certified=bool(r.certified))


def storm_check(job: dict[str, Any], work: Path) -> dict[str, Any]:
    """Storm's best sound check of the posed product, as ``bench_qvbs.py`` measures it
    (its worker writes our DRN export, then stormpy checks it), or ``{}`` on an error."""
    ours = bq._child("ours", job, work, bq.BUDGET)
    storm = {} if "error" in ours else bq._child("storm_check", job, work, bq.BUDGET)
    (work / "model.drn").unlink(missing_ok=True)
    if not storm or "error" in storm:
        return {}
    return dict(cpu=storm["best_cpu"], value=storm["methods"][storm["best"]]["value"])


def _run(root: Path, job: dict[str, Any], reps: int, work: Path) -> dict[str, Any]:
    (work / "job.json").write_text(json.dumps(dict(job, reps=reps)), encoding="utf-8")
    env = dict(os.environ, PYTHONPATH=str(root))
    proc = subprocess.run([sys.executable, __file__, "--child", str(work)], env=env,
                          capture_output=True, text=True, timeout=bq.BUDGET)
    if proc.returncode != 0:
        raise RuntimeError(f"{root}: {proc.stderr.strip().splitlines()[-1:]}")
    return json.loads((work / "out.json").read_text(encoding="utf-8"))


def _median(xs: list[float]) -> float:
    s = sorted(xs)
    return s[len(s) // 2] if len(s) % 2 else 0.5 * (s[len(s) // 2 - 1] + s[len(s) // 2])


def main(argv: list[str] | None = None) -> int:
    ap = _common.parser(__doc__.splitlines()[0])
    ap.add_argument("--qvbs", type=Path, default=None,
                    help="a checkout's benchmarks/ folder of ahartmanns/qcomp")
    ap.add_argument("--compare", type=Path, default=None,
                    help="the checkout before (its mitld_lp), run in turns with this one")
    ap.add_argument("--only", nargs="*", default=None, metavar="NAME")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--reps", type=int, default=3, help="solves a process")
    ap.add_argument("--no-storm", action="store_true",
                    help="without Storm's best check (two processes an instance fewer)")
    ap.add_argument("--child", default=None, help=ps.argparse_hidden())
    args = ap.parse_args(argv)
    if args.child:
        work = Path(args.child)
        job = json.loads((work / "job.json").read_text(encoding="utf-8"))
        (work / "out.json").write_text(json.dumps(child(job, job["reps"])), encoding="utf-8")
        return 0
    if args.qvbs is None or args.compare is None:
        ap.error("--qvbs and --compare are required")
    rounds, reps = (1, 1) if args.quick else (args.rounds, args.reps)
    out = _common.out_dir(args)
    rows = []
    with tempfile.TemporaryDirectory(prefix="solve_alternating_") as tmp:
        work = Path(tmp)
        for inst, job in ps.chosen_jobs(args.qvbs, args.quick,
                                        set(args.only or ps.INSTANCES), work):
            spent: dict[str, list[float]] = {"before": [], "after": []}
            stage: dict[str, list[float]] = {"before": [], "after": []}
            seen: dict[str, Any] = {}
            for _ in range(rounds):
                for side, root in (("before", args.compare), ("after", ROOT)):
                    got = _run(Path(root).resolve(), job, reps, work)
                    spent[side] += got["solve"]
                    stage[side] += got.get("analysis", [])
                    seen[side] = got
            b, a = _median(spent["before"]), _median(spent["after"])
            storm = {} if args.no_storm else storm_check(job, work)
            rows.append([inst.name, repr(seen["after"]["lower"]), seen["before"].get("maybe"),
                         seen["after"].get("maybe"), len(spent["after"]),
                         round(min(spent["before"]), 4), round(b, 4),
                         round(min(spent["after"]), 4), round(a, 4), round(a / b, 3),
                         *(round(_median(stage[k]), 4) if stage[k] else None
                           for k in ("before", "after")),
                         round(storm["cpu"], 4) if storm else None,
                         f"{storm['value']:.4g}" if storm else None,
                         seen["before"]["bracket"] == seen["after"]["bracket"],
                         seen["before"]["certified"] and seen["after"]["certified"]])
            print(_common.text_table(COLUMNS, rows[-1:]), "bracket (hex) before:",
                  seen["before"]["bracket"], "after:", seen["after"]["bracket"], flush=True)
    text = ("## The solve stage before and after, in turns (CPU seconds)\n\n"
            + _common.markdown_table(COLUMNS, rows)
            + f"\n\n{rounds} rounds, each a process of the checkout before then one of this "
              f"checkout, {reps} solves a process.\n")
    _common.write_text(out / "solve_alternating.md", text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
