"""The LP stage's and the certificates' CPU a warm solve, and the greedy policy's chain
solved alone, with hashes of the LP's policy and values and of the bracket, on QVBS
instances, a checkout against another.

Per instance and tree, a child process (the instance posed as ``bench_qvbs.py`` poses
it, the solver modules imported first, ``bench_sweeps.preload``):

* one synthesis, its LP policy and held values hashed (SHA-256 of their bytes and
  dtypes) and its bracket; :func:`mitld_lp.solvers.greedy_block.certified_greedy`
  wrapped to keep the walk of its largest block's policy chain
  (:class:`mitld_lp.solvers.chain_levels.ChainLevels`, factorised by that solve);
* ``--reps`` more syntheses, each timed by the process clock in place: the whole solve
  (``solve_cpu``), the plain route's LP stage (``routes.plain._solve_lp``) and its
  certificates (``routes.plain._certified``);
* the kept walk solved ``--reps`` times each way: two columns (the greedy check's values
  and exit times), one column, one column transposed (the policy's flow), each answer
  hashed: the compiled single-state runs of :mod:`mitld_lp.solvers.level_kernels`
  alone, a gain of a few ms that the whole solve's spread hides.

``--compare DIR``: the checkout ``DIR``'s package too, the children alternated
``--rounds`` times (the base's first)::

    python experiments/lp_stage_cpu.py --qvbs <QVBS> --only zeroconf.1000-4-false.correct_max \\
        csma.4-2.some_before --compare <base> --rounds 2 --reps 7
    python experiments/lp_stage_cpu.py --qvbs <QVBS> --quick   # firewire_dl, 2 solves

Medians and least (ms) are written to ``lp_stage_cpu.md`` in ``--out`` (default
``experiments/out``, a scratch folder).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from itertools import product
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

QUICK = "firewire_dl.3-600.deadline"
WALKS = ("2 columns", "1 column", "1 column transposed")


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


def _clocked(reps: int, run: Any) -> tuple[list[float], Any]:
    import time

    times, got = [], None
    for _ in range(reps):
        t = time.process_time()
        got = run()
        times.append(time.process_time() - t)
    return times, got


def child(job: dict[str, Any]) -> dict[str, Any]:
    """The module docs' three parts, in one process."""
    import time

    import bench_sweeps as bs
    import numpy as np

    import mitld_lp.routes.plain as plain
    import mitld_lp.solvers.lp_blocks as lb
    from mitld_lp import load_model, synthesize

    model = load_model(job["model"], max_states=job["max_states"])
    bs.preload()
    spent = {"lp": 0.0, "cert": 0.0}
    lps: list[Any] = []
    walks: list[Any] = []

    def timed(part: str, f: Any) -> Any:
        def run(*a: Any, **k: Any) -> Any:
            t = time.process_time()
            r = f(*a, **k)
            spent[part] += time.process_time() - t
            (lps if part == "lp" else []).append(r)
            return r
        return run

    greedy = lb.certified_greedy

    def keep(block: Any, reward: Any, *a: Any, **k: Any) -> Any:
        got = greedy(block, reward, *a, **k)
        if got is not None and not walks:  # the first synthesis's alone
            walks.append((got.walk, reward[got.chosen].copy()))
        return got

    plain._solve_lp = timed("lp", plain._solve_lp)
    plain._certified = timed("cert", plain._certified)
    lb.certified_greedy = keep
    first = synthesize(model)
    lp = lps[-1]
    out: dict[str, Any] = dict(
        bracket=[first.lower, first.upper],
        lp_hash=_digest(None if lp is None else lp.policy,
                        None if lp is None else lp.held_values),
        bracket_hash=_digest([first.lower, first.upper]))
    stages = []
    for _ in range(job["reps"]):
        spent.update(lp=0.0, cert=0.0)
        stages.append((synthesize(model).solve_cpu, spent["lp"], spent["cert"]))
    out["stages"] = [list(c) for c in zip(*stages, strict=True)]
    out["walks"] = []
    if walks:
        walk, rhs1 = walks[0]
        rhs2 = np.column_stack([rhs1, np.ones(rhs1.size)])
        for what, run in zip(WALKS, (lambda: walk.solve(rhs2), lambda: walk.solve(rhs1),
                                     lambda: walk.solve_transposed(rhs1)), strict=True):
            times, x = _clocked(job["reps"], run)
            out["walks"].append((what, walk.chain.shape[0], times, _digest(x)))
    return out


