"""Where bench_qvbs.py's ``process_cpu - whole_cpu`` goes: its worker, step by step.

``bench_qvbs.py``'s worker (``work_ours``) counts in ``process_cpu`` everything its child
spends until the synthesis ends, and in ``whole_cpu`` only the load and the synthesis.
The difference is the process beside the work.  Here a child runs ``work_ours`` itself,
as bench_qvbs's worker does, with the process's CPU (``resource``, ended children
included) read after each step:
* the interpreter;
* the harness (bench_qvbs's own imports);
* the command line's start (``--start command`` only);
* ``import numpy``;
* the package's import;
* the load;
* ``bench_sweeps.preload`` (the solve's imports);
* the synthesis.

It is run once per start (``library``: a program importing the package; ``command``: as
``mitld-lp`` starts) on each instance of ``--only``, and prints the steps, the gap and the
answer (the bracket's lower end).

    python experiments/route_gap.py --qvbs /path/to/qcomp/benchmarks \
        --only zeroconf.1000-4-false.correct_max --out /tmp/gap
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

import _common  # noqa: E402

ROOT = HERE.parent

CHILD = r"""
import json, resource, sys
def cpu():
    a, b = (resource.getrusage(w) for w in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN))
    return a.ru_utime + a.ru_stime + b.ru_utime + b.ru_stime
steps = [("interpreter", cpu())]
sys.path.insert(0, sys.argv[3])
import bench_qvbs as bq
steps.append(("harness", cpu()))
if sys.argv[2] == "command":
    bq._command_start()
    steps.append(("command start", cpu()))
import numpy
steps.append(("import numpy", cpu()))
import mitld_lp
from mitld_lp import load_model, synthesize
steps.append(("package import", cpu()))
preload = bq.bs.preload
def timed_preload():
    preload(); steps.append(("preload", cpu()))
def timed_load(*a, **k):
    r = load_model(*a, **k); steps.append(("load", cpu())); return r
def timed_synthesize(*a, **k):
    r = synthesize(*a, **k); steps.append(("synthesis", cpu())); return r
bq.bs.preload = timed_preload
mitld_lp.load_model, mitld_lp.synthesize = timed_load, timed_synthesize
job = dict(json.loads(open(sys.argv[1]).read()), start="library")  # (its start: above)
import pathlib, tempfile
with tempfile.TemporaryDirectory() as work:
    out = bq.work_ours(job, pathlib.Path(work))
print(json.dumps(dict(steps=steps, process=out["process_cpu"], whole=out["whole_cpu"],
                      lower=out["lower"], numba="numba" in sys.modules)))
"""


def run(job: Path, start: str) -> dict:
    done = subprocess.run([sys.executable, "-c", CHILD, str(job), start, str(HERE)], cwd=ROOT,
                          capture_output=True, text=True, check=True, timeout=3600)
    return json.loads(done.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> list[list[object]]:
    import bench_qvbs

    p = _common.parser(__doc__.splitlines()[0])
    p.add_argument("--qvbs", type=Path, required=True, help="qcomp's benchmarks/ folder")
    p.add_argument("--only", nargs="+", required=True, metavar="NAME")
    p.add_argument("--start", nargs="+", choices=("library", "command"),
                   default=["library", "command"])
    args = p.parse_args(argv)
    rows: list[list[object]] = []
    with tempfile.TemporaryDirectory() as tmp:
        todo, _ = bench_qvbs.jobs(args.qvbs, 0, 10**9, bench_qvbs.FAMILIES, Path(tmp))
        for inst, job in todo:
            if inst.name not in args.only:
                continue
            path = Path(tmp) / f"{inst.name}.json"
            path.write_text(json.dumps(job), encoding="utf-8")
            for start in args.start:
                got = run(path, start)
                last = 0.0
                print(f"{inst.name}, {start} start: value {got['lower']!r}")
                for step, at in got["steps"]:
                    print(f"    {step:16s} {at - last:7.3f}")
                    rows.append([inst.name, start, step, round(at - last, 4), got["lower"]])
                    last = at
                gap = got["process"] - got["whole"]
                print(f"    gap (process_cpu - whole_cpu) {gap:.3f}, whole_cpu "
                      f"{got['whole']:.3f}, process_cpu {got['process']:.3f}; "
                      f"numba loaded: {got['numba']}")
                rows.append([inst.name, start, "gap", round(gap, 4), got["lower"]])
                rows.append([inst.name, start, "whole_cpu", round(got["whole"], 4),
                             got["lower"]])
    _common.write_tables(_common.out_dir(args), "route_gap",
                         ["instance", "start", "step", "cpu_s", "value"], rows)
    return rows


if __name__ == "__main__":
    main()
