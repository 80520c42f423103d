"""What the memory-capped child's result costs to send back, before and after, in CPU.

The PRISM load explores a world whose variables' ranges do not fit the budgets in a
forked child with a capped address space (``mitld_lp.worlds.prism_bounded.run_capped``),
which sends Storm's model back as arrays.  Here, in fresh processes taking turns, the
child returns arrays of the sizes of a world's tables (by default csma 4-2 of QVBS:
608,082 states, 825,504 choices, 1,094,356 branches; 35 MB) made before the clock
starts, with this checkout's ``run_capped`` and, with ``--compare DIR``, with that
checkout's; printed: the CPU of the call (the parent's and the child's), the least over
``--repeats`` runs, and the answer (the arrays came back equal, bit for bit).

    python experiments/capped_transfer.py --compare /tmp/base
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

import _common  # noqa: E402

ROOT = HERE.parent

PROBE = r"""
import json, resource, sys
import numpy as np
from mitld_lp.worlds.prism_bounded import run_capped
n, m, b = (int(x) for x in sys.argv[1:4])
rng = np.random.default_rng(0)
arrays = dict(choices=np.arange(n + 1, dtype=np.int64), branches=np.arange(m + 1, dtype=np.int64),
              targets=rng.integers(0, n, b, dtype=np.int64), probabilities=rng.random(b),
              labels=np.zeros(n, dtype=np.int32), actions=np.zeros(m, dtype=np.int32))
def cpu():
    u, c = (resource.getrusage(w) for w in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN))
    return u.ru_utime + u.ru_stime + c.ru_utime + c.ru_stime
c = cpu()
got = run_capped(lambda: arrays, 4 << 30)
spent = cpu() - c
same = all(got[k].dtype == v.dtype and got[k].tobytes() == v.tobytes() for k, v in arrays.items())
print(json.dumps(dict(cpu=spent, same=same, mb=sum(v.nbytes for v in arrays.values()) / 1e6)))
"""


def run(code: Path, sizes: list[int]) -> dict:
    env = {"PYTHONPATH": str(code), "PATH": "/usr/bin:/bin"}
    out = subprocess.run([sys.executable, "-c", PROBE, *map(str, sizes)], cwd=code, env=env,
                         capture_output=True, text=True, check=True, timeout=600)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> list[list[object]]:
    p = _common.parser(__doc__.splitlines()[0])
    p.add_argument("--compare", type=Path, default=None, help="a checkout to run as the base")
    p.add_argument("--sizes", type=int, nargs=3, default=[608_082, 825_504, 1_094_356],
                   metavar=("STATES", "CHOICES", "BRANCHES"))
    p.add_argument("--repeats", type=int, default=None, help="runs of each (default 5)")
    args = p.parse_args(argv)
    repeats = args.repeats or (2 if args.quick else 5)
    codes = {"this": ROOT, **({"base": args.compare} if args.compare else {})}
    runs: dict[str, list[dict]] = {name: [] for name in codes}
    for _ in range(repeats):  # taking turns
        for name, code in codes.items():
            runs[name].append(run(code, args.sizes))
    header = ["checkout", "states", "choices", "branches", "mb", "cpu_min_s", "cpu_median_s",
              "same_arrays"]
    rows = []
    for name, got in runs.items():
        cpus = sorted(r["cpu"] for r in got)
        rows.append([name, *args.sizes, round(got[0]["mb"], 1), round(cpus[0], 4),
                     round(cpus[len(cpus) // 2], 4), all(r["same"] for r in got)])
        print(dict(zip(header, rows[-1], strict=True)))
    _common.write_tables(_common.out_dir(args), "capped_transfer", header, rows)
    return rows


if __name__ == "__main__":
    main()
