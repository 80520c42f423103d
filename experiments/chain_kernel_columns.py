"""The greedy policy's chain solved again and again: CPU ms a solve of its level walk
(:class:`mitld_lp.solvers.chain_levels.ChainLevels`, the compiled single-state runs of
:mod:`mitld_lp.solvers.level_kernels`) with two columns (the greedy check's values and
exit times), one column, and one column transposed (the policy's flow), on QVBS
instances whose LP stage settles a block by its greedy policy, a checkout against
another.

Per instance and tree, a child process: the instance posed as ``bench_qvbs.py`` poses
it, one synthesis with :func:`mitld_lp.solvers.greedy_block.certified_greedy` wrapped
to keep its largest block's walk (its factorisations made by that solve), then each
solve ``--reps`` times on that walk (the median, the least); the answers' SHA-256
beside.  ``--compare DIR``: the checkout ``DIR``'s package too, alternated
``--rounds`` times (the base's first)::

    python experiments/chain_kernel_columns.py --qvbs <QVBS> \\
        --only zeroconf.1000-4-false.correct_max --compare <base> --rounds 2
    python experiments/chain_kernel_columns.py --qvbs <QVBS> --quick

Written: ``chain_kernel_columns.md`` in ``--out`` (default ``experiments/out``).
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

QUICK = "zeroconf.1000-4-false.correct_max"


def child(job: dict[str, Any]) -> dict[str, Any]:
    import hashlib
    import time

    import bench_sweeps as bs
    import numpy as np

    import mitld_lp.solvers.lp_blocks as lb
    from mitld_lp import load_model, synthesize

    model = load_model(job["model"], max_states=job["max_states"])
    bs.preload()
    kept: list[Any] = []
    greedy = lb.certified_greedy

    def keep(block: Any, reward: Any, *a: Any, **k: Any) -> Any:
        got = greedy(block, reward, *a, **k)
        if got is not None:
            kept.append((got.walk, reward[got.chosen].copy()))
        return got

    lb.certified_greedy = keep
    synthesize(model)
    if not kept:
        return dict(rows=[], states=0)
    walk, rhs1 = max(kept, key=lambda w: w[0].chain.shape[0])
    n = walk.chain.shape[0]
    rhs2 = np.column_stack([rhs1, np.ones(n)])
    out = []
    for label, run in (("2 columns", lambda: walk.solve(rhs2)),
                       ("1 column", lambda: walk.solve(rhs1)),
                       ("1 column transposed", lambda: walk.solve_transposed(rhs1))):
        times = []
        for _ in range(job["reps"]):
            t = time.process_time()
            x = run()
            times.append(time.process_time() - t)
        times.sort()
        out.append((label, times[len(times) // 2] * 1e3, times[0] * 1e3,
                    hashlib.sha256(np.ascontiguousarray(x).tobytes()).hexdigest()[:16]))
    return dict(rows=out, states=n, compiled=walk._kernels is not None)


def _run(qvbs: Path, work: Path, root: Path) -> dict[str, Any]:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(root), *filter(None, [os.environ.get("PYTHONPATH")])]))
    subprocess.run([sys.executable, __file__, "--qvbs", str(qvbs), "--child", str(work)],
                   check=True, env=env)
    return json.loads((work / "out.json").read_text(encoding="utf-8"))


def main(argv: list[str] | None = None) -> None:
    import bench_qvbs as bq

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--qvbs", type=Path, required=True)
    ap.add_argument("--only", nargs="*", default=[QUICK], metavar="NAME")
    ap.add_argument("--reps", type=int, default=21)
    ap.add_argument("--quick", action="store_true", help=f"{QUICK}, 5 solves each")
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
    reps = 5 if args.quick else args.reps
    lines = ["## The greedy chain's level walk, CPU ms a solve (median / least)", "",
             "| instance | tree | chain states | solve | ms | answer hash |",
             "|---|---|---|---|---|---|"]
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
                    got = _run(args.qvbs, work, root)
                    for what, med, least, digest in got["rows"]:
                        line = (f"| {name} | {label} {k + 1} | {got['states']} | {what} | "
                                f"{med:.2f} / {least:.2f} | {digest} |")
                        print(line, flush=True)
                        lines.append(line)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "chain_kernel_columns.md").write_text("\n".join(lines) + "\n",
                                                      encoding="utf-8")
    print(f"written: {args.out / 'chain_kernel_columns.md'}")


if __name__ == "__main__":
    main()
