"""Benchmark: start-up, the bundled case as a whole process beside a stormpy script.

The README's first command, ``mitld-lp solve models/bus_grid.toml``, answers a 371-state
product: what it costs is mostly start-up (the interpreter, imports, the command line),
so it is measured as a whole process, in CPU seconds (user + system of the finished
child, ``os.wait4``), beside stormpy scripts doing the same task's work, in one run:

* ``ours``: ``python -m mitld_lp solve models/bus_grid.toml --json`` (the console
  script's route, ``mitld_lp.startup.command``), its certified ``[lower, upper]``;
* ``storm_prism``: a stormpy script on the PRISM encoding of the same task
  (``experiments/prism/bus.prism`` with the case's constants, the script
  ``bench_sweeps.py`` runs): import stormpy, parse, build, check ``Pmax=? [F
  "target"]`` with ``force_soundness``; the target's yardstick;
* ``storm_drn``: a stormpy script on the case's product exported by
  ``mitld-lp export --drn`` (read the DRN, check ``Pmax=? [F "accept"]``, sound);
* ``ours_corridor``: the README's first command for a Storm user, ``mitld-lp solve
  models/corridor.prism --prop 'Pmax=? [F<=6 "goal"]' --const open_at_start=true``
  (a PRISM file through Storm's builder, our analysis and solve), beside
  ``storm_corridor``: a stormpy script on the same file with the constant written in,
  the same property checked soundly;
* ``ours_corridor_law``: the bundled corridor model file, ``mitld-lp solve
  models/corridor.toml`` (the same PRISM file, the door's opening a Poisson law: what a
  law in closed form saves, without SciPy's statistics);
* ``ours_corridor_program``: the same model file solved by a program that imports the
  package (``load_model`` and ``synthesize``, the start ``bench_qvbs.py``'s worker has by
  default): what the library's start costs beside the command line's;
* ``version``: ``mitld-lp --version`` (the package's import and the console script's
  start, nothing of the command line) and ``check``: ``mitld-lp check`` on the case's
  formula (the command line and the formula parser, no model): trivial commands;
* the floors, for reading the others: the interpreter alone (``python -c pass``),
  ``import numpy, scipy.sparse`` (what the product's matrices need) and ``import
  stormpy``.

Every process is run ``--repeats`` times, the commands taking turns (one round runs each
once), and each row gives the least and the median CPU of its runs; the ratio of ours to
each stormpy script is the median of the rounds' ratios (each round's pair ran side by
side, which keeps it meaningful on a machine whose speed drifts).  The target (issue 45):
the case as a process <= 2x the stormpy script on the PRISM encoding.

``--compare BASE`` also runs ``ours``, ``ours_corridor(_law, _program)``, ``version`` and
``check`` with another ``mitld_lp``, in the same rounds, as ``*_base`` rows: before and
after in one run.
``BASE`` is a checkout's folder or a commit of this repository (its ``mitld_lp`` taken
with ``git archive`` into a scratch folder).  Bytecode is cached for both (the
variable ``PYTHONDONTWRITEBYTECODE`` is cleared, as ``bench_sweeps.py`` does: an
installed package's bytecode is written at installation).

Written: ``bench_startup.csv``, ``bench_startup.md`` and ``bench_startup_machine.txt``::

    python experiments/bench_startup.py --compare e1d68a4 --out experiments/results
    python experiments/bench_startup.py --compare /tmp/before --out /tmp/startup

``--quick`` runs two rounds into ``experiments/out/quick`` (or ``--out``).  Storm's
answers must lie within 1e-6 (its precision) of our bracket, or the run stops.
"""

from __future__ import annotations

import json
import os
import platform
import statistics
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

import _common  # noqa: E402
from bench_scaling import Instance  # noqa: E402  (the case's PRISM encoding)

ROOT = HERE.parent
CASE = ROOT / "models" / "bus_grid.toml"
TARGET = 2.0  # the case as a process <= 2x the stormpy script (issue 45)

STORM_FILE = """
import sys, stormpy
program = stormpy.parse_prism_program(sys.argv[1])
prop = stormpy.parse_properties(sys.argv[2], program)[0]
model = stormpy.build_model(program, [prop])
env = stormpy.Environment()
env.solver().force_soundness = True
print(stormpy.model_checking(model, prop, environment=env).get_value(model.initial_states[0]))
"""
#: A program importing the package (the library's start, no command line) and solving a
#: model file as ``bench_qvbs.py``'s worker does by default.
PROGRAM = """
import json, sys
from mitld_lp import load_model, synthesize
r = synthesize(load_model(sys.argv[1]))
print(json.dumps(dict(lower=r.lower, upper=r.upper, certified=r.certified)))
"""
CORRIDOR = ROOT / "models" / "corridor.prism"
CORRIDOR_PROPERTY = 'Pmax=? [F<=6 "goal"]'

