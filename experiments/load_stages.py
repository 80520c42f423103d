"""The PRISM load split into its stages, beside Storm's own build, in CPU seconds and MB.

Per QVBS instance (posed as ``bench_qvbs.py`` poses it; default the five of the issue's
table), in a fresh process per checkout:

* ``imports``: ``import stormpy`` and the package's PRISM loader (``mitld_lp.load_model``
  and ``mitld_lp.worlds.prism``), which ``bench_qvbs``'s ``load_cpu`` counts and its
  ``storm_build_cpu`` does not (Storm's script imports stormpy before its clock starts);
* ``load``: ``mitld_lp.load_model`` whole, as the benchmark runs it (Storm's exploration in
  the memory-capped child where the budgets ask for one; its CPU counted);
* the same load in a fresh process with the build in it, each stage timed where it runs:
  ``parse`` (stormpy's parse of the file, the labels added, the constants given, the
  program's checks), ``storm_ours`` (Storm's build with the load's options:
  ``prism_build.storm_build``), ``convert`` (Storm's model copied into our arrays,
  ``prism_tables.read_model``: the UMB export and its read, the labels, the rows'
  checks), or, where the own explorer builds (``own``: ``prism_build.own_build``), inside
  it ``explore`` (the kernel and its arrays), ``own_compile`` (the program compiled to
  bytecode), ``own_names`` (the choices' names), ``own_rows`` (the rows' check and
  normalisation) and ``own_labels`` (the labels' flags); ``spec`` (the spec's parse) and
  ``else`` (the rest: the task's decided states, the game);
* ``storm_ref``: Storm's build as ``bench_qvbs``'s reference run makes it,
  ``stormpy.build_model(program, [prop])`` (the property's labels, no valuations, no
  choice labels), its parse apart (``ref_parse``).

Each stage's peak is the resident size's high-water mark while it runs over the size
when it starts (``*_mb``; reset through ``/proc/self/clear_refs``; Storm's reference in
a process of its own, so that it reuses no heap our load freed); ``child_peak_mb`` the
capped child's whole peak (0: the budgets asked for no child); ``process_peak_mb`` the
whole process's peak after the load as the benchmark runs it (imports included).  The
answer beside the times: the states and transitions of our world and of Storm's
reference build (ours stops where the task is decided, as the reference stops where its
property is).

    python experiments/load_stages.py --qvbs /work/shared/qvbs --compare /tmp/base
    python experiments/load_stages.py --quick --qvbs /work/shared/qvbs
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

import _common  # noqa: E402

ROOT = HERE.parent

FIVE = ("consensus.4-4.c2", "zeroconf_dl.1000-1-false-30.deadline_max",
        "firewire_dl.3-600.deadline", "zeroconf.1000-4-false.correct_max",
        "csma.4-2.some_before")
QUICK = ("consensus.4-4.c2",)

HELPERS = r"""
import functools, json, re, resource, sys

def cpu():
    u, c = (resource.getrusage(w) for w in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN))
    return u.ru_utime + u.ru_stime + c.ru_utime + c.ru_stime

def rss_mb():
    with open("/proc/self/status") as f:
        return {k: int(v.split()[0]) / 1024 for k, v in
                (line.split(":", 1) for line in f) if k in ("VmRSS", "VmHWM")}

def reset_peak():
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
    except OSError:
        pass

"""

PROBE = HELPERS + r"""
job = json.loads(sys.argv[1])
c = cpu()
import stormpy
stormpy_import = cpu() - c
c = cpu()
from mitld_lp import load_model
from mitld_lp.worlds import prism as pr, prism_build as pb
import stormpy.io
ours_import = cpu() - c

def load():
    c = cpu()
    model = load_model(job["model"], max_states=job["max_states"])
    return model, cpu() - c

out = dict(stormpy_import=stormpy_import, ours_import=ours_import)
if sys.argv[2] == "whole":  # the load as the benchmark runs it, first in its process
    _, out["load"] = load()
    out["process_peak_mb"] = rss_mb()["VmHWM"]
    out["child_peak_mb"] = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    print(json.dumps(out))
    sys.exit(0)

# the load with every stage in this process, each timed and its peak taken
stages = {}
def timed(module, name, label):
    f = getattr(module, name)
    @functools.wraps(f)
    def run(*a, **k):
        before = rss_mb()["VmRSS"]
        reset_peak()
        c = cpu()
        try:
            return f(*a, **k)
        finally:
            spent = cpu() - c
            s = stages.setdefault(label, [0.0, 0.0])
            s[0] += spent
            s[1] = max(s[1], rss_mb()["VmHWM"] - before)
    setattr(module, name, run)

pb.can_cap = lambda: False
from mitld_lp.worlds import prism_program as pp  # (where the parse runs since proc-lean)
from mitld_lp.worlds import prism_explore as pe
from mitld_lp import game_tables as gt
for module, name, label in ((pr, "parse_program", "parse"), (pr, "with_labels", "parse"),
                            (pp, "parse_program", "parse"), (pp, "with_labels", "parse"),
                            (pr, "with_constants", "parse"), (pr, "check_program", "parse"),
                            (pb, "storm_build", "storm_ours"), (pb, "read_model", "convert"),
                            (pb, "own_build", "own"), (pr, "own_build", "own"),
                            (pe, "explore_program", "explore"),
                            (pe, "label_values", "own_labels"),
                            (pe, "compile_program", "own_compile"),
                            (pe, "_naming", "own_names"), (pe, "checked_rows", "own_rows"),
                            (pe, "normalise_rows", "own_rows"), (gt, "parse_spec", "spec")):
    if hasattr(module, name):  # (a name prism.py no longer imports: its module's)
        timed(module, name, label)
