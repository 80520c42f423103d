"""The fuzz campaign of issue 12: formulas, model files and command lines thrown at the
``mitld-lp`` command, every run in a worker process under a memory and a time limit.

What is run (each input through :func:`mitld_lp.cli.main`, as a user would type it):

* formulas: ``check FORMULA``; when the answer is "supported", every inline law
  ``D[family(args)]`` of the formula is also built (``distributions.from_spec``): a law
  ``check`` accepts but cannot be built is an *accepted invalid law*;
* model files: a bundled ``models/*.toml`` mutated (keys dropped, added, renamed to
  unicode and control characters, values of the wrong type, out of range, huge, nested
  hundreds of levels deep, the text cut or spliced), then ``info FILE --max-states N
  --time-limit T``;
* command lines: random arguments for every verb on tiny models, with output files that
  already exist (they must not change without ``--force``);
* the surfaces of issue 29 (:mod:`mitld_lp.testing.fuzz_surfaces`), each run in a fresh
  process whose peak memory (``ru_maxrss``) is compared with the ``--max-memory`` it was
  given: laws fitted to data files that are links to ``/dev/zero``, FIFOs, sparse 50 GB
  files, junk; models with 1-10 events whose laws are bands; sweeps whose results file is
  a device, a FIFO, under ``/proc``, or whose ``--dask`` is no address; two sweeps
  writing one results file at once, the first killed (SIGKILL, SIGINT, SIGTERM) at a
  random moment, then a third run to the end (the file must never hold a point twice or
  a cut line before the last); controller files truncated, flipped, forged, zip bombs,
  FIFOs; ``[python]`` worlds breaking the contract in 27 ways.

Each outcome is classified by the exit code (0 ok, 2 user error, 3 stop, 1 internal
error) or by how the worker ended (killed by a signal or the memory limit: crash; over
the time limit: timeout).  Independently of the code, every run is also checked for the
one-error-path promise: stderr lines are printable, an exit 2 says ``error:`` on exactly
one line, and no existing output file was overwritten without ``--force``.

The workers are started with ``resource.setrlimit(RLIMIT_AS, ...)`` (default 2 GB) in
``preexec_fn``; a worker that dies, times out, or leaves a command thread running (a
``--time-limit`` stop) is replaced before the next run.

Usage: ``python experiments/fuzz.py --quick`` (about 100 of each, 60 surface cases, into
the scratch folder ``experiments/out``); ``python experiments/fuzz.py`` (10,000 formulas,
2,000 model files, 500 command lines, 300 surface cases) writes
``experiments/results/fuzz.md``; ``--formulas N --models N --cli N --surfaces N`` choose
the counts.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import random
import re
import resource
import select
import subprocess
import sys
import threading
import time
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from mitld_lp.testing.fuzz import (
    CliFiles,
    base_documents,
    formula_text,
    law_problem,
    mutate_model,
    random_argv,
    run_main,
    stderr_problems,
)
from mitld_lp.testing.fuzz_surfaces import KINDS, SurfaceFiles, random_case, results_damage

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
MODELS = ROOT / "models"
SCRATCH = HERE / "out"
RESULTS = HERE / "results"
GRID_MODELS = ("bus_grid", "bus_grid_case2", "patrol", "red_light")
"""The bundled models the model-file campaign mutates."""


# --------------------------------------------------------------------------- one run


def run_one(item: dict[str, Any]) -> dict[str, Any]:
    """One run (in the worker): the exit code, the first error line, the problems."""
    files = CliFiles(Path(item["folder"])) if item["kind"] == "cli" else None
    if files is not None:
        files.prepare()
    code, _out, err = run_main(item["argv"])
    problems = stderr_problems(code, err)
    if item["kind"] == "formula" and code == 0:
        bad = law_problem(item["argv"][-1])
        if bad:
            problems.append(bad)
    if files is not None and "--force" not in item["argv"]:
        problems += [f"overwrote {n} without --force" for n in files.overwritten()]
    said = [line for line in err.splitlines() if "error:" in line or "stopped:" in line]
    return {"code": code, "said": said[-1][:300] if said else "", "problems": problems}


def worker() -> None:
    """Read one JSON item a line from stdin, answer one JSON line each on the original
    stdout (fd 1 itself goes to /dev/null: native solvers print there)."""
    proto = os.fdopen(os.dup(1), "w")
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)
    for line in sys.stdin:
        item = json.loads(line)
        try:
            answer = run_one(item)
        except BaseException as exc:  # noqa: BLE001 - reported as a crash, then we end
            answer = {"code": -1, "said": f"worker: {type(exc).__name__}: {exc}"[:300],
                      "problems": [], "dead": True}
        answer["dirty"] = threading.active_count() > 1  # a command thread still running
        proto.write(json.dumps(answer) + "\n")
        proto.flush()
        if answer.get("dirty") or answer.get("dead"):
            return


# --------------------------------------------------------------------------- the parent

OUTCOMES = ("ok (0)", "user error (2)", "budget stop (3)", "time limit (3)",
            "out of memory (3)", "internal error (1)", "crash", "timeout")
FINE = ("ok (0)", "user error (2)", "budget stop (3)")


def _outcome(code: int) -> str:
    return {0: "ok (0)", 2: "user error (2)", 3: "stop (3)", 1: "internal error (1)"}.get(
        code, "crash")


@dataclass
class Tally:
    """Counts of one campaign, and an example input for each kind of failure."""

    name: str
    outcomes: Counter[str] = field(default_factory=Counter)
    problems: Counter[str] = field(default_factory=Counter)
    examples: dict[str, str] = field(default_factory=dict)
    broken: int = 0
    seconds: float = 0.0

    def add(self, outcome: str, said: str, problems: Sequence[str], show: str) -> None:
        if outcome == "stop (3)":
            outcome = ("out of memory (3)" if "out of memory" in said else
                       "time limit (3)" if "time limit" in said else "budget stop (3)")
        self.outcomes[outcome] += 1
        self.broken += bool(problems)
        keys = [re.sub(r"(accepted invalid law \w+).*", r"\1(...)", p) for p in problems]
        if outcome not in FINE:
            keys.append(f"{outcome}: {_normalise(said)}")
        for key in keys:
            self.problems[key] += 1
            self.examples.setdefault(key, show)


def _normalise(said: str) -> str:
    """An error line without its numbers and quoted values, to group failures."""
    said = re.sub(r"'[^']*'|\"[^\"]*\"", "'…'", said)
    return re.sub(r"\d+(\.\d+)?(e[+-]?\d+)?", "N", said)[:160]


class Pool:
    """One worker process at a time, under RLIMIT_AS and a per-run time limit."""

    def __init__(self, memory: int, log: Path) -> None:
        self.memory = memory
        self.log = log
        self.proc: subprocess.Popen[str] | None = None

    def _limit(self) -> None:
        resource.setrlimit(resource.RLIMIT_AS, (self.memory, self.memory))

    def _start(self) -> subprocess.Popen[str]:
        env = dict(os.environ, PYTHONPATH=f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}",
                   OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MALLOC_ARENA_MAX="2")
        with self.log.open("a") as log:
            return subprocess.Popen(
                [sys.executable, str(Path(__file__).resolve()), "--worker"],
                stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=log, text=True,
                env=env, preexec_fn=self._limit,
            )

    def stop(self) -> None:
        if self.proc is not None:
            self.proc.kill()
            self.proc.wait()
            self.proc = None

    def run(self, item: dict[str, Any], seconds: float) -> dict[str, Any]:
        if self.proc is None:
            self.proc = self._start()
        proc = self.proc
        assert proc.stdin is not None and proc.stdout is not None
        try:
            proc.stdin.write(json.dumps(item) + "\n")
            proc.stdin.flush()
        except BrokenPipeError:
            pass
        ready, _, _ = select.select([proc.stdout], [], [], seconds)
        line = proc.stdout.readline() if ready else None
        if line is None:
            self.stop()
            return {"code": None, "outcome": "timeout", "said": f"over {seconds:g} s",
                    "problems": []}
        if not line:
            code = proc.wait()
            self.proc = None
            return {"code": None, "outcome": "crash", "said": f"worker ended with {code}",
                    "problems": []}
        answer = json.loads(line)
        answer["outcome"] = "crash" if answer.get("dead") else _outcome(answer["code"])
        if answer.get("dirty") or answer.get("dead"):
            self.stop()
        return answer


def _show(argv: list[str], model_text: str | None) -> str:
    text = " ".join(repr(a) if not re.fullmatch(r"[\w./:=,-]+", a) else a for a in argv)
    if model_text is not None:
        text += f"  with the file {model_text[:400]!r}"
    return text


def campaign(n_formulas: int, n_models: int, n_cli: int, seed: int, folder: Path,
             memory: int, progress: bool = True) -> list[Tally]:
    """Run the three campaigns; return their tallies."""
    rng = random.Random(seed)
    folder.mkdir(parents=True, exist_ok=True)
    pool = Pool(memory, folder / "workers.log")
    docs = base_documents(MODELS / f"{name}.toml" for name in GRID_MODELS)
    tallies = []
    try:
        for name, n, seconds in (("formulas", n_formulas, 30.0), ("model files", n_models, 30.0),
                                 ("command lines", n_cli, 60.0)):
            tally = Tally(name)
            t0 = time.perf_counter()
            for i in range(n):
                model_text = None
                if name == "formulas":
                    text = formula_text(rng)
                    item = {"kind": "formula", "argv": ["check", "--", text]}
                elif name == "model files":
                    base = rng.choice(sorted(docs))
                    model_text = mutate_model(rng, docs[base])
                    path = folder / "model.toml"
                    path.write_text(model_text, encoding="utf-8")
                    item = {"kind": "model", "argv": ["info", str(path), "--max-states", "20000",
                                                      "--time-limit", "5"]}
                else:
                    cli = folder / "cli"
                    item = {"kind": "cli", "argv": random_argv(rng, cli), "folder": str(cli)}
                answer = pool.run(item, seconds)
                tally.add(answer["outcome"], answer.get("said", ""), answer.get("problems", []),
                          _show(item["argv"], model_text))
                if progress and (i + 1) % max(1, n // 10) == 0:
                    print(f"  {name}: {i + 1}/{n}", file=sys.stderr, flush=True)
            tally.seconds = time.perf_counter() - t0
            tallies.append(tally)
    finally:
        pool.stop()
    return tallies


# --------------------------------------------------------------------------- the surfaces

ALLOWANCE = 128 << 20
"""Bytes a run may spend above the base beyond 1.5 x its --max-memory: the stages the
budget does not govern (the automaton, bounded by --max-automaton-states; the modules
a fit imports, scipy.stats and scipy.optimize, which the base's tiny solve does not)."""

SURFACE_OUTCOMES = ("ok (0)", "user error (2)", "budget stop (3)", "interrupted (130)",
                    "killed (by the campaign)", "internal error (1)", "crash", "timeout",
                    "over budget", "damaged file")


@dataclass
class SurfaceTally:
    """Counts of the surface campaign, per kind of case."""

    outcomes: dict[str, Counter[str]] = field(default_factory=dict)
    problems: Counter[str] = field(default_factory=Counter)
    examples: dict[str, str] = field(default_factory=dict)
    peak: dict[str, float] = field(default_factory=dict)  # per kind: most MB above base
    seconds: float = 0.0

    def add(self, kind: str, outcome: str, key: str | None, show: str) -> None:
        self.outcomes.setdefault(kind, Counter())[outcome] += 1
        if key is not None:
            self.problems[f"{kind}: {key}"] += 1
            self.examples.setdefault(f"{kind}: {key}", show)


def _spawn(argv: list[str], python: str | None, cwd: Path, memory: int) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}",
               OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MALLOC_ARENA_MAX="2")
    cmd = [sys.executable, "-c", python] if python else [sys.executable, "-m", "mitld_lp",
                                                          *argv]

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (memory, memory))

    return subprocess.Popen(cmd, cwd=cwd, env=env, stdin=subprocess.DEVNULL,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                            preexec_fn=limit)


