"""Benchmark: the sensed build (the information-state product) before and after, one run.

Each case is the bus case (``models/bus_grid.toml``, ``models/bus_puddle.toml``, or
``models/bus_fit.toml``: bus 1 within a band, bus 2's law fitted to data with its 95%
band) with cameras that miss buses (``[sensors] b = { detect = d }``; ``b@d fa=f``: one
that also gives false alarms, ``false_alarm = f``, every step's report read) at an
``epsilon``, solved by ``synthesize`` on the ``sensed`` route in a child process of its
own.  Per case:

* ``build_cpu``: the CPU seconds of :func:`mitld_lp.sensing.belief.belief_product` (the
  information states, their transitions and the controller's moves), timed inside the
  child; ``process_cpu`` the child's CPU up to the answer (imports, build, solve,
  certificate; Storm's check after it is not counted);
* ``states_per_s``: the states the build made a CPU second; ``estimate``: the largest of
  the size estimates (:mod:`mitld_lp.sensing.growth`) the build made at its levels' ends
  while it had found under half its states (its budgets are checked against them before
  the work; blank: no level judged that early);
* the product's states, choices and transitions (with a band: the band's middle law's,
  the first of the products the route builds), and the certified bracket ``[lower,
  upper]``, printed beside each time; ``digest``: the start of a SHA-256 of the
  product's matrix (every probability's bits, column, row and state's choices);
* Storm (stormpy), where installed (``storm_of`` says which): ``Pmax=? [F "accept"]`` on
  the same product exported as DRN (truncation losing: our ``lower``), its value beside
  ours and its seconds; not for a task with a safety part (``bus_puddle``: its
  acceptance is staying in end components of the information states, not reaching a
  target, so Storm's reachability on the DRN is not the same question); with a band,
  Storm's robust check of the exported chain (``export --chain``: the controller's
  interval chain, ``Pmin`` with the uncertainty minimised), which is our ``lower``.

``--compare DIR`` runs each case a second time, in the same run, with the ``mitld_lp`` of
that checkout (``base_*`` columns: the build before, its states), and checks that both
give the same bracket (to 1e-9); ``same`` says ``yes`` where the products are the same to
the bit (equal digests) and so are the brackets, ``size`` where the sizes and brackets (to
1e-9) agree but not every bit, ``smaller`` where the brackets agree on fewer states (the
merge of :mod:`mitld_lp.sensing.merge`) or transitions (a choice's entries into one state
merged, :func:`mitld_lp.sensing.rows.merged_entries`), ``no`` where the brackets differ;
``certified``: ours, and the base's after a slash where compared.

Run: ``python experiments/bench_sensed.py [--quick] [--out DIR] [--compare DIR]
[--repeats N] [--only TEXT]`` (``N`` runs of each child, the least CPU reported; only
the cases whose name contains ``TEXT``).
``--quick``: two small cases (not the fitted law's: some minutes).  Writes
``bench_sensed.csv``, ``bench_sensed.md`` and ``bench_sensed_machine.txt``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import _common as C

FULL = (
    ("bus_grid.toml", (("b2", 0.5),), 0.01),  # issue 45's: 81,814 states, 52,498 merged
    ("bus_grid.toml", (("b1", 0.5),), 1e-3),
    ("bus_grid.toml", (("b1", 0.5), ("b2", 0.5)), 1e-3),
    ("bus_puddle.toml", (("b1", 0.5),), 1e-3),
    ("bus_fit.toml", (("b2", 0.5),), 0.01),  # issue 43's case: bands, a fitted law
    # false alarms (experiments/false_alarms.py's camera): every step's report read
    ("bus_grid.toml", (("b2", 0.8, 0.05),), 0.05),
)
QUICK = (
    ("bus_grid.toml", (("b1", 0.5),), 0.01),
    ("bus_grid.toml", (("b1", 0.7), ("b2", 0.7)), 0.05),
    ("bus_grid.toml", (("b2", 0.8, 0.05),), 0.1),
)
HEADER = ["case", "states", "choices", "transitions", "lower", "upper", "certified",
          "digest",
          "estimate", "build_cpu", "states_per_s", "process_cpu", "base_states",
          "base_build_cpu", "base_states_per_s", "base_process_cpu", "speedup", "same",
          "storm_of", "storm_value", "storm_s"]


def name_of(case: tuple[Any, ...]) -> str:
    model, sensors, eps = case
    cams = "+".join(f"{e}@{d:g}" + "".join(f" fa={f:g}" for f in fa)
                    for e, d, *fa in sensors)
    return f"{model.removesuffix('.toml')} {cams} eps={eps:g}"


def case_model(index: int, quick: bool) -> Any:
    """Case ``index`` of :data:`QUICK` (``quick``) or :data:`FULL` as a model: the bus
    case's model file loaded, with the case's cameras at its ``epsilon``."""
    import dataclasses
    from types import MappingProxyType

    from mitld_lp import load_model
    from mitld_lp.sensing import Sensor

    model_name, sensors, eps = (QUICK if quick else FULL)[index]
    base = load_model(C.model_path(model_name))
    return dataclasses.replace(base, epsilon=eps, sensors=MappingProxyType(
        {e: Sensor(*s) for e, *s in sensors}))


def worker(index: int, quick: bool, out: Path, storm: bool) -> None:
    """One case in this process: the build timed, the answer, Storm on the product."""
    import mitld_lp.sensing.belief as belief
    import mitld_lp.sensing.growth as growth
    from mitld_lp import synthesize

    model_name = (QUICK if quick else FULL)[index][0]
    storm = storm and model_name != "bus_puddle.toml"  # a safety part: not reachability
    built: dict[str, float] = {}
    build = belief.belief_product

    def timed(*args: Any, **kwargs: Any) -> Any:
        t0 = time.process_time()
        b = build(*args, **kwargs)
        built["cpu"] = built.get("cpu", 0.0) + time.process_time() - t0
        return b

    belief.belief_product = timed  # the sensed route imports it when it builds
    guess = growth.projected

    def projected(*args: Any, **kwargs: Any) -> Any:
        out = guess(*args, **kwargs)
        seen.append((sum(args[0]), out[0]))  # the states found so far, the estimate
        return out

    seen: list[tuple[int, int]] = []
    growth.projected = projected  # the size estimate at each level's end
    r = synthesize(case_model(index, quick))
    process = time.process_time()  # this process so far: imports, build, solve
    assert r.route == "sensed", r.route
    row: dict[str, Any] = {
        "states": r.mdp.n_states, "choices": r.mdp.n_choices,
        "transitions": int(r.mdp.matrix.nnz), "lower": r.lower, "upper": r.upper,
        "certified": "yes" if r.certified else "NO", "digest": digest(r.mdp),
        "build_cpu": built["cpu"], "process_cpu": process,
        "estimate": max((e for f, e in seen if 2 * f < r.mdp.n_states), default=None),
        "states_per_s": r.mdp.n_states / built["cpu"],
        "package": str(Path(belief.__file__).parents[1])}
    from mitld_lp.running.sensed_band_chain import is_sensed_band, write_sensed_band_chain

    if storm and is_sensed_band(r):  # the controller's interval chain: Storm's worst case
        from bus_camera_band import storm_worst

        path = write_sensed_band_chain(r, out.with_suffix(".drn"))
        row["storm_of"] = "chain worst"
        row["storm_value"], row["storm_s"] = storm_worst(path)
    elif storm:
        row["storm_of"] = "product Pmax"
        row["storm_value"], row["storm_s"] = C.storm_pmax(r.mdp, r.mdp.target)
    out.write_text(json.dumps(row), encoding="utf-8")


def child(index: int, quick: bool, code: Path | None, storm: bool) -> dict[str, Any]:
    """:func:`worker` in a child process (``code``: the checkout it imports, default this
    one)."""
    return run_child(__file__, index, quick, code, storm)


def run_child(script: str, index: int, quick: bool, code: Path | None,
              storm: bool) -> dict[str, Any]:
    """The worker of ``script`` (an experiment with this one's options,
    :func:`add_options`) for case ``index`` in a child process importing the
    ``mitld_lp`` of ``code`` (default this checkout); its row."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(code or C.ROOT), str(C.HERE)])
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "row.json"
        argv = [sys.executable, script, "--worker", str(index), str(out)]
        argv += ["--quick"] if quick else []
        argv += [] if storm else ["--no-storm"]
        with tempfile.TemporaryFile() as errors:
            proc = subprocess.Popen(argv, cwd=code or C.ROOT, stdout=subprocess.DEVNULL,
                                    stderr=errors, env=env)
            _, status, _ = os.wait4(proc.pid, 0)
            errors.seek(0)
            err = errors.read().decode(errors="replace")
        if os.waitstatus_to_exitcode(status) != 0:
            raise RuntimeError(f"case {index} failed:\n{err[-2000:]}")
        return json.loads(out.read_text(encoding="utf-8"))


