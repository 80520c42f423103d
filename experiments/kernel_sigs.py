"""Which compiled kernels the tests compile, with how many signatures, and what each costs.

Runs the given test files (default: those that call the project's numba kernels) under
pytest in a child process with an *empty* numba cache (a fresh ``NUMBA_CACHE_DIR``), with
this module loaded as a pytest plugin: it listens to numba's ``numba:compile`` events and
records, for each signature compiled, the kernel, its argument types and the CPU seconds
of the compile (a kernel's own seconds: those of the kernels it calls and compiles first
are counted on them).  Then prints one row per kernel: signatures, seconds, and each
signature's argument dtypes where the kernel has more than one.  The index files numba
wrote (``*.nbi`` under the cache directory) are counted too, as a check::

    python experiments/kernel_sigs.py                      # the default test files
    python experiments/kernel_sigs.py tests/test_kernels.py --workers 2
    python experiments/kernel_sigs.py --compare /tmp/base  # the same files on a checkout

With ``--compare DIR`` the same tests run on the checkout in ``DIR`` too (its own
``PYTHONPATH``, its own empty cache) and the two tables are printed side by side.  The
tests' outcome (passed/failed counts) is printed beside each run: the answers are
checked by the tests themselves.
"""

from __future__ import annotations

import argparse
import json
import os
import pickle
import subprocess
import sys
import tempfile
import time
from pathlib import Path

DEFAULT_TESTS = (
    "tests/test_kernels.py", "tests/test_solve_kernels_load.py",
    "tests/test_solve_kernels_optimistic.py", "tests/test_ovi_interleave.py",
    "tests/test_compiled_graph.py", "tests/test_eliminate.py", "tests/test_chain_levels.py",
    "tests/test_single_levels.py", "tests/test_level_runs.py", "tests/test_deadline_walks.py",
    "tests/test_sensing_kernels.py", "tests/test_sensing_arrays.py",
    "tests/test_sensing_rows.py", "tests/test_sensing_merge.py", "tests/test_sensed_level.py",
    "tests/test_kernel_sigs.py",
)

ENV_OUT = "KERNEL_SIGS_OUT"

# ---------------------------------------------------------------- the pytest plugin part
_records: list[dict] = []


def _describe(arg: object) -> str:
    """numba's type of an argument, its array layout included (``array(int32, 1d, C)``)."""
    return str(arg).replace("array(", "(")


class _Listener:
    """numba's compile events: a stack of (kernel, start CPU, children's seconds)."""

    def __init__(self) -> None:
        self.stack: list[list] = []

    def notify(self, event) -> None:  # numba's Listener protocol (start and end)
        if event.is_start:
            self.stack.append([time.process_time(), 0.0])
            return
        start, children = self.stack.pop()
        total = time.process_time() - start
        if self.stack:
            self.stack[-1][1] += total
        disp = event.data["dispatcher"]
        func = disp.py_func
        _records.append({"kernel": f"{func.__module__}.{func.__qualname__}",
                         "args": [_describe(a) for a in event.data["args"]],
                         "seconds": total - children, "with_callees": total})


def pytest_configure(config) -> None:  # pragma: no cover - runs in the child
    from numba.core import event

    listener = _Listener()

    class _Adapter(event.Listener):
        def on_start(self, ev):
            listener.notify(ev)

        def on_end(self, ev):
            listener.notify(ev)

    event.register("numba:compile", _Adapter())


def pytest_unconfigure(config) -> None:  # pragma: no cover - runs in the child
    out = os.environ.get(ENV_OUT)
    if out:
        Path(out, f"{os.getpid()}.json").write_text(json.dumps(_records))


# ---------------------------------------------------------------- the driver
def _index_entries(cache: Path) -> dict[str, int]:
    """Signatures per index file numba wrote under ``cache``."""
    found = {}
    for nbi in sorted(cache.rglob("*.nbi")):
        with open(nbi, "rb") as f:
            pickle.load(f)  # numba's version
            _, overloads = pickle.loads(f.read())
        found[nbi.name] = len(overloads)
    return found