def _reap(proc: subprocess.Popen, seconds: float,
          kill: tuple[int, float] | None = None) -> tuple[int | None, str, float]:
    """Wait for ``proc`` (``kill``: send that signal after so many seconds): its exit
    code (None: over ``seconds``, killed), its stderr and its peak RSS in MB."""
    t0 = time.monotonic()
    err_chunks: list[str] = []
    reader = threading.Thread(target=lambda: err_chunks.append(proc.stderr.read()),
                              daemon=True)
    reader.start()
    sent = False
    while True:
        pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
        if pid:
            proc.returncode = os.waitstatus_to_exitcode(status)
            reader.join(5)
            return proc.returncode, "".join(err_chunks), usage.ru_maxrss / 1024
        now = time.monotonic() - t0
        if kill is not None and not sent and now >= kill[1]:
            proc.send_signal(kill[0])
            sent = True
        if now > seconds:
            proc.kill()
            _, status, usage = os.wait4(proc.pid, 0)
            reader.join(5)
            return None, "".join(err_chunks), usage.ru_maxrss / 1024
        time.sleep(0.02)


def _surface_outcome(code: int | None, killed: bool = False) -> str:
    if code is None:
        return "timeout"
    if killed and code in (-9, -15, 130, -2):
        return "killed (by the campaign)"
    return {0: "ok (0)", 2: "user error (2)", 3: "budget stop (3)", 130: "interrupted (130)",
            1: "internal error (1)"}.get(code, "crash")