STORM_DRN = """
import sys, stormpy
model = stormpy.build_model_from_drn(sys.argv[1])
prop = stormpy.parse_properties('Pmax=? [F "accept"]')[0]
env = stormpy.Environment()
env.solver().force_soundness = True
print(stormpy.model_checking(model, prop, environment=env).get_value(model.initial_states[0]))
"""


def run_cpu(argv: list[str], code: Path | None = None) -> tuple[float, str]:
    """The CPU seconds (user + system, ``os.wait4``) of the process ``argv`` and its
    standard output; ``code``: a checkout put first on ``PYTHONPATH``.  A failure
    raises with the process's standard error."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    if code is not None:
        env["PYTHONPATH"] = os.pathsep.join([str(code),
                                             *filter(None, [env.get("PYTHONPATH")])])
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        # the working directory comes first on ``python -m``'s path: the checkout's own
        proc = subprocess.Popen(argv, cwd=code or ROOT, stdout=out, stderr=err, env=env)
        _, status, usage = os.wait4(proc.pid, 0)
        out.seek(0)
        err.seek(0)
        text = out.read().decode(errors="replace")
        if os.waitstatus_to_exitcode(status) != 0:
            raise RuntimeError(f"{argv}: exit {os.waitstatus_to_exitcode(status)}\n"
                               + err.read().decode(errors="replace")[-2000:])
    return usage.ru_utime + usage.ru_stime, text


def _bracket(out: str) -> str:
    answer = json.loads(out)
    if not answer.get("certified"):
        raise RuntimeError(f"the case is not certified: {out[:500]}")
    return f"[{answer['lower']:.10f}, {answer['upper']:.10f}]"


def commands(work: Path, compare: Path | None) -> dict[str, tuple[list[str], Path | None, Any]]:
    """Each row's command, the checkout it imports (None: this one) and how its
    answer is read from its output."""
    prism = work / "case.prism"
    prism.write_text(Instance("bus", 4, 3).prism(), encoding="utf-8")
    drn = work / "case.drn"
    py = sys.executable
    run_cpu([py, "-m", "mitld_lp", "export", str(CASE), "--drn", str(drn), "--force", "-q"])
    formula = 'D[mu1] b1 & F (b1 & F[0,3] A) | D[mu2] b2 & F (b2 & F[0,3] B)'
    corridor = work / "corridor.prism"  # the open constant written in, for stormpy
    text = CORRIDOR.read_text(encoding="utf-8")
    corridor.write_text(text.replace("const bool open_at_start;",
                                     "const bool open_at_start = true;"), encoding="utf-8")
    ours: dict[str, tuple[list[str], Any]] = {
        "ours": ([py, "-m", "mitld_lp", "solve", str(CASE), "--json", "-q"], _bracket),
        "version": ([py, "-m", "mitld_lp", "--version"], str.strip),
        "check": ([py, "-m", "mitld_lp", "check", formula, "-q"],
                  lambda out: out.strip().splitlines()[0][:40]),
        "ours_corridor": ([py, "-m", "mitld_lp", "solve", str(CORRIDOR), "--prop",
                           CORRIDOR_PROPERTY, "--const", "open_at_start=true", "--json", "-q"],
                          _bracket),
        "ours_corridor_law": ([py, "-m", "mitld_lp", "solve", str(CORRIDOR.with_suffix(".toml")),
                               "--json", "-q"], _bracket),
        "ours_corridor_program": ([py, "-c", PROGRAM, str(CORRIDOR.with_suffix(".toml"))],
                                  _bracket),
    }
    rows: dict[str, tuple[list[str], Path | None, Any]] = {
        name: (argv, None, read) for name, (argv, read) in ours.items()}
    if compare is not None:
        rows.update({f"{name}_base": (argv, compare, read)
                     for name, (argv, read) in ours.items()})
    number = lambda out: f"{float(out.strip()):.10f}"  # noqa: E731
    rows.update({
        "storm_prism": ([py, "-c", STORM_FILE, str(prism), 'Pmax=? [F "target"]'], None,
                        number),
        "storm_drn": ([py, "-c", STORM_DRN, str(drn)], None, number),
        "storm_corridor": ([py, "-c", STORM_FILE, str(corridor), CORRIDOR_PROPERTY], None,
                           number),
        "python": ([py, "-c", "pass"], None, lambda out: ""),
        "numpy_scipy_sparse": ([py, "-c", "import numpy, scipy.sparse"], None,
                               lambda out: ""),
        "stormpy_import": ([py, "-c", "import stormpy"], None, lambda out: ""),
    })
    return rows


def base_checkout(base: str, work: Path) -> Path:
    """The folder whose ``mitld_lp`` the ``*_base`` rows import: ``base`` itself when it
    is a folder, else this repository's ``mitld_lp`` at the commit ``base``."""
    if Path(base).is_dir():
        return Path(base)
    archive = subprocess.run(["git", "archive", "--format=tar", base, "mitld_lp"], cwd=ROOT,
                             capture_output=True, check=True).stdout
    folder = work / "base"
    folder.mkdir()
    archive_file = work / "base.tar"
    archive_file.write_bytes(archive)
    with tarfile.open(archive_file) as tar:
        tar.extractall(folder, filter="data")
    return folder