model, here = load()
t = model.game._tables
out.update(here=here, states=len(t.states), transitions=int(t.targets.size),
           props=len(model.game.proposition_names))
for label, (spent, peak) in stages.items():
    out[label], out[label + "_mb"] = spent, peak
NESTED = ("explore", "own_labels", "own_compile", "own_names", "own_rows")  # inside "own"
out["else"] = here - sum(v[0] for k, v in stages.items() if k not in NESTED)
print(json.dumps(out))
"""

REFERENCE = HELPERS + r"""
job = json.loads(sys.argv[1])
import stormpy
out = {}
before = rss_mb()["VmRSS"]
reset_peak()
c = cpu()
program = stormpy.parse_prism_program(job["prism"])
undefined = {k.name for k in program.constants if not k.defined}
given = {k: v for k, v in job["constants"].items() if k in undefined}
if given:
    program, _ = stormpy.instantiate_constants(program, given)
text = job["property"]
for name, value in job["constants"].items():
    if name not in undefined:
        shown = str(value).lower() if isinstance(value, bool) else str(value)
        text = re.sub(rf"(?<![\w\"]){re.escape(name)}(?![\w\"])", shown, text)
prop = stormpy.parse_properties(text, program)[0]
out["ref_parse"] = cpu() - c
c = cpu()
ref = stormpy.build_model(program, [prop])
out["storm_ref"] = cpu() - c
out["storm_ref_mb"] = rss_mb()["VmHWM"] - before
out["ref_states"], out["ref_transitions"] = ref.nr_states, ref.nr_transitions
print(json.dumps(out))
"""

COLUMNS = ("states", "transitions", "props", "ref_states", "stormpy_import", "ours_import",
           "load", "here", "parse", "spec", "storm_ours", "storm_ref", "convert", "own",
           "explore", "own_compile", "own_names", "own_rows", "own_labels", "else",
           "ref_parse", "storm_ours_mb", "storm_ref_mb", "convert_mb", "own_mb", "explore_mb",
           "child_peak_mb", "process_peak_mb")


def probe(job: dict, root: Path, code: str = PROBE, mode: str = "stages") -> dict:
    """One fresh process of the checkout ``root`` running ``code`` on ``job``."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPATH"] = str(root)
    out = subprocess.run([sys.executable, "-c", code, json.dumps(job), mode], cwd="/tmp", env=env,
                         capture_output=True, text=True, timeout=3600)
    if out.returncode:
        raise SystemExit(f"{job['model']}: the probe failed:\n{out.stderr[-2000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> list[list[object]]:
    import bench_qvbs

    p = _common.parser(__doc__.splitlines()[0])
    p.add_argument("--qvbs", type=Path, required=True, help="the benchmarks/ folder of QVBS")
    p.add_argument("--only", nargs="+", default=None, help=f"instances (default {FIVE})")
    p.add_argument("--repeats", type=int, default=1, help="runs of each, the least kept")
    p.add_argument("--compare", type=Path, default=None, metavar="DIR",
                   help="also the checkout DIR's package (before), taking turns with this one's")
    args = p.parse_args(argv)
    out = _common.out_dir(args)
    names = tuple(args.only or (QUICK if args.quick else FIVE))
    work = out / "load_stages_models"
    work.mkdir(parents=True, exist_ok=True)
    found, _ = bench_qvbs.jobs(args.qvbs, 0, 2_000_000, tuple(bench_qvbs.FAMILIES), work)
    jobs = {inst.name: job for inst, job in found if inst.name in names}
    missing = [n for n in names if n not in jobs]
    if missing:
        raise SystemExit(f"not found under {args.qvbs}: {', '.join(missing)}")
    roots = [("before", args.compare.resolve()), ("after", ROOT)] if args.compare else [
        ("this", ROOT)]
    header = ["instance", "checkout", *COLUMNS]
    rows: list[list[object]] = []
    for name in names:
        runs: dict[str, list[dict]] = {r: [] for r, _ in roots}
        for _ in range(args.repeats):
            ref = probe(jobs[name], ROOT, REFERENCE)  # Storm alone: no checkout's package
            for label, root in roots:
                whole = probe(jobs[name], root, mode="whole")
                runs[label].append(dict(probe(jobs[name], root), **ref, load=whole["load"],
                                        child_peak_mb=whole["child_peak_mb"],
                                        process_peak_mb=whole["process_peak_mb"]))
        sizes = {(r["states"], r["transitions"]) for rs in runs.values() for r in rs}
        if len(sizes) != 1:
            raise SystemExit(f"{name}: the checkouts load other worlds: {sorted(sizes)}")
        for label, _ in roots:
            best = {k: min(r.get(k, 0.0) for r in runs[label]) for k in COLUMNS}
            row = [name, label, *(round(best[k], 4) if isinstance(best[k], float) else best[k]
                                  for k in COLUMNS)]
            rows.append(row)
            print("  ".join(f"{k}={v}" for k, v in zip(header, row, strict=True)), flush=True)
    _common.write_tables(out, "load_stages", header, rows)
    return rows


if __name__ == "__main__":
    main()
