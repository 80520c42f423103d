"""The analysis's outputs and the solved result hashed, and the lifted policy's and the
analysis's CPU a warm solve, on QVBS instances, a checkout against another.

Per instance and tree, a child process (the instance posed as ``bench_qvbs.py`` poses
it, the solver modules imported first, ``bench_sweeps.preload``):

* one synthesis with :func:`mitld_lp.solvers.analysis.analyse` wrapped: every array
  field of the two quotients it returns hashed (SHA-256 of their dtypes and bytes, the
  record's ``shared`` dict left out: a branch may add to it), and the bracket and the
  lifted policies (:func:`mitld_lp.solvers.quotient.lift_policy`'s answers) hashed;
* ``--reps`` more syntheses, each timed by the process clock: the whole solve
  (``solve_cpu``), ``analyse`` and ``lift_policy`` (CPU ms a solve).

``--compare DIR``: the checkout ``DIR``'s package too, the children alternated
``--rounds`` times (the base's first)::

    python experiments/analysis_hashes.py --qvbs <QVBS> --only csma.4-2.some_before \\
        --compare <base> --rounds 2 --reps 5
    python experiments/analysis_hashes.py --qvbs <QVBS> --quick   # firewire_dl, 2 solves

Written: ``analysis_hashes.md`` in ``--out`` (default ``experiments/out``, a scratch folder).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import subprocess
import sys
import tempfile
from itertools import product
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

QUICK = "firewire_dl.3-600.deadline"


def _arrays(record: Any, prefix: str = "") -> list[tuple[str, Any]]:
    """The arrays of a record's fields, nested records and tuples walked, by name."""
    import numpy as np

    out: list[tuple[str, Any]] = []
    if isinstance(record, np.ndarray):
        return [(prefix, record)]
    if isinstance(record, (tuple, list)):
        for k, v in enumerate(record):
            out += _arrays(v, f"{prefix}[{k}]")
        return out
    if dataclasses.is_dataclass(record) and not isinstance(record, type):
        for f in dataclasses.fields(record):
            if f.name != "shared":
                out += _arrays(getattr(record, f.name), f"{prefix}.{f.name}")
        return out
    if hasattr(record, "__array__") and not callable(record):
        return [(prefix, np.asarray(record))]
    if isinstance(record, (int, float, str, bool)) or record is None:
        return [(prefix, np.asarray(repr(record)))]
    return out


