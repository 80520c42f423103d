"""The door's whole process on QVBS PRISM files, ours beside the base's and Storm's, in one run.

    python experiments/bench_door.py --qvbs <QVBS> --compare <base> [--repeats 5]
    python experiments/bench_door.py --quick      # the corridor alone, one round

Per instance and round, the routes take turns, each a process of its own (CPU seconds,
user + system, and peak resident MB, from ``os.wait4``):

* ``door``: ``mitld-lp solve MODEL --prop PROPERTY --const ... --json`` of this
  checkout, and ``door base`` of ``--compare BASE`` (a checkout of the base), with
  the bracket;
* ``storm``: a stormpy script doing Storm's whole run (import, parse, build, sound
  check: ``property_reader_times.STORM``), with its value;
* ``import stormpy`` and ``python -c pass``: what the import alone costs a process.

The first round is a warm-up (each tree's kernels linked or compiled once) and is not
counted.  Prints the medians and writes ``bench_door.md`` into the output folder
(``--out``; by default the scratch folder ``experiments/out/quick``).
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _common  # noqa: E402
from property_reader_times import STORM  # noqa: E402

# (name, model file under the QVBS folder, constants, property as QVBS publishes it)
CASES = [
    ("consensus.4-4.c2", "consensus/consensus.4.prism", "K=4",
     'Pmin=? [ F "finished"&"all_coins_equal_1" ]'),
    ("firewire_dl.3-600.deadline", "firewire_dl/firewire_dl.prism", "delay=3,deadline=600",
     "Pmin=? [ F s=9 ]"),
    ("csma.4-2.some_before", "csma/csma.4-2.prism", "",
     "Pmin=? [ F min_backoff_after_success<K ]"),
]
QUICK = [("corridor", str(_common.MODELS / "corridor.prism"), "open_at_start=true",
          'Pmax=? [F<=6 "goal"]')]


def run(argv: list[str], code: Path | None) -> tuple[float, float, str]:
    """``(CPU s, peak MB, stdout)`` of the process ``argv`` (``code`` first on its path)."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    if code is not None:
        env["PYTHONPATH"] = os.pathsep.join([str(code), *filter(None, [env.get("PYTHONPATH")])])
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        proc = subprocess.Popen(argv, cwd=code or _common.ROOT, stdout=out, stderr=err,
                                env=env)
        _, status, usage = os.wait4(proc.pid, 0)
        out.seek(0)
        err.seek(0)
        if os.waitstatus_to_exitcode(status) != 0:
            raise RuntimeError(f"{argv}: exit {os.waitstatus_to_exitcode(status)}\n"
                               + err.read().decode(errors="replace")[-2000:])
        text = out.read().decode(errors="replace")
    return usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024, text


def door(code: Path, model: str, constants: str, prop: str) -> tuple[float, float, str]:
    argv = [sys.executable, "-m", "mitld_lp", "solve", model, "--prop", prop, "--json"]
    if constants:
        argv += ["--const", constants]
    cpu, peak, out = run(argv, code)
    answer = json.loads(out.strip().splitlines()[-1])
    return cpu, peak, f"[{answer['lower']:.10g}, {answer['upper']:.10g}]"


def main(argv: list[str] | None = None) -> int:
    ap = _common.parser(__doc__.splitlines()[0])
    ap.add_argument("--qvbs", type=Path, default=None, help="the QVBS benchmarks folder")
    ap.add_argument("--compare", type=Path, default=None, help="a checkout of the base")
    ap.add_argument("--repeats", type=int, default=None, help="rounds counted (default 3)")
    ap.add_argument("--only", nargs="*", default=[])
    args = ap.parse_args(argv)
    if args.out is None:  # a scratch folder, never the committed results
        args.out = _common.QUICK_OUT
    out = _common.out_dir(args)
    repeats = args.repeats or (1 if args.quick else 3)
    cases = QUICK if args.quick or args.qvbs is None else [
        (name, str(args.qvbs / "mdp" / path), c, p) for name, path, c, p in CASES
        if not args.only or name in args.only]
    rows = []
    for name, model, constants, prop in cases:
        runs: dict[str, list[tuple[float, float]]] = {}
        answers: dict[str, str] = {}
        for round_ in range(repeats + 1):
            got = {}
            for label, code in (("door", _common.ROOT), ("door base", args.compare)):
                if code is not None:
                    cpu, peak, answers[label] = door(code, model, constants, prop)
                    got[label] = (cpu, peak)
            cpu, peak, text = run([sys.executable, "-c", STORM, model, constants, prop],
                                  None)
            got["storm"], answers["storm"] = (cpu, peak), text.strip()
            for label, code_ in (("import stormpy", "import stormpy"),
                                 ("python -c pass", "pass")):
                cpu, peak, _ = run([sys.executable, "-c", code_], None)
                got[label], answers[label] = (cpu, peak), ""
            if round_:  # the first round warms each tree up
                for label, figures in got.items():
                    runs.setdefault(label, []).append(figures)
        for label, values in runs.items():
            rows.append((name, label, f"{statistics.median(v[0] for v in values):.3f}",
                         f"{min(v[0] for v in values):.3f}",
                         f"{statistics.median(v[1] for v in values):.1f}", answers[label]))
        print(_common.text_table(("instance", "route", "median CPU s", "least CPU s",
                                  "peak MB", "answer"), rows[-len(runs):]), flush=True)
    header = ("instance", "route", "median CPU s", "least CPU s", "peak MB", "answer")
    _common.write_text(out / "bench_door.md", _common.markdown_table(header, rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
