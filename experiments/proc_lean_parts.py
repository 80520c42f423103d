"""proc-lean's two cuts of a PRISM route's process, each measured where it acts, beside
the whole process, before and after in one run.

Per QVBS instance (posed as ``bench_qvbs.py`` poses it), ``--repeats`` fresh processes
per checkout, taking turns, each started as ``bench_qvbs.py``'s worker starts (a program
importing NumPy, then the package), loading the model and solving it:

* ``parses``: Storm's parses of the PRISM file (``stormpy.parse_prism_program`` calls,
  counted) and ``parse_s`` their CPU seconds;
* ``pool_s``: the CPU seconds of the process's threads other than the main one (NumPy's
  and SciPy's OpenBLAS pools; Clarabel's threads take none here), read from
  ``/proc/self/task/*/stat`` (clock ticks) 0.3 s after the solve, when every pool has
  stopped spinning;
* ``process_s``: the whole process's CPU up to the end of the solve (the same clock as
  ``bench_qvbs.py``'s ``process_cpu``), which on a shared machine moves by more than
  the cuts;
* the answer (the bracket) beside them.

The median of each over the repeats is printed per checkout.  ``--first package``: the
program imports the package before NumPy (the package's modules import it), as a
program whose first import is ``from mitld_lp import ...``.

    python experiments/proc_lean_parts.py --qvbs /work/shared/qvbs --compare /tmp/base \\
        --only consensus.4-4.c2 firewire_dl.3-600.deadline --repeats 7 --out /tmp/x
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

import _common  # noqa: E402

ROOT = HERE.parent

PROBE = r"""
import json, os, resource, sys, time
def cpu():
    u, c = (resource.getrusage(w) for w in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN))
    return u.ru_utime + u.ru_stime + c.ru_utime + c.ru_stime
job = json.loads(sys.argv[1])
if job.get("first") != "package":
    import numpy
from mitld_lp import load_model, synthesize
import stormpy
parses = [0, 0.0]
inner = stormpy.parse_prism_program
def counted(*a, **k):
    c = time.process_time()
    try:
        return inner(*a, **k)
    finally:
        parses[0] += 1
        parses[1] += time.process_time() - c
stormpy.parse_prism_program = counted
model = load_model(job["model"], max_states=job["max_states"])
r = synthesize(model)
process = cpu()
time.sleep(0.3)
tick = os.sysconf("SC_CLK_TCK")
main = os.getpid()
pool = 0
for tid in os.listdir("/proc/self/task"):
    if int(tid) != main:
        with open(f"/proc/self/task/{tid}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
        pool += int(fields[11]) + int(fields[12])
print(json.dumps(dict(parses=parses[0], parse_s=parses[1], pool_s=pool / tick,
                      process_s=process, lower=r.lower, upper=r.upper)))
"""

COLUMNS = ("parses", "parse_s", "pool_s", "process_s")


def probe(job: dict, root: Path) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPATH"] = str(root)
    out = subprocess.run([sys.executable, "-c", PROBE, json.dumps(job)], cwd="/tmp", env=env,
                         capture_output=True, text=True, timeout=3600)
    if out.returncode:
        raise SystemExit(f"{job['model']}: the probe failed:\n{out.stderr[-2000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> list[list[object]]:
    import bench_qvbs

    p = _common.parser(__doc__.splitlines()[0])
    p.add_argument("--qvbs", type=Path, required=True, help="the benchmarks/ folder of QVBS")
    p.add_argument("--only", nargs="+", default=["consensus.4-4.c2"], help="instances")
    p.add_argument("--repeats", type=int, default=5, help="processes per checkout")
    p.add_argument("--compare", type=Path, default=None, metavar="DIR",
                   help="also the checkout DIR's package (before), taking turns with this one")
    p.add_argument("--first", choices=("numpy", "package"), default="numpy",
                   help="what the program imports first (default NumPy, as bench_qvbs)")
    args = p.parse_args(argv)
    out = _common.out_dir(args)
    work = out / "proc_lean_models"
    work.mkdir(parents=True, exist_ok=True)
    found, _ = bench_qvbs.jobs(args.qvbs, 0, 2_000_000, tuple(bench_qvbs.FAMILIES), work)
    jobs = {inst.name: dict(job, first=args.first) for inst, job in found
            if inst.name in args.only}
    missing = [n for n in args.only if n not in jobs]
    if missing:
        raise SystemExit(f"not found under {args.qvbs}: {', '.join(missing)}")
    roots = [("before", args.compare.resolve()), ("after", ROOT)] if args.compare else [
        ("this", ROOT)]
    header = ["instance", "checkout", *COLUMNS, "lower", "upper"]
    rows: list[list[object]] = []
    for name in args.only:
        for _, root in roots:  # a first run each: bytecode and numba's caches written
            probe(jobs[name], root)
        runs: dict[str, list[dict]] = {label: [] for label, _ in roots}
        for _ in range(args.repeats):
            for label, root in roots:
                runs[label].append(probe(jobs[name], root))
        brackets = {(r["lower"], r["upper"]) for rs in runs.values() for r in rs}
        if len(brackets) != 1:
            raise SystemExit(f"{name}: the checkouts answer differently: {sorted(brackets)}")
        (lower, upper), = brackets
        for label, _ in roots:
            med = {k: statistics.median(r[k] for r in runs[label]) for k in COLUMNS}
            row = [name, label, *(round(med[k], 4) for k in COLUMNS), lower, upper]
            rows.append(row)
            print("  ".join(f"{k}={v}" for k, v in zip(header, row, strict=True)), flush=True)
    _common.write_tables(out, "proc_lean_parts", header, rows)
    return rows


if __name__ == "__main__":
    main()