def _digest(pairs: list[tuple[str, Any]]) -> str:
    import hashlib

    import numpy as np

    h = hashlib.sha256()
    for name, a in pairs:
        a = np.ascontiguousarray(a)
        h.update(name.encode())
        h.update(str(a.dtype).encode())
        h.update(str(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest()[:16]


def child(job: dict[str, Any]) -> dict[str, Any]:
    """The module docs' two parts, in one process."""
    import time

    import bench_sweeps as bs
    import numpy as np

    import mitld_lp.solvers.analysis as an
    import mitld_lp.solvers.quotient as qu
    from mitld_lp import load_model, synthesize

    model = load_model(job["model"], max_states=job["max_states"])
    bs.preload()
    spent = {"analyse": 0.0, "lift": 0.0}
    kept: dict[str, list[Any]] = {"analyse": [], "lift": []}

    def timed(part: str, f: Any) -> Any:
        def run(*a: Any, **k: Any) -> Any:
            t = time.process_time()
            r = f(*a, **k)
            spent[part] += time.process_time() - t
            kept[part].append(r)
            return r
        return run

    analyse, lift = an.analyse, qu.lift_policy
    timed_analyse, timed_lift = timed("analyse", analyse), timed("lift", lift)
    for mod in list(sys.modules.values()):  # every module's name bound to them
        if getattr(mod, "__name__", "").startswith("mitld_lp"):
            if getattr(mod, "analyse", None) is analyse:
                mod.analyse = timed_analyse
            if getattr(mod, "lift_policy", None) is lift:
                mod.lift_policy = timed_lift
    first = synthesize(model)
    out: dict[str, Any] = dict(
        bracket=[first.lower, first.upper],
        analysis_hash=_digest(_arrays(kept["analyse"])),
        policy_hash=_digest([(str(k), np.asarray(p)) for k, p in enumerate(kept["lift"])]),
        bracket_hash=_digest([("b", np.array([first.lower, first.upper]))]),
        n_analyses=len(kept["analyse"]), n_lifts=len(kept["lift"]))
    rows = []
    for _ in range(job["reps"]):
        spent.update(analyse=0.0, lift=0.0)
        kept["analyse"].clear()
        kept["lift"].clear()
        rows.append((synthesize(model).solve_cpu, spent["analyse"], spent["lift"]))
    out["times"] = [list(c) for c in zip(*rows, strict=True)]
    return out


def _ms(times: list[float]) -> str:
    v = sorted(times)
    return f"{v[len(v) // 2] * 1e3:.1f} / {v[0] * 1e3:.1f}"


def _row(name: str, label: str, got: dict[str, Any]) -> str:
    solve, analyse, lift = got["times"]
    return (f"| {name} | {label} | {_ms(solve)} | {_ms(analyse)} | {_ms(lift)} | "
            f"{got['analysis_hash']} | {got['policy_hash']} | {got['bracket_hash']} | "
            f"{got['bracket']} |")


def _answer(work: Path) -> None:
    got = child(json.loads((work / "job.json").read_text(encoding="utf-8")))
    (work / "out.json").write_text(json.dumps(got), encoding="utf-8")


def _in_child(root: Path, qvbs: Path, work: Path, job: dict[str, Any]) -> dict[str, Any]:
    """``job`` run by a child process importing the package of the checkout ``root``."""
    (work / "job.json").write_text(json.dumps(job), encoding="utf-8")
    paths = [str(root), *filter(None, [os.environ.get("PYTHONPATH")])]
    subprocess.run([sys.executable, __file__, "--qvbs", str(qvbs), "--child", str(work)],
                   check=True, env=dict(os.environ, PYTHONPATH=os.pathsep.join(paths)))
    return json.loads((work / "out.json").read_text(encoding="utf-8"))


def main(argv: list[str] | None = None) -> None:
    import bench_qvbs as bq

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    for flag, kw in [("--child", dict(default=None, help=argparse.SUPPRESS)),
                     ("--qvbs", dict(type=Path, required=True)),
                     ("--only", dict(nargs="*", default=[QUICK], metavar="NAME")),
                     ("--quick", dict(action="store_true", help=f"{QUICK}, 2 solves")),
                     ("--reps", dict(type=int, default=5, help="timed solves a child")),
                     ("--compare", dict(type=Path, default=None, metavar="DIR",
                                        help="a base checkout, alternated with this one")),
                     ("--rounds", dict(type=int, default=1, help="with --compare")),
                     ("--out", dict(type=Path, default=HERE / "out"))]:
        ap.add_argument(flag, **kw)
    args = ap.parse_args(argv)
    if args.child is not None:  # the child's side: the job in, its figures out
        return _answer(Path(args.child))
    names = [QUICK] if args.quick else args.only
    reps = 2 if args.quick else args.reps
    trees = {"this": HERE.parent} if args.compare is None else \
        {"base": args.compare, "this": HERE.parent}
    n_rounds = args.rounds if args.compare else 1
    lines = ["## CPU ms a warm solve (median / least), and hashes", "",
             "| instance | tree | solve | analyse | lift_policy | analysis hash | "
             "lifted policies hash | bracket hash | bracket |",
             "|---|---|---|---|---|---|---|---|---|"]
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        posed = dict((inst.name, job) for inst, job in
                     bq.jobs(args.qvbs, 0, bq.MAX_STATES, bq.FAMILIES, work)[0])
        if set(names) - set(posed):
            raise SystemExit(f"--only: not QVBS instances posed here: "
                             f"{sorted(set(names) - set(posed))}")
        for name, k, label in product(names, range(1, n_rounds + 1), list(trees)):
            got = _in_child(trees[label], args.qvbs, work, dict(posed[name], reps=reps))
            lines.append(_row(name, f"{label} {k}", got))
            print(lines[-1], flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "analysis_hashes.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    print(f"written: {args.out / 'analysis_hashes.md'}")


if __name__ == "__main__":
    main()