def measure(work: Path, repeats: int, compare: Path | None) -> dict[str, dict[str, Any]]:
    """Every command ``repeats`` times, taking turns; the CPU seconds of each run and
    the answer of the first (every run's answer must equal it)."""
    rows = commands(work, compare)
    for argv, code, _ in rows.values():  # warm-up: bytecode written, files cached
        run_cpu(argv, code)
    runs: dict[str, list[float]] = {name: [] for name in rows}
    answers: dict[str, str] = {}
    for _ in range(repeats):
        for name, (argv, code, read) in rows.items():
            cpu, out = run_cpu(argv, code)
            answer = read(out)
            if answers.setdefault(name, answer) != answer:
                raise RuntimeError(f"{name}: answer {answer} after {answers[name]}")
            runs[name].append(cpu)
    return {name: dict(answer=answers[name], runs=runs[name]) for name in rows}


def table(measured: dict[str, dict[str, Any]]) -> list[dict[str, Any]]:
    """One row per command: least and median CPU, and for ours (and its base) the
    median over rounds of its ratio to each stormpy script."""
    out = []
    for name, m in measured.items():
        row: dict[str, Any] = dict(command=name, answer=m["answer"], runs=len(m["runs"]),
                                   cpu_min=min(m["runs"]),
                                   cpu_median=statistics.median(m["runs"]))
        for storm in ("storm_prism", "storm_drn", "storm_corridor"):
            ratios = [a / b for a, b in zip(m["runs"], measured[storm]["runs"], strict=True)]
            row[f"over_{storm}"] = statistics.median(ratios)
        out.append(row)
    return out


def report(rows: list[dict[str, Any]], compare: str | None) -> str:
    header = ["command", "answer", "runs", "CPU min (s)", "CPU median (s)",
              "/ storm_prism", "/ storm_drn", "/ storm_corridor"]
    cells = [[r["command"], r["answer"], r["runs"], f"{r['cpu_min']:.3f}",
              f"{r['cpu_median']:.3f}", f"{r['over_storm_prism']:.2f}",
              f"{r['over_storm_drn']:.2f}", f"{r['over_storm_corridor']:.2f}"] for r in rows]
    ours = next(r for r in rows if r["command"] == "ours")
    got = ours["over_storm_prism"]
    verdict = (f"the case as a process is {got:.2f}x the stormpy script on the PRISM "
               f"encoding (median of the rounds' ratios): target <= {TARGET:g}x "
               + ("met" if got <= TARGET else f"missed by {got / TARGET:.2f}x"))
    corridor = next(r for r in rows if r["command"] == "ours_corridor")
    verdict += (f"; the corridor PRISM file with its property, "
                f"{corridor['over_storm_corridor']:.2f}x its stormpy script")
    lines = [_common.markdown_table(header, cells), verdict]
    if compare is not None:
        lines.append(f"`*_base` rows: the mitld_lp of {compare}")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> list[dict[str, Any]]:
    ap = _common.parser(__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=None,
                    help="rounds of every command (default 15, 2 with --quick)")
    ap.add_argument("--compare", default=None, metavar="BASE",
                    help="also run ours with this checkout's (a folder) or this commit's "
                         "mitld_lp (the base rows)")
    args = ap.parse_args(argv)
    out = _common.out_dir(args)
    repeats = args.repeats or (2 if args.quick else 15)
    with tempfile.TemporaryDirectory() as tmp:
        base = None if args.compare is None else base_checkout(args.compare, Path(tmp))
        measured = measure(Path(tmp), repeats, base)
    lower, upper = json.loads(measured["ours"]["answer"])
    corridor = json.loads(measured["ours_corridor"]["answer"])
    for storm, (lo, hi) in (("storm_prism", (lower, upper)), ("storm_drn", (lower, upper)),
                            ("storm_corridor", corridor)):  # Storm's precision: 1e-6
        value = float(measured[storm]["answer"])
        if not lo - 1e-6 <= value <= hi + 1e-6:
            raise RuntimeError(f"{storm}: {value} outside ours [{lo}, {hi}] +- 1e-6")
    rows = table(measured)
    text = report(rows, args.compare)
    print(text)
    _common.write_csv(out / "bench_startup.csv", list(rows[0]),
                      [list(r.values()) for r in rows])
    _common.write_text(out / "bench_startup.md", text)
    _common.write_text(out / "bench_startup_machine.txt",
                       f"{platform.platform()}; python {platform.python_version()}; "
                       f"{os.cpu_count()} cores; load average "
                       f"{' '.join(f'{x:.2f}' for x in os.getloadavg())} at the end\n")
    print(f"wrote {_common.shown(out / 'bench_startup.md')}")
    return rows


if __name__ == "__main__":
    main()