def _ms(times: list[float]) -> str:
    v = sorted(times)
    return f"{v[len(v) // 2] * 1e3:.1f} / {v[0] * 1e3:.1f}"


def _rows(name: str, label: str, got: dict[str, Any]) -> tuple[list[str], list[str]]:
    solve, lp, cert = got["stages"]
    stage = [f"| {name} | {label} | {_ms(solve)} | {_ms(lp)} | {_ms(cert)} | "
             f"{got['lp_hash']} | {got['bracket_hash']} | {got['bracket']} |"]
    walk = [f"| {name} | {label} | {n} | {what} | {_ms(times)} | {digest} |"
            for what, n, times, digest in got["walks"]]
    return stage, walk


def _answer(work: Path) -> None:
    got = child(json.loads((work / "job.json").read_text(encoding="utf-8")))
    (work / "out.json").write_text(json.dumps(got), encoding="utf-8")


def main(argv: list[str] | None = None) -> None:
    import bench_qvbs as bq

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--qvbs", type=Path, required=True)
    ap.add_argument("--only", nargs="*", default=[QUICK], metavar="NAME")
    ap.add_argument("--quick", action="store_true", help=f"{QUICK}, two timed solves")
    ap.add_argument("--reps", type=int, default=5, help="timed solves a child, each way")
    ap.add_argument("--compare", type=Path, default=None, metavar="DIR",
                    help="a base checkout, its children alternated with this one's")
    ap.add_argument("--rounds", type=int, default=1, help="with --compare")
    ap.add_argument("--out", type=Path, default=HERE / "out")
    args = ap.parse_args(argv)
    if args.child is not None:  # the child's side: the job in, its figures out
        return _answer(Path(args.child))
    trees = [("this", HERE.parent)] if args.compare is None else \
        [("base", args.compare), ("this", HERE.parent)]
    rounds = range(1, (args.rounds if args.compare else 1) + 1)
    stage_lines = ["## The LP stage and the certificates, CPU ms a warm solve "
                   "(median / least)", "", "| instance | tree | solve | LP stage | "
                   "certificates | LP policy+values hash | bracket hash | bracket |",
                   "|---|---|---|---|---|---|---|---|"]
    walk_lines = ["", "## The greedy chain's level walk, CPU ms a solve (median / least)",
                  "", "| instance | tree | chain states | solve | ms | answer hash |",
                  "|---|---|---|---|---|---|"]
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        posed = {inst.name: job for inst, job in
                 bq.jobs(args.qvbs, 0, bq.MAX_STATES, bq.FAMILIES, work)[0]}
        unknown = sorted(set([QUICK] if args.quick else args.only) - set(posed))
        if unknown:
            raise SystemExit(f"--only: not QVBS instances posed here: {unknown}")
        for name, k, (label, root) in product([QUICK] if args.quick else args.only,
                                              rounds, trees):
            reps = 2 if args.quick else args.reps
            (work / "job.json").write_text(json.dumps(dict(posed[name], reps=reps)),
                                           encoding="utf-8")
            env = dict(os.environ, PYTHONPATH=os.pathsep.join(
                [str(root), *filter(None, [os.environ.get("PYTHONPATH")])]))
            subprocess.run([sys.executable, __file__, "--qvbs", str(args.qvbs),
                            "--child", str(work)], check=True, env=env)
            stage, walk = _rows(name, f"{label} {k}", json.loads(
                (work / "out.json").read_text(encoding="utf-8")))
            print("\n".join(stage + walk), flush=True)
            stage_lines += stage
            walk_lines += walk
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "lp_stage_cpu.md").write_text("\n".join(stage_lines + walk_lines) + "\n",
                                              encoding="utf-8")
    print(f"written: {args.out / 'lp_stage_cpu.md'}")


if __name__ == "__main__":
    main()
