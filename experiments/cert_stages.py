"""Profile: the certificate's pieces on QVBS instances, before and after, in one run.

Per instance (posed as ``bench_qvbs.py`` poses it) and per checkout (this one, and with
``--compare DIR`` the ``mitld_lp`` of another checkout), in a child process of its own,
rounds alternating between the checkouts so that the machine's load hits both alike:
the synthesis with the entry points below timed in place (CPU seconds, no profiler;
each inside its stage's figure), the bracket printed beside the times (its hex digits:
the same bits before and after, or not).  Storm's check of the same product is in
``bench_qvbs.py``'s run; this script only splits our solve stage.

* the stages: ``solve_stage`` (the route's ``solve_models``), ``analyse``,
  ``interval_iterations`` (``iteration_result`` inside it: its results built, the
  bounds lifted), ``iteration_policy`` (the iteration's policy made where the route
  reads it), ``solve_lp``, ``certify``, ``_keeping``;
* the certificate's sides: ``rounding`` (its factors), ``policy_lower`` /
  ``policy_upper``, ``optimum_upper`` / ``optimum_lower``, ``everywhere``;
* inside the certificate: the kernels' load where their cache is warm (``warm_load``),
  the policy's chain (``chain``), its never / sure sets (``chain_sets``: compiled once
  the load is paid, else its edges reversed (``Reversed.__init__``) and its two
  searches (``Reversed.reaching``)), its values and
  slack (``_solve``), the Bellman checks (``_fails``), the repair (``Repair.run``) and
  the recheck after it (``_touched``, ``_fails_among``: cert-half's, empty before);
* the chain's pieces (cert-78): its sets and solved states' chain by one compiled call
  (``chain_parts``), else the sets (``chain_sets``) and the NumPy gather
  (``chain_gather``); ``chain_rest`` the chain outside its sets and ``_solve`` (the
  gather, inline before cert-78); inside ``_solve`` the blocks renumbered
  (``chain_blocks``), the single states' set-up (``chain_singles``) and the walk found
  (``chain_walk``);
* ``ChainLevels.__init__``: the chains' own components (the LP's greedy chain and the
  certificate's), ``chain_walk_solve`` their solves;
* the iteration's pieces: its sweeps (``compiled_sweeps``, ``numpy_sweeps``; their
  count ``sweeps`` and ``ms_per_sweep``), the compiled sweeps' order and the block
  renumbered in it (``sweep_order``, ``renumbered``), the policy jump
  (``policy_jump``); the LP stage's greedy block (``lp_greedy``); the minimum's proof
  that no end component is left (``_escapes``);
* the analysis's parts (fixed-82): the product's components and reach
  (``an_components``), a maximum's end components with its value-1 states
  (``an_ends``) or those found apart (``an_prob1e``), the quotient's rows
  (``an_quotient_rows``) and blocks (``an_quotient_blocks``); and every kernel's link
  from the loader's cache wherever it falls (``kernel_links``).

::

    python experiments/cert_stages.py --qvbs qcomp/benchmarks \\
        --only zeroconf.1000-4-false.correct_max --compare /tmp/base --rounds 2
    python experiments/cert_stages.py --only --bus bus_scaled_n128_d3 --compare /tmp/base

``--bus`` adds instances of ``bench_sweeps.py`` (posed as it poses them).  ``--storm``
runs ``bench_qvbs.measure`` once per QVBS instance first, for Storm's best sound check
of the same product in the same run (``storm_check_cpu``, its value beside).

Written: ``cert_stages.csv``, ``cert_stages.md``, and ``cert_stages_summary.md`` (per
instance: the bracket, whether its bits are the same in every run, the least
certificate and solve of each checkout, Storm's best check).

``--memory`` (cert-mem): instead of the times, the traced peak (``tracemalloc``) of
each of the certificate's pieces of :data:`TRACED` and of the whole synthesis, bytes a
product transition above the traced size before ``synthesize`` (the highest of its
calls; a piece's peak includes the pieces inside it), the size at ``certify``'s entry
(``certify_entry``: what the route holds for it), and where inside the certificate the
traced size was highest (``certify_where``: a thread reads the innermost frames of the
package every half millisecond at each new high); one round, the bracket beside.
``--sensed`` adds the sensed case (``bench_qvbs.py``'s, ``--quick``: its smallest)::

    python experiments/cert_stages.py --qvbs qcomp/benchmarks --memory --sensed \\
        --only csma.4-2.some_before --compare /tmp/base
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

import _common  # noqa: E402
import bench_qvbs as bq  # noqa: E402
from profile_solve import _timed, bus_jobs  # noqa: E402  (timed in place, alike)

TIMED = (("mitld_lp.routes.plain", "solve_models", "solve_stage"),
         ("mitld_lp.solvers.analysis", "analyse"),
         ("mitld_lp.solvers.iteration", "interval_iterations"),
         ("mitld_lp.solvers.iteration", "_result", "iteration_result"),
         ("mitld_lp.routes.plain", "_settled", "iteration_policy"),
         ("mitld_lp.solvers.lp", "solve_lp"),
         ("mitld_lp.solvers.certify", "certify"),
         ("mitld_lp.solvers.certify", "rounding"),
         ("mitld_lp.solvers.certify", "chain"),
         ("mitld_lp.solvers.certify_chain", "Reversed.__init__"),
         ("mitld_lp.solvers.certify_chain", "Reversed.reaching"),
         ("mitld_lp.solvers.certify_chain", "_solve"),
         ("mitld_lp.solvers.certify", "policy_lower"),
         ("mitld_lp.solvers.certify", "policy_upper"),
         ("mitld_lp.solvers.certify", "optimum_upper"),
         ("mitld_lp.solvers.certify", "optimum_lower"),
         ("mitld_lp.solvers.certify", "_fails"),
         ("mitld_lp.solvers.certify", "_fails_among"),
         ("mitld_lp.solvers.certify", "_touched"),
         ("mitld_lp.solvers.certify_repair", "Repair.run"),
         ("mitld_lp.solvers.certify", "everywhere"),
         ("mitld_lp.solvers.chain_levels", "ChainLevels.__init__"),
         ("mitld_lp.routes.plain", "_keeping"),
         # the iteration's pieces (cert-cut): the sweeps (compiled or NumPy), their
         # set-up (the order of the compiled sweeps, the block renumbered), the policy
         # jump; the LP stage's greedy block and every chain walk's solve
         ("mitld_lp.solvers.iteration", "compiled_sweeps"),
         ("mitld_lp.solvers.iteration", "numpy_sweeps"),
         ("mitld_lp.solvers.iteration", "value_order", "sweep_order"),
         ("mitld_lp.solvers.iteration", "renumbered"),
         ("mitld_lp.solvers.iteration", "jump", "policy_jump"),
         ("mitld_lp.solvers.lp_blocks", "certified_greedy", "lp_greedy"),
         ("mitld_lp.solvers.chain_levels", "ChainLevels.solve", "chain_walk_solve"),
         # the certificate's proof that a minimum leaves no end component
         ("mitld_lp.solvers.certify", "_escapes"),
         # cert-fast: the Bellman check's rows and the repair's needs by one compiled
         # call where a kernel's load is paid (inside ``_fails`` / ``Repair.run``; a
         # call that returns None, the NumPy code running, is timed too), the chain's
         # edges reversed (``Reversed.__init__`` above) and the readers by column
         ("mitld_lp.solvers.certify", "compiled_checks"),
         ("mitld_lp.solvers.certify_repair", "compiled_needs"),
         ("mitld_lp.solvers.certify_repair", "readers_by_column"),
         # cert-small: the kernels' load where their cache is warm (its figure the
         # load alone, numba's pieces and none of the kernels), the chain's never /
         # sure sets (compiled once paid, else the edges reversed and searched twice)
         ("mitld_lp.solvers.certify", "load_if_warm", "warm_load"),
         ("mitld_lp.solvers.certify_chain", "_sets", "chain_sets"),
         # cert-78: the chain's sets and its solved states' chain by one compiled call
         # (``chain_parts``; a call that returns None is timed too), the NumPy gather
         # where it does not run (``chain_gather``), and inside ``_solve``: the support
         # graph's blocks renumbered (``chain_blocks``), the single states' set-up
         # (``chain_singles``) and the chain's own walk found (``chain_walk``:
         # ``ChainLevels``' components, or the LP's walk taken over)
         ("mitld_lp.solvers.certify_chain", "compiled_chain_parts", "chain_parts"),
         ("mitld_lp.solvers.certify_chain", "_gathered", "chain_gather"),
         ("mitld_lp.solvers.certify_chain", "blocks_from", "chain_blocks"),
         # layer-85b: the same blocks by one compiled call, in the same column (its
         # NumPy calls then run only where it returns None: the sum is the blocks')
         ("mitld_lp.solvers.certify_chain", "compiled_chain_blocks", "chain_blocks"),
         ("mitld_lp.solvers.certify_chain", "_Singles.__init__", "chain_singles"),
         ("mitld_lp.solvers.certify_chain", "walk_of", "chain_walk"),
         # fixed-82: the analysis's parts where it calls them (the product's components
         # and reach, a maximum's end components with its value-1 states, or those
         # found apart, the quotient's rows and blocks) and every kernel's link from the
         # loader's cache (wherever in the solve it falls)
         ("mitld_lp.solvers.analysis", "components_reaching", "an_components"),
         ("mitld_lp.solvers.analysis", "ends_and_sure", "an_ends"),
         ("mitld_lp.solvers.analysis", "prob1e_on_product", "an_prob1e"),
         ("mitld_lp.solvers.analysis", "quotient_rows", "an_quotient_rows"),
         ("mitld_lp.solvers.analysis", "quotient_blocks", "an_quotient_blocks"),
         ("mitld_lp.util.kernel_loader", "_load", "kernel_links"))
"""The entry points timed in place: (module, attribute, column); the column is the
attribute's name where no third is given.  ``solve_stage``: the plain route's
``solve_models`` (the analysis to the certificates, without the result's record);
``iteration_result``: the iteration's results built (the bounds lifted to the product;
the policy was made there before it was made at its first read); ``iteration_policy``:
that first read, where the route needs it (absent before).  ``sweeps``: the interval
iteration's sweeps (every block's), ``ms_per_sweep`` the sweeps' CPU (compiled and
NumPy) over them (empty where none)."""
COLUMNS = ("instance", "checkout", "round", "lower", "upper", "solve_cpu", "sweeps",
           "ms_per_sweep", *dict.fromkeys(t[-1] if len(t) == 3 else t[1] for t in TIMED),
           "chain_rest")
"""``chain_rest``: the chain's CPU outside its sets (``chain_sets`` / ``chain_parts``)
and ``_solve``: the NumPy gather of the solved states' rows where it runs, inline in a
checkout before cert-78."""


TRACED = tuple((module, name) for module, name, *_ in TIMED
               if module.startswith("mitld_lp.solvers.certify") and name not in (
                   "_fails_among", "_touched", "_escapes", "compiled_checks",
                   "compiled_needs", "readers_by_column", "blocks_from", "compiled_chain_blocks",
                   "_Singles.__init__", "walk_of")) + (
    ("mitld_lp.solvers.certify", "_trapped"),)
"""The certificate's pieces whose traced peaks ``--memory`` reads (module, attribute);
a checkout without one has no figure for it."""
MEM_COLUMNS = ("instance", "checkout", "lower", "upper", "synthesize", "certify_entry",
               *(t[1] for t in TRACED), "certify_where")


def _load_model(job: dict[str, Any]) -> Any:
    import bench_sweeps as bs

    from mitld_lp import load_model

    if "bus" in job:  # an instance of bench_sweeps.py, posed as it poses them
        from bench_scaling import Instance

        return bs._model(Instance(*job["bus"]))
    if job.get("case") == "sensed":
        import bench_sensed

        return bench_sensed.case_model(job["index"], job["quick"])
    return load_model(job["model"], max_states=job["max_states"])


def memory_child(job: dict[str, Any]) -> dict[str, Any]:
    """The synthesis with each piece of :data:`TRACED` wrapped for its traced peak
    (``--memory``): peaks nest (an inner piece's reset of the peak is carried to the
    pieces around it), bytes a transition above the traced size before ``synthesize``."""
    import importlib
    import threading
    import tracemalloc

    from mitld_lp import synthesize

    model = _load_model(job)
    peaks: dict[str, int] = {}
    open_: list[int] = []  # the running peak of each piece open, innermost last
    watch = {"on": False, "high": 0, "where": None}
    entry: list[int] = []

    def traced(f: Any, name: str) -> Any:
        def wrapper(*a: Any, **k: Any) -> Any:
            now, peak = tracemalloc.get_traced_memory()
            if open_:
                open_[-1] = max(open_[-1], peak)
            open_.append(now)
            tracemalloc.reset_peak()
            if name == "certify":
                entry.append(now)
                watch.update(on=True, high=now)
            try:
                return f(*a, **k)
            finally:
                got = max(open_.pop(), tracemalloc.get_traced_memory()[1])
                peaks[name] = max(peaks.get(name, 0), got)
                if open_:
                    open_[-1] = max(open_[-1], got)
                tracemalloc.reset_peak()
                if name == "certify":
                    watch["on"] = False
        return wrapper

    for module, name in TRACED:
        owner: Any = importlib.import_module(module)
        *path, last = name.split(".")
        for part in path:
            # a class's old private name in a checkout before it was made public
            owner = getattr(owner, part, None) or getattr(owner, "_" + part)
        if hasattr(owner, last):
            setattr(owner, last, traced(getattr(owner, last), name))
    main_id = threading.get_ident()

    def sample() -> None:
        while True:
            time.sleep(0.0005)
            if not watch["on"]:
                continue
            now = tracemalloc.get_traced_memory()[0]
            if now > watch["high"]:
                frame, where = sys._current_frames().get(main_id), []
                while frame is not None and len(where) < 3:
                    if "mitld_lp" in frame.f_code.co_filename:
                        where.append(frame.f_code.co_filename.split("mitld_lp/")[-1]
                                     + f":{frame.f_lineno} ({frame.f_code.co_name})")
                    frame = frame.f_back
                frame = None  # (a frame held here would keep its arrays alive)
                watch.update(high=now, where=" <- ".join(where))

    threading.Thread(target=sample, daemon=True).start()
    tracemalloc.start()
    base = tracemalloc.get_traced_memory()[0]
    tracemalloc.reset_peak()
    open_.append(base)
    r = synthesize(model)
    whole = max(open_.pop(), tracemalloc.get_traced_memory()[1])
    tracemalloc.stop()
    per = float(r.mdp.n_transitions)
    out: dict[str, Any] = {k: round((v - base) / per, 1) for k, v in peaks.items()}
    out.update(lower=r.lower.hex(), upper=r.upper.hex(),
               synthesize=round((whole - base) / per, 1),
               certify_entry=round((max(entry) - base) / per, 1) if entry else None,
               certify_where=watch["where"])
    return out


def child(job: dict[str, Any]) -> dict[str, Any]:
    """The synthesis with each entry point of :data:`TIMED` wrapped (CPU seconds)."""
    import importlib

    import bench_sweeps as bs

    from mitld_lp import synthesize

    model = _load_model(job)  # (a bus instance, the sensed case or a QVBS one)
    bs.preload()
    spent: dict[str, float] = defaultdict(float)
    for module, name, *column in TIMED:
        try:  # (a checkout before the module was written: no column)
            owner: Any = importlib.import_module(module)
        except ImportError:
            continue
        *path, last = name.split(".")
        for part in path:
            # a class's old private name in a checkout before it was made public
            owner = getattr(owner, part, None) or getattr(owner, "_" + part)
        if hasattr(owner, last):  # (a checkout before it was written: no column)
            setattr(owner, last, _timed(getattr(owner, last), (column or [name])[0],
                                        spent))
    c = time.process_time()
    r = synthesize(model)
    solve_cpu = time.process_time() - c
    part = getattr(r, "part", None)
    it = getattr(getattr(part, "lower_model", None), "iteration", None)
    sweeps = None if it is None else int(it.iterations)
    swept = spent.get("compiled_sweeps", 0.0) + spent.get("numpy_sweeps", 0.0)
    rest = spent.get("chain", 0.0) - sum(spent.get(k, 0.0) for k in (
        "chain_sets", "chain_parts", "_solve"))
    return dict(spent, solve_cpu=solve_cpu, lower=r.lower.hex(), upper=r.upper.hex(),
                chain_rest=rest if "chain" in spent else None,
                sweeps=sweeps, ms_per_sweep=1e3 * swept / sweeps if sweeps else None)


def _run(job: dict[str, Any], work: Path, package: Path) -> dict[str, Any]:
    (work / "job.json").write_text(json.dumps(job), encoding="utf-8")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(package), str(HERE)]))
    proc = subprocess.run([sys.executable, __file__, "--child", str(work)], env=env,
                          capture_output=True, text=True, timeout=bq.BUDGET)
    if proc.returncode != 0:
        return {"error": proc.stderr.strip().splitlines()[-1:]}
    return json.loads((work / "out.json").read_text(encoding="utf-8"))


def main(argv: list[str] | None = None) -> int:
    ap = _common.parser(__doc__.splitlines()[0])
    ap.add_argument("--qvbs", type=Path, help="a checkout's benchmarks/ of ahartmanns/qcomp")
    ap.add_argument("--only", nargs="*", default=["zeroconf.1000-4-false.correct_max"])
    ap.add_argument("--bus", nargs="*", default=(), metavar="NAME",
                    help="also these instances of bench_sweeps.py (e.g. bus_scaled_n128_d3)")
    ap.add_argument("--compare", type=Path, default=None, metavar="DIR")
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--storm", action="store_true",
                    help="Storm's best sound check of each QVBS instance beside (one "
                         "bench_qvbs.measure run each, first)")
    ap.add_argument("--memory", action="store_true",
                    help="the certificate's pieces' traced peaks instead of their times "
                         "(one round)")
    ap.add_argument("--sensed", action="store_true",
                    help="also bench_qvbs.py's sensed case")
    ap.add_argument("--child", default=None, help=argparse_hidden())
    args = ap.parse_args(argv)
    if args.child:
        work = Path(args.child)
        job = json.loads((work / "job.json").read_text(encoding="utf-8"))
        got = memory_child(job) if job.get("memory") else child(job)
        (work / "out.json").write_text(json.dumps(got), encoding="utf-8")
        return 0
    if args.qvbs is None and (args.only or not (args.bus or args.sensed)):
        ap.error("--qvbs is required (a checkout's benchmarks/ folder)")
    out = _common.out_dir(args)
    checkouts = [("after", HERE.parent)]
    if args.compare is not None:
        checkouts.insert(0, ("before", args.compare.resolve()))
    rows = []
    with tempfile.TemporaryDirectory(prefix="cert_stages_") as tmp:
        found = (bq.jobs(args.qvbs, 0, bq.MAX_STATES, bq.FAMILIES, Path(tmp))[0]
                 if args.qvbs is not None and args.only else [])
        storm: dict[str, dict[str, Any]] = {}
        jobs = ([f for f in found if f[0].name in set(args.only)] + bus_jobs(args.bus)
                + (bq.case_jobs(["sensed"], args.quick, Path(tmp)) if args.sensed else []))
        if args.memory:
            return _memory(jobs, checkouts, Path(tmp), out)
        for inst, job in jobs:
            if args.storm and "bus" not in job:
                (Path(tmp) / inst.name).mkdir()
                storm[inst.name] = bq.measure(inst, job, Path(tmp) / inst.name, bq.BUDGET)
                got = storm[inst.name]
                print(inst.name, "Storm's best check", got.get("storm_check_cpu"),
                      got.get("storm_best"), "agrees:", got.get("storm_agrees"),
                      "QVBS reference:", got.get("reference"), flush=True)
            for k in range(args.rounds):
                for label, package in checkouts:
                    got = _run(job, Path(tmp), package)
                    rows.append([inst.name, label, k, got.get("lower"), got.get("upper"),
                                 *(_short(got.get(c)) for c in COLUMNS[5:])])
                    print(_common.text_table(COLUMNS, rows[-1:]), flush=True)
    _common.write_tables(out, "cert_stages", COLUMNS, rows)
    _common.write_text(out / "cert_stages_summary.md", _summary(rows, storm))
    print(f"wrote {out / 'cert_stages_summary.md'}")
    return 0


def _memory(jobs: list[tuple[Any, dict[str, Any]]], checkouts: list[tuple[str, Path]],
            tmp: Path, out: Path) -> int:
    """``--memory``: one traced run of each job in each checkout (:func:`memory_child`),
    written as ``cert_stages_memory.csv`` / ``.md``."""
    rows = []
    for inst, job in jobs:
        for label, package in checkouts:
            got = _run(dict(job, memory=True), tmp, package)
            rows.append([inst.name, label, *(got.get(c) for c in MEM_COLUMNS[2:])])
            if "error" in got:
                rows[-1][-1] = f"error: {got['error']}"
            print(_common.text_table(MEM_COLUMNS, rows[-1:]), flush=True)
    _common.write_tables(out, "cert_stages_memory", MEM_COLUMNS, rows)
    print(f"wrote {out / 'cert_stages_memory.md'}")
    return 0


def _summary(rows: list[list[Any]], storm: dict[str, dict[str, Any]]) -> str:
    """Per instance: the bracket (lower, upper), whether its bits are the same in
    every run of both checkouts, the least certificate and solve of each checkout
    (CPU seconds), and Storm's best check (with ``--storm``)."""
    col = {c: i for i, c in enumerate(COLUMNS)}
    out = []
    for name in dict.fromkeys(r[0] for r in rows):
        mine = [r for r in rows if r[0] == name]
        brackets = {(r[col["lower"]], r[col["upper"]]) for r in mine}
        lower, upper = next(iter(brackets))

        def least(label: str, key: str, mine: list = mine) -> str:
            got = [r[col[key]] for r in mine if r[1] == label and r[col[key]] is not None]
            return f"{min(got):.3f}" if got else "-"

        s = storm.get(name, {})
        out.append([name, float.fromhex(lower) if lower else None,
                    float.fromhex(upper) if upper else None, len(brackets) == 1,
                    f"{least('before', 'certify')} -> {least('after', 'certify')}",
                    f"{least('before', 'solve_cpu')} -> {least('after', 'solve_cpu')}",
                    s.get("reference", "-"), s.get("storm_agrees", "-"),
                    s.get("storm_check_cpu", "-")])
    return _common.markdown_table(("instance", "lower", "upper", "same bits",
                                   "certificate before -> after",
                                   "solve before -> after", "QVBS reference",
                                   "Storm agrees", "Storm's best check"), out)


def _short(v: Any) -> Any:
    return round(v, 4) if isinstance(v, float) else v


def argparse_hidden() -> str:
    import argparse

    return argparse.SUPPRESS


if __name__ == "__main__":
    raise SystemExit(main())
