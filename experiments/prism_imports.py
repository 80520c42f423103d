"""What the PRISM route imports, and the CPU each import costs, in a fresh interpreter.

``python -X importtime`` reports wall-clock microseconds, which on a loaded machine are
mostly other processes' time.  Here each module's import is timed in CPU seconds (a
hook on the import system's loader step; a module's own time is its import less the
imports it starts), in a fresh interpreter that solves a PRISM model file the way the
benchmark's worker does (``load_model`` then ``synthesize``), started as a program
importing the package (as imported; with its imports exactly as Python makes them,
``plain``; having asked for :mod:`mitld_lp.library_start`, ``hooked``) and as the command
line starts (``mitld_lp.startup.lean_start``, the collector held while importing).
Printed per start: the answer, the CPU of the whole process, of every import, and of
each top-level package's modules (the package's own by subpackage), the least over
``--repeats`` runs; and the package's modules (not its packages' ``__init__``) no
function of which ran in this process (:mod:`cProfile` over the route, a run of its own;
a PRISM world explored in the memory-capped child runs the copy of Storm's model there,
which this process does not see). The process's CPU includes that child's.

    python experiments/prism_imports.py                       # models/corridor.toml
    python experiments/prism_imports.py --model /tmp/jobs/consensus.4-4.c2.toml
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
import sys, time, importlib._bootstrap as bs
cpu = time.process_time
stack, own = [], {}
load = bs._load_unlocked
def timed(spec):
    stack.append([cpu(), 0.0])
    try:
        return load(spec)
    finally:
        start, inner = stack.pop()
        total = cpu() - start
        own[spec.name] = total - inner
        if stack:
            stack[-1][1] += total
bs._load_unlocked = timed
profile = sys.argv[3] == "profile"
if sys.argv[2] == "command":
    import gc
    from mitld_lp import startup
    gc.disable()
    startup.lean_start()
if sys.argv[2] == "hooked":
    from mitld_lp import library_start
    library_start.install()
from mitld_lp import load_model, synthesize
if sys.argv[2] == "command":
    gc.freeze(); gc.enable()
if profile:
    import cProfile, pstats
    p = cProfile.Profile(); p.enable()
r = synthesize(load_model(sys.argv[1]))
called = []
if profile:
    p.disable()
    files = {k[0] for k in pstats.Stats(p).stats if k[2] != "<module>"}
    called = sorted(n for n, m in sys.modules.items() if n.startswith("mitld_lp")
                    and getattr(m, "__file__", None) and m.__file__ not in files
                    and not m.__file__.endswith("__init__.py"))
import json, resource
u, c = (resource.getrusage(who) for who in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN))
print(json.dumps(dict(lower=r.lower, upper=r.upper,
                      process=u.ru_utime + u.ru_stime + c.ru_utime + c.ru_stime,
                      own=own, unused=called)))
"""


#: The starts measured: ``plain``, a program importing the package with the imports
#: exactly as Python makes them (``MITLD_LP_PLAIN_IMPORTS=1``: without
#: :mod:`mitld_lp.own_imports`, the library start before it); ``library``, a program
#: importing the package; ``hooked``, a program that asks for
#: :func:`mitld_lp.library_start.install` first; ``command``, the command line's start.
STARTS = ("plain", "library", "hooked", "command")


def run(model: Path, start: str, profile: bool) -> dict:
    env = {"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"}
    if start == "plain":
        env["MITLD_LP_PLAIN_IMPORTS"] = "1"
    out = subprocess.run([sys.executable, "-c", PROBE, str(model), start,
                          "profile" if profile else "time"], cwd=ROOT, env=env,
                         capture_output=True, text=True, check=True, timeout=1800)
    return json.loads(out.stdout.strip().splitlines()[-1])


def group(name: str) -> str:
    parts = name.split(".")
    return ".".join(parts[:2]) if parts[0] == "mitld_lp" else parts[0]


def main(argv: list[str] | None = None) -> list[list[object]]:
    p = _common.parser(__doc__.splitlines()[0])
    p.add_argument("--model", type=Path, default=ROOT / "models" / "corridor.toml")
    p.add_argument("--repeats", type=int, default=None,
                   help="runs per start (default 3, 1 with --quick)")
    p.add_argument("--top", type=int, default=14, help="groups shown per start")
    args = p.parse_args(argv)
    repeats = args.repeats or (1 if args.quick else 3)
    rows: list[list[object]] = []
    for start in STARTS:
        runs = [run(args.model, start, False) for _ in range(repeats)]
        best = min(runs, key=lambda r: r["process"])
        groups: dict[str, float] = {}
        for name, seconds in best["own"].items():
            groups[group(name)] = groups.get(group(name), 0.0) + seconds
        imports = sum(best["own"].values())
        answer = f"[{best['lower']:.10g}, {best['upper']:.10g}]"
        print(f"{start}: answer {answer}, process {best['process']:.3f} s CPU, imports "
              f"{imports:.3f} s ({len(best['own'])} modules), package's own "
              f"{sum(v for k, v in best['own'].items() if k.startswith('mitld_lp')):.3f} s")
        rows.append([start, "(process)", round(best["process"], 4), answer])
        rows.append([start, "(imports)", round(imports, 4), answer])
        for name, seconds in sorted(groups.items(), key=lambda kv: -kv[1])[: args.top]:
            print(f"    {seconds:.4f}  {name}")
            rows.append([start, name, round(seconds, 4), answer])
        unused = run(args.model, start, True)["unused"]
        print("    package modules imported with no function run: "
              f"{', '.join(unused) or 'none'}")
        rows.append([start, "(unused package modules)", len(unused), " ".join(unused)])
    out = _common.out_dir(args)
    header = ["start", "imported", "cpu_s", "answer"]
    rows.append(["model", str(args.model), repeats, "runs per start (the least shown)"])
    _common.write_tables(out, "prism_imports", header, rows)
    return rows


if __name__ == "__main__":
    main()
