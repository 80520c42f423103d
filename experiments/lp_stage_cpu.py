"""The LP stage's and the certificate's CPU a warm solve, with hashes of the LP's policy
and values and of the bracket, on QVBS instances, a checkout against another.

Per instance and tree, a child process (the instance posed as ``bench_qvbs.py`` poses
it, the solver modules imported first, ``bench_sweeps.preload``): one synthesis
unprofiled (its LP policy and held values hashed, SHA-256 of their bytes and dtypes,
and the bracket's), then ``--reps`` more, each timed by the process clock in place:
the whole solve (``solve_cpu``), the plain route's LP stage (``routes.plain._solve_lp``)
and its certificates (``routes.plain._certified``); their medians and least printed.
``--compare DIR``: the checkout ``DIR``'s package too, the two children alternated
``--rounds`` times (the base's first)::

    python experiments/lp_stage_cpu.py --qvbs <QVBS> --only zeroconf.1000-4-false.correct_max \\
        csma.4-2.some_before --compare <base> --rounds 2 --reps 7
    python experiments/lp_stage_cpu.py --qvbs <QVBS> --quick   # firewire_dl, 2 solves

Written: ``lp_stage_cpu.md`` in ``--out`` (default ``experiments/out``, a scratch folder).
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


def _digest(*arrays: Any) -> str:
    import hashlib

    import numpy as np

    h = hashlib.sha256()
    for a in arrays:
        if a is None:
            h.update(b"none")
            continue
        a = np.ascontiguousarray(np.asarray(a.lift() if hasattr(a, "lift") else a))
        h.update(str(a.dtype).encode())
        h.update(a.tobytes())
    return h.hexdigest()[:16]


def child(job: dict[str, Any]) -> dict[str, Any]:
    """One synthesis hashed, then ``reps`` timed: the solve, the LP stage, the
    certificates."""
    import time

    import bench_sweeps as bs

    import mitld_lp.routes.plain as plain
    from mitld_lp import load_model, synthesize

    model = load_model(job["model"], max_states=job["max_states"])
    bs.preload()
    spent: dict[str, float] = {"lp": 0.0, "cert": 0.0}
    lps: list[Any] = []

    def timed(part: str, f: Any) -> Any:
        def run(*a: Any, **k: Any) -> Any:
            t = time.process_time()
            r = f(*a, **k)
            spent[part] += time.process_time() - t
            if part == "lp":
                lps.append(r)
            return r
        return run

    plain._solve_lp = timed("lp", plain._solve_lp)
    plain._certified = timed("cert", plain._certified)
    first = synthesize(model)
    lp = lps[-1]
    hashes = dict(lp=_digest(None if lp is None else lp.policy,
                             None if lp is None else lp.held_values),
                  bracket=_digest([first.lower, first.upper]))
    rows = []
    for _ in range(job["reps"]):
        spent.update(lp=0.0, cert=0.0)
        r = synthesize(model)
        rows.append((r.solve_cpu, spent["lp"], spent["cert"]))
    return dict(bracket=[first.lower, first.upper], hashes=hashes, rows=rows)


def _run(qvbs: Path, work: Path, root: Path) -> dict[str, Any]:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(root), *filter(None, [os.environ.get("PYTHONPATH")])]))
    subprocess.run([sys.executable, __file__, "--qvbs", str(qvbs), "--child", str(work)],
                   check=True, env=env)
    return json.loads((work / "out.json").read_text(encoding="utf-8"))


def _line(name: str, label: str, got: dict[str, Any]) -> str:
    cols = list(zip(*got["rows"], strict=True))

    def med(k: int) -> str:
        v = sorted(cols[k])
        return f"{v[len(v) // 2] * 1e3:.1f} / {v[0] * 1e3:.1f}"

    return (f"| {name} | {label} | {med(0)} | {med(1)} | {med(2)} | "
            f"{got['hashes']['lp']} | {got['hashes']['bracket']} | {got['bracket']} |")


def main(argv: list[str] | None = None) -> None:
    import bench_qvbs as bq

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--qvbs", type=Path, required=True)
    ap.add_argument("--only", nargs="*", default=[QUICK], metavar="NAME")
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--quick", action="store_true", help=f"{QUICK}, two timed solves")
    ap.add_argument("--compare", type=Path, default=None, metavar="DIR")
    ap.add_argument("--rounds", type=int, default=1)
    ap.add_argument("--out", type=Path, default=HERE / "out")
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child is not None:
        work = Path(args.child)
        job = json.loads((work / "job.json").read_text(encoding="utf-8"))
        (work / "out.json").write_text(json.dumps(child(job)), encoding="utf-8")
        return
    names = [QUICK] if args.quick else args.only
    reps = 2 if args.quick else args.reps
    lines = ["## The LP stage and the certificates, CPU ms a warm solve (median / least)",
             "", "| instance | tree | solve | LP stage | certificates | LP policy+values "
             "hash | bracket hash | bracket |", "|---|---|---|---|---|---|---|---|"]
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        found, _ = bq.jobs(args.qvbs, 0, bq.MAX_STATES, bq.FAMILIES, work)
        jobs = {inst.name: job for inst, job in found}
        for name in names:
            if name not in jobs:
                raise SystemExit(f"--only: {name} is not a QVBS instance posed here")
            (work / "job.json").write_text(json.dumps(dict(jobs[name], reps=reps)),
                                           encoding="utf-8")
            trees = ([("base", args.compare), ("this", HERE.parent)] if args.compare
                     else [("this", HERE.parent)])
            for k in range(args.rounds if args.compare else 1):
                for label, root in trees:
                    line = _line(name, f"{label} {k + 1}", _run(args.qvbs, work, root))
                    print(line, flush=True)
                    lines.append(line)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "lp_stage_cpu.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    print(f"written: {args.out / 'lp_stage_cpu.md'}")


if __name__ == "__main__":
    main()