def run(root: Path, tests: list[str], workers: int) -> dict:
    """The tests of ``root`` on an empty cache: the compiles, the index files, the outcome."""
    with tempfile.TemporaryDirectory(prefix="kernel-sigs-") as tmp:
        cache, out = Path(tmp, "cache"), Path(tmp, "out")
        cache.mkdir()
        out.mkdir()
        env = dict(os.environ, NUMBA_CACHE_DIR=str(cache), **{ENV_OUT: str(out)},
                   PYTHONPATH=os.pathsep.join([str(root), str(Path(__file__).parent)]))
        cmd = [sys.executable, "-m", "pytest", "-q", "-p", "kernel_sigs", "-p", "no:cacheprovider",
               *tests]
        if workers > 1:
            cmd += ["-n", str(workers), "--dist", "loadfile"]
        t0 = time.time()
        done = subprocess.run(cmd, cwd=root, env=env, text=True, capture_output=True)
        wall = time.time() - t0
        outcome = (done.stdout.strip().splitlines() or ["(no output)"])[-1]
        records = [r for f in out.glob("*.json") for r in json.loads(f.read_text())]
        return {"records": records, "index": _index_entries(cache), "outcome": outcome,
                "wall": wall}


def table(result: dict) -> dict[str, dict]:
    rows: dict[str, dict] = {}
    for r in result["records"]:
        if not r["kernel"].startswith("mitld_lp."):
            continue
        row = rows.setdefault(r["kernel"], {"sigs": [], "seconds": 0.0})
        sig = ", ".join(r["args"])
        if sig not in row["sigs"]:  # two workers may compile one signature at once
            row["sigs"].append(sig)
            row["seconds"] += r["seconds"]
    return rows


def _print(rows: dict[str, dict], other: dict[str, dict] | None) -> None:
    head = f"{'kernel':<58} {'sigs':>4} {'CPU s':>7}"
    if other is not None:
        head = f"{'kernel':<58} {'before':>6} {'CPU s':>7} {'after':>5} {'CPU s':>7}"
    print(head)
    names = sorted(set(rows) | set(other or {}),
                   key=lambda k: -max(rows.get(k, {"seconds": 0})["seconds"],
                                      (other or {}).get(k, {"seconds": 0})["seconds"]))
    for name in names:
        short = name.removeprefix("mitld_lp.")
        a = rows.get(name, {"sigs": [], "seconds": 0.0})
        if other is None:
            print(f"{short:<58} {len(a['sigs']):>4} {a['seconds']:>7.2f}")
        else:
            b = other.get(name, {"sigs": [], "seconds": 0.0})
            print(f"{short:<58} {len(b['sigs']):>6} {b['seconds']:>7.2f} {len(a['sigs']):>5} "
                  f"{a['seconds']:>7.2f}")
    for label, rs in (("before", other), ("after" if other is not None else "", rows)):
        if rs is None:
            continue
        for name, row in sorted(rs.items()):
            if len(row["sigs"]) > 1:
                print(f"  {label} {name.removeprefix('mitld_lp.')}:")
                for s in row["sigs"]:
                    print(f"      ({s})")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("tests", nargs="*", help="test files (default: the kernels' own)")
    ap.add_argument("--workers", type=int, default=1, help="pytest-xdist workers (1: none)")
    ap.add_argument("--compare", type=Path, help="a 'before' checkout to run the same tests on")
    ap.add_argument("--json", type=Path, help="write both runs' records here (a new file: "
                    "never one that exists)")
    ap.add_argument("--quick", action="store_true",
                    help="the first default test file only (it prints only, unless --json)")
    args = ap.parse_args(argv)
    if args.json is not None and args.json.exists():
        ap.error(f"--json {args.json}: the file exists; give a new one")
    here = Path(__file__).resolve().parent.parent
    tests = args.tests or [t for t in DEFAULT_TESTS if (here / t).exists()]
    if args.quick:
        tests = tests[:1]
    after = run(here, tests, args.workers)
    before = None
    if args.compare is not None:
        base_tests = [t for t in tests if (args.compare / t).exists()]
        before = run(args.compare.resolve(), base_tests, args.workers)
    print(f"tests: {' '.join(tests)}")
    for label, res in (("before", before), ("after", after)):
        if res is None:
            continue
        rows = table(res)
        print(f"{label}: {res['outcome']}; wall {res['wall']:.0f} s; "
              f"{sum(len(r['sigs']) for r in rows.values())} signatures of {len(rows)} kernels "
              f"compiled, {sum(r['seconds'] for r in rows.values()):.1f} CPU s; index files "
              f"with >1 signature: "
              f"{ {k: v for k, v in res['index'].items() if v > 1} or 'none'}")
    _print(table(after), None if before is None else table(before))
    if args.json:
        args.json.write_text(json.dumps({"after": after, "before": before}, indent=1))


if __name__ == "__main__":
    main()