def surfaces(n: int, seed: int, folder: Path, memory: int, progress: bool = True
             ) -> SurfaceTally:
    """Run ``n`` surface cases (module docstring), each in a fresh process."""
    rng = random.Random(seed)
    files = SurfaceFiles(folder / "surfaces")
    files.prepare()
    tally = SurfaceTally()
    t0 = time.perf_counter()
    # the base: the peak of a tiny solve, what importing and solving cost before any budget
    _, _, base = _reap(_spawn(["solve", str(files.folder / "tiny.toml"), "-q"], None,
                              files.folder, memory), 120)
    kinds = [KINDS[i % len(KINDS)] for i in range(n)]
    rng.shuffle(kinds)
    for i, kind in enumerate(kinds):
        case = random_case(rng, files, kind)
        first = _spawn(case.argv, case.python, files.folder, memory)
        kill = (case.kill, case.kill_after) if case.kill else None
        twin = None
        if case.twin is not None:
            time.sleep(case.twin_delay)
            twin = _spawn(case.twin, None, files.folder, memory)
        code, err, peak = _reap(first, 180, kill)
        runs = [(code, err, peak, kill is not None)]
        if twin is not None:
            runs.append((*_reap(twin, 180), False))
        problems = []
        for c, e, pk, killed in runs:
            outcome = _surface_outcome(c, killed)
            tally.peak[kind] = max(tally.peak.get(kind, 0.0), pk - base)
            key = None
            if outcome in ("internal error (1)", "crash", "timeout"):
                key = f"{outcome}: {_normalise(_said(e))}"
            elif c == 3 and "out of memory" in e:
                outcome, key = "over budget", "a MemoryError under the worker's limit"
            elif case.max_memory is not None and (pk - base) * 2**20 > (
                    1.5 * case.max_memory + ALLOWANCE):
                outcome, key = "over budget", (f"{pk - base:.0f} MB above the base under "
                                               f"--max-memory {case.max_memory >> 20} MB")
            elif c == 2 and sum("error:" in line for line in e.splitlines()) != 1:
                key = "exit 2 without exactly one error line"
            tally.add(kind, outcome, key, case.show + (f" -> {_said(e)}" if key else ""))
            problems.append(key)
        if case.results is not None:
            damage = results_damage(case.results)
            if not damage:  # a third run to the end: every point once
                c, e, _ = _reap(_spawn(case.argv, None, files.folder, memory), 180)
                damage = results_damage(case.results)
                if c not in (0, 3) and not damage:
                    damage = [f"the run after them ended with {c}: {_said(e)}"]
            if damage:
                tally.add(kind, "damaged file", "; ".join(damage), case.show)
        if progress and (i + 1) % max(1, n // 10) == 0:
            print(f"  surfaces: {i + 1}/{n}", file=sys.stderr, flush=True)
    tally.seconds = time.perf_counter() - t0
    return tally


def _said(err: str) -> str:
    lines = [line for line in err.splitlines() if line.strip()]
    said = [line for line in lines if "error" in line or "stopped" in line]
    return (said or lines or [""])[-1][:300]


def surface_report(t: SurfaceTally) -> list[str]:
    lines = ["", "## The surfaces of issue 29", "",
             "| kind | runs | " + " | ".join(SURFACE_OUTCOMES) + " | peak MB above base |",
             "|---|---:|" + "---:|" * len(SURFACE_OUTCOMES) + "---:|"]
    for kind in KINDS:
        c = t.outcomes.get(kind, Counter())
        lines.append(f"| {kind} | {sum(c.values())} | "
                     + " | ".join(str(c[o]) for o in SURFACE_OUTCOMES)
                     + f" | {t.peak.get(kind, 0.0):.0f} |")
    lines += ["", "Each case runs in a fresh process under the worker's memory limit. *over "
              "budget*: a run that ran out of memory, or whose peak RSS above the base (a "
              "tiny solve) exceeded 1.5 times the `--max-memory` it was given plus "
              f"{ALLOWANCE >> 20} MB for the stages that budget does not govern (the "
              "automaton, bounded by `--max-automaton-states`; the modules a fit imports). "
              "*peak MB above base*: the largest of the kind. *damaged file*: after two sweeps "
              "wrote one results file at once (the first perhaps killed) and a third ran to "
              "the end, a point twice, a cut line before the last, or more rows than "
              "points. A run killed by the campaign is not a crash. "
              f"{t.seconds:.0f} s in all.", "", "### Failures, grouped", ""]
    for key, count in t.problems.most_common():
        lines.append(f"- {count}x: {key}  \n  e.g. `{t.examples[key][:400]}`")
    if not t.problems:
        lines.append("none")
    return lines


def report(tallies: list[Tally], args: argparse.Namespace, seconds: float,
           surface: SurfaceTally | None = None) -> str:
    """The summary table and the failures, as Markdown."""
    lines = [
        "# Fuzz campaign (experiments/fuzz.py)",
        "",
        f"Date: {datetime.now(UTC).strftime('%Y-%m-%d %H:%M UTC')}; machine: {platform.node()}"
        f" ({platform.machine()}, {os.cpu_count()} cores, {platform.system()} "
        f"{platform.release()}), Python {platform.python_version()}; seed {args.seed}; "
        f"memory limit {args.memory_gb:g} GB a worker; {seconds:.0f} s in all.",
        "",
        "Command: `python experiments/fuzz.py " + " ".join(sys.argv[1:]) + "`",
        "",
        "| campaign | runs | " + " | ".join(OUTCOMES) + " | promise broken | seconds |",
        "|---|---:|" + "---:|" * len(OUTCOMES) + "---:|---:|",
    ]
    for t in tallies:
        lines.append(f"| {t.name} | {sum(t.outcomes.values())} | "
                     + " | ".join(str(t.outcomes[o]) for o in OUTCOMES)
                     + f" | {t.broken} | {t.seconds:.0f} |")
    lines += ["", "Exit 3 is split by what stopped the run: a budget checked in time "
              "(`--max-states`), the time limit (model files run with `--max-states 20000 "
              "--time-limit 5`), or "
              "a `MemoryError` under the worker's memory limit (a budget that acted too "
              "late). *crash*: the worker died (signal, or memory exhausted outside Python); "
              "*timeout*: no answer within 30 s (60 s for command lines). *promise broken*: runs "
              "whose exit code was fine but that broke the one-error-path promise (a "
              "non-printable or missing error line, an invalid inline law `check` calls "
              "supported, an output file overwritten without `--force`).",
              "", "## Failures, grouped", ""]
    any_failure = False
    for t in tallies:
        for key, count in t.problems.most_common():
            any_failure = True
            lines.append(f"- {t.name}, {count}x: {key}  \n  e.g. `{t.examples[key][:500]}`")
    if not any_failure:
        lines.append("none")
    if surface is not None:
        lines += surface_report(surface)
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> list[Tally]:
    ap = argparse.ArgumentParser(description="The fuzz campaign of issue 12 (see the module "
                                 "docstring).")
    ap.add_argument("--quick", action="store_true", help="about 100 of each, scratch folder")
    ap.add_argument("--out", type=Path, help="folder for fuzz.md (default: experiments/results,"
                    " or the scratch folder experiments/out with --quick)")
    ap.add_argument("--formulas", type=int)
    ap.add_argument("--models", type=int)
    ap.add_argument("--cli", type=int)
    ap.add_argument("--surfaces", type=int)
    ap.add_argument("--seed", type=int, default=12)
    ap.add_argument("--memory-gb", type=float, default=2.0)
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        worker()
        return []
    full = (10_000, 2_000, 500) if not args.quick else (100, 100, 100)
    counts = [given if given is not None else default for given, default in
              zip((args.formulas, args.models, args.cli), full, strict=True)]
    out = args.out or (SCRATCH if args.quick else RESULTS)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    tallies = campaign(*counts, seed=args.seed, folder=SCRATCH / "fuzz",
                       memory=int(args.memory_gb * 2**30))
    n_surfaces = args.surfaces if args.surfaces is not None else (60 if args.quick else 300)
    surface = surfaces(n_surfaces, args.seed, SCRATCH / "fuzz", int(args.memory_gb * 2**30))
    text = report(tallies, args, time.perf_counter() - t0, surface)
    print(text)
    path = out / "fuzz.md"
    path.write_text(text, encoding="utf-8")
    print(f"wrote {path}", file=sys.stderr)
    return tallies


if __name__ == "__main__":
    main()