def parsed(description: str, only: str, worker: Any, argv: list[str] | None
           ) -> argparse.Namespace | None:
    """The options of a before/after benchmark run case by case in child processes
    (``--quick``, ``--out``, ``--compare``, ``--repeats``, ``--only``, with ``only`` an
    example, and the child's own); None when this process is a child, after running
    its case by ``worker(index, quick, out, storm)``."""
    ap = C.parser(description)
    ap.add_argument("--compare", type=Path, default=None, metavar="DIR",
                    help="also run with the mitld_lp of this checkout (before/after)")
    ap.add_argument("--repeats", type=int, default=1,
                    help="runs of each child; the least CPU of them is reported (default 1)")
    ap.add_argument("--only", default=None, metavar="TEXT",
                    help=f"only the cases whose name contains TEXT (e.g. {only})")
    ap.add_argument("--worker", nargs=2, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--no-storm", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker is not None:
        worker(int(args.worker[0]), args.quick, Path(args.worker[1]), not args.no_storm)
        return None
    if args.compare is not None and not (args.compare / "mitld_lp").is_dir():
        ap.error(f"--compare {args.compare}: no mitld_lp package in that directory")
    return args


def main(argv: list[str] | None = None) -> int:
    args = parsed(__doc__.splitlines()[0], "bus_fit", worker, argv)
    if args is None:
        return 0
    out = C.out_dir(args)
    rows = []
    for i, case in enumerate(QUICK if args.quick else FULL):
        if args.only is not None and args.only not in name_of(case):
            continue
        ours = least([child(i, args.quick, None, storm=k == 0)
                      for k in range(args.repeats)])
        row: dict[str, Any] = {"case": name_of(case), **ours}
        if args.compare is not None:
            base = least([child(i, args.quick, args.compare.resolve(), storm=False)
                          for _ in range(args.repeats)])
            row["base_build_cpu"], row["base_process_cpu"] = (base["build_cpu"],
                                                              base["process_cpu"])
            row["base_states"] = base["states"]
            row["certified"] = f"{ours['certified']}/{base['certified']}"
            row["base_states_per_s"] = base["states"] / base["build_cpu"]
            row["speedup"] = base["build_cpu"] / ours["build_cpu"]
            agree = (abs(base["lower"] - ours["lower"]) <= 1e-9
                     and abs(base["upper"] - ours["upper"]) <= 1e-9)
            sizes = all(base[k] == ours[k] for k in ("states", "choices", "transitions"))
            bits = all(base[k] == ours[k] for k in ("digest", "lower", "upper"))
            fewer = all(ours[k] <= base[k] for k in ("states", "transitions"))
            row["same"] = ("no" if not agree else "yes" if bits else "size" if sizes else
                           "smaller" if fewer else "larger")
        rows.append(row)
        print(C.text_table(HEADER, [[fmt(k, row.get(k)) for k in HEADER]]), flush=True)
    table = [[fmt(k, r.get(k)) for k in HEADER] for r in rows]
    print()
    print(C.text_table(HEADER, table))
    C.write_csv(out / "bench_sensed.csv", HEADER, table)
    C.write_text(out / "bench_sensed.md", C.markdown_table(HEADER, table) + (
        "\nCPU seconds; `build_cpu` is belief_product alone (`states_per_s`: the states it "
        "made a CPU second), `estimate` the largest of the size estimates made at the "
        "levels' ends while under half the states were found (mitld_lp/sensing/growth.py, "
        "blank where no level was judged by then), "
        "`base_*` the same case with "
        f"the package of `--compare` ({args.compare}), `same`: `yes` the same product to "
        "the bit (`digest`, a SHA-256 of its matrix) and the same bracket to the bit, `size` "
        "equal sizes and brackets (1e-9), `smaller` equal brackets on fewer states or "
        "transitions; Storm "
        "(`storm_of`): Pmax "
        "on the same product as DRN, or the worst case on the exported interval chain "
        "with a band (parse and check).\n"))
    from bench_scaling import machine_text

    C.write_text(out / "bench_sensed_machine.txt", machine_text(
        "the machine is shared: the before/after ratio is taken in one run",
        ["each case a child process; CPU seconds (process_time inside the child)"]))
    return 0 if all(r.get("same", "yes") != "no" for r in rows) else 1


def digest(mdp: Any) -> str:
    """The start of a SHA-256 of the product's matrix: every probability's bits, its
    column, each choice's row and each state's choices (integers as 64-bit values)."""
    import hashlib

    import numpy as np

    h = hashlib.sha256()
    m = mdp.matrix
    for x in (m.data, m.indices, m.indptr, mdp.row_groups, mdp.choice_actions):
        x = np.ascontiguousarray(x)
        # index values, not their width: an int32 and an int64 copy hash alike
        h.update((x.astype(np.int64) if x.dtype.kind in "iu" else x).tobytes())
    return h.hexdigest()[:12]


def least(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """The first run's answer with the least CPU seconds of all runs (the machine is
    shared: the least is the one least disturbed)."""
    out = dict(runs[0])
    for key in ("build_cpu", "process_cpu"):
        out[key] = min(r[key] for r in runs)
    out["states_per_s"] = out["states"] / out["build_cpu"]
    return out


def fmt(key: str, v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, bool) or isinstance(v, str):
        return str(v)
    if isinstance(v, int):
        return f"{v:,}"
    if key in ("lower", "upper", "storm_value"):
        return f"{v:.10f}"
    if key.endswith("states_per_s"):
        return f"{v:,.0f}"
    return f"{v:.1f}x" if key == "speedup" else f"{v:.3f}"


if __name__ == "__main__":
    raise SystemExit(main())
