"""What the PRISM load spends beside Storm's build, step by step, in CPU seconds.

For each model file (a ``[prism]`` world, as ``bench_qvbs.py`` writes them), in fresh
processes, the load (``mitld_lp.load_model``) timed whole, once with Storm's exploration
in the memory-capped child as the budgets ask (``capped``: this process and the child)
and once with the build in this process (``here``), the steps of the latter timed apart
(each function's CPU while it runs): Storm's build of the world (``storm_build``), the
variables and the initial state's values (``head``: read from Storm's program, or its
build of the initial state alone where the program has an ``init`` block), the copy of
Storm's model into arrays (``read_model``: the UMB export and its read, the labels, the
checks of every distribution; inside it, timed apart: Storm's export ``umb_export``, the
archive's headers ``umb_members``, the rows' check ``checked_rows``, the state and choice
labels, the states of one of Storm's labels read for the decided, deadlock and
out-of-bounds states ``label_states``), the spec's parse, the PRISM file's parse and the
labels added to it, the program's checks; and in the capped load, the parent's copy of the
arrays the child sends (``child_receive``); apart, stormpy's import before the load
(``stormpy_import``, which the load does not count here and the benchmark's ``load_cpu``
does: Storm's ``storm_build_cpu`` leaves it out).  The answer printed beside: the
world's states and transitions.  The least over ``--repeats`` runs of each.
``--compare DIR``: the same for the package of the checkout DIR (before), the two taking
turns, a row each.

    python experiments/load_steps.py /tmp/jobs/zeroconf_dl.1000-1-false-30.deadline_max.toml
    python experiments/load_steps.py --compare /tmp/base --repeats 5 /tmp/jobs/*.toml
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
import functools, json, resource, sys, time
c = time.process_time()
import stormpy
stormpy_import = time.process_time() - c
from mitld_lp import load_model
from mitld_lp import game_tables as gt
from mitld_lp.worlds import prism as pr, prism_build as pb
def cpu():
    u, c = (resource.getrusage(w) for w in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN))
    return u.ru_utime + u.ru_stime + c.ru_utime + c.ru_stime
steps = {}
def timed(module, name, label):
    f = getattr(module, name, None)
    if f is None:  # an older checkout (--compare) without this step
        return
    @functools.wraps(f)
    def run(*a, **k):
        c = time.process_time()
        try:
            return f(*a, **k)
        finally:
            steps[label] = steps.get(label, 0.0) + time.process_time() - c
    setattr(module, name, run)
import stormpy.io
from mitld_lp.worlds import prism_bounded as pbd, prism_tables as pt
from mitld_lp.worlds import prism_program as pp
here = sys.argv[2] == "here"
if here:
    pb.can_cap = lambda: False
    for module, name, label in ((pb, "storm_build", "storm_build"), (pb, "head", "head"),
                                (pb, "program_head", "head"),
                                (pb, "read_model", "read_model"),
                                (gt, "parse_spec", "parse_spec"),
                                (pr, "parse_program", "parse_program"),
                                (pr, "with_labels", "with_labels"),
                                (pp, "parse_program", "parse_program"),
                                (pp, "with_labels", "with_labels"),
                                (pr, "check_program", "check_program"),
                                # inside read_model:
                                (stormpy.io, "export_to_umb", "umb_export"),
                                (pt, "archive_members", "umb_members"),
                                (pt, "checked_rows", "checked_rows"),
                                (pt, "state_labels", "state_labels"),
                                (pt, "label_states", "label_states"),
                                (pt, "choice_labels", "choice_labels")):
        timed(module, name, label)
else:  # the parent's side of the capped child: the model's arrays received
    timed(pbd, "_receive", "child_receive")
c = cpu()
model = load_model(sys.argv[1], max_states=2_000_000)
load = cpu() - c
t = model.game._tables
steps["stormpy_import"] = stormpy_import  # before the load: not in it
print(json.dumps(dict(load=load, steps=steps, states=len(t.states),
                      transitions=int(t.targets.size))))
"""


def run(model: Path, where: str, root: Path = ROOT) -> dict:
    env = {"PYTHONPATH": str(root), "PATH": "/usr/bin:/bin"}
    out = subprocess.run([sys.executable, "-c", PROBE, str(model), where], cwd=root, env=env,
                         capture_output=True, text=True, check=True, timeout=3600)
    return json.loads(out.stdout.strip().splitlines()[-1])


STEPS = ("storm_build", "head", "read_model", "parse_spec", "parse_program", "with_labels",
         "check_program")
INSIDE = ("umb_export", "umb_members", "checked_rows", "state_labels", "label_states",
          "choice_labels")
"""Steps inside ``read_model`` (in its time already, not in ``rest``)."""


def main(argv: list[str] | None = None) -> list[list[object]]:
    p = _common.parser(__doc__.splitlines()[0])
    p.add_argument("models", type=Path, nargs="+", help="model files with a [prism] world")
    p.add_argument("--repeats", type=int, default=None, help="runs of each (default 3)")
    p.add_argument("--compare", type=Path, default=None, metavar="DIR",
                   help="also the checkout DIR's package (before), taking turns with this "
                   "one's, a row each; the same states and transitions are checked")
    args = p.parse_args(argv)
    repeats = args.repeats or (1 if args.quick else 3)
    header = ["model", "checkout", "states", "transitions", "capped", "here", *STEPS, "rest",
              *INSIDE, "child_receive", "stormpy_import"]
    roots = [("before", args.compare.resolve()), ("after", ROOT)] if args.compare else [
        ("this", ROOT)]
    rows: list[list[object]] = []
    for model in args.models:
        capped: dict[str, list[dict]] = {name: [] for name, _ in roots}
        here: dict[str, list[dict]] = {name: [] for name, _ in roots}
        for _ in range(repeats):  # taking turns
            for name, root in roots:
                capped[name].append(run(model, "capped", root))
                here[name].append(run(model, "here", root))
        sizes = {(r["states"], r["transitions"]) for name, _ in roots
                 for r in capped[name] + here[name]}
        if len(sizes) != 1:
            raise SystemExit(f"{model}: the checkouts load other worlds: {sorted(sizes)}")
        for name, _ in roots:
            best = min(here[name], key=lambda r: r["load"])
            steps = [round(min(r["steps"].get(s, 0.0) for r in here[name]), 4) for s in STEPS]
            rest = best["load"] - sum(best["steps"].get(s, 0.0) for s in STEPS)
            inside = [round(min(r["steps"].get(s, 0.0) for r in here[name]), 4)
                      for s in INSIDE]
            receive = round(min(r["steps"].get("child_receive", 0.0) for r in capped[name]), 4)
            imported = round(min(r["steps"]["stormpy_import"] for r in capped[name]
                                 + here[name]), 4)
            rows.append([model.stem, name, best["states"], best["transitions"],
                         round(min(r["load"] for r in capped[name]), 4),
                         round(best["load"], 4), *steps, round(rest, 4), *inside, receive,
                         imported])
            print(dict(zip(header, rows[-1], strict=True)))
    _common.write_tables(_common.out_dir(args), "load_steps", header, rows)
    return rows


if __name__ == "__main__":
    main()
