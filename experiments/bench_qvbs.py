"""Benchmark: QVBS's public PRISM MDPs of at least 1e5 states, ours beside Storm, one run.

The successor of ``bench_sweeps.py`` for the public models: the same figures, in CPU
seconds, on the QVBS instances (``ahartmanns/qcomp``, ``benchmarks/mdp``; data CC-BY
4.0) of the families the issue names -- consensus, csma, wlan, wlan_dl, zeroconf,
zeroconf_dl, firewire_dl, resource-gathering -- with between ``--min-states``
(100,000) and ``--max-states`` (2,000,000) states by QVBS's count.  Each property is posed
as ``experiments/qvbs.py`` poses it (the PRISM file as published, its constants, the
property as an MITLD spec).  Per instance, each route in a child process of its own:

* ``ours``: :func:`mitld_lp.load_model` and :func:`mitld_lp.synthesize` with their
  defaults; ``solve_cpu`` is everything after the product is built (the solver modules
  imported before, as in ``bench_sweeps.py``), ``analysis_cpu`` the part of it in the
  graph analysis (``solvers.analysis.analyse``, timed in place), ``whole_cpu`` the load (the PRISM
  exploration, with the child process Storm explores in when it is capped) and the
  synthesis, ``process_cpu`` the child's CPU up to the end of the synthesis (imports
  included; the bench's extras below are not: ``child_cpu`` is the whole child;
  ``harness_cpu`` the interpreter and this script's own imports, before the route,
  which every route's process pays alike: they import neither ``mitld_lp``, NumPy
  nor lark, so Storm's process pays nothing of ours);
  of the whole, ``load_cpu`` is the load (Storm's exploration and the copy of its
  model, in the capped child or not) and ``product_cpu`` what the synthesis does
  before the solve (the product with the task's automaton, mostly);
  ``bytes_per_transition`` the peak resident size during ``synthesize`` (the peak is
  reset after the load, where Linux allows it) over the size before it, per product
  transition (the product is built inside ``synthesize``); ``process_peak_mb`` the
  whole process's peak resident size in MB, the load's included (and a capped child's,
  where Storm builds in one), beside Storm's whole run's (``storm_process_peak_mb``):
  unlike the figure per transition it does not depend on what the load left free in
  the heap for the synthesis to reuse.  After the figures are
  taken, the product is written as DRN (target: the lower model's goal) and one sweep
  of it is timed (a sparse product and a maximum per state; the median of seven
  batches of at least 0.05 s each, as the CPU clock ticks in milliseconds);
* ``storm_check``: stormpy reads that DRN and checks ``Pmax=? [F "target"]`` with each
  of Storm's sound methods (``force_soundness``, precision 1e-9 absolute; a method whose
  check reads 0 CPU seconds, under the clock's tick, is timed again in batches:
  :func:`batched`); the fastest is Storm's best check (``storm_value`` its answer), and
  every method must agree with our product's optimum within
  1e-6 (``Pmin=?`` where ours minimises the product, ``Result.sense``: a ``Pmin``
  property of a co-safe task; a task with a safety part is minimised as its
  complement's maximum, whose product is written);
* ``storm_prism``: Storm's whole run on the PRISM file and the QVBS property as
  published, as a process: import stormpy, parse, build, check with the best method
  found on the DRN (``storm_process_cpu``, up to the end of the check;
  ``storm_prism_cpu`` the parse, build and check alone, ``storm_build_cpu`` the parse
  and build: the peer of ``load_cpu``).

``--compare DIR`` runs ``ours`` a second time on each instance, in the same run, with
the ``mitld_lp`` of another checkout ``DIR`` (an older commit, ``git worktree add`` or
``git archive``), and adds its figures as ``base_*`` columns and a before/after table:
the same bracket, the same product (``same_product``: the same states, transitions and
:func:`product_digest`, a hash of the product's arrays bit for bit), CPU and bytes per
transition side by side.

An instance is *trivial* only if its answer is decided by the graph alone, before any
number: both truncation models' qualitative sets (Storm's prob01) put the initial state
at exactly 0 or exactly 1 (``ModelSolution.qualitative``).  It is reported apart, with
the reason, and never in a ratio; a small probability (a rare event, 3.7e-5 on
``zeroconf`` 1000-4) is not trivial and counts in every ratio.  ``iteration_sweeps``
are the interval iteration's own sweeps (``solve_sweeps`` is the whole solve stage in
sweeps' worth: the LP, the iteration and the certificate); ``iteration_s`` and
``lp_s`` are their wall seconds as the solvers report them (``lp_s`` each LP once: where
nothing is truncated the two models are one object, whose LP it counted twice before
wave 82, zeroconf 1000-4's 0.088 s as 0.176).  The targets checked on
the others (all have at least 1e5 states): solve <= 2x Storm's best check, whole
process <= 1x Storm's whole process, <= 50 bytes per transition on a product of at
least 1e6 transitions (the issue's words; every row prints its bytes per transition).
Instances not run are listed with the reason (not in the checkout, not a probability,
over the CPU budget).

**The issue's own cases** (``--cases grid sensed``, the default: both, after the QVBS
instances selected; ``--no-cases``: the QVBS instances alone; without ``--qvbs`` the cases
alone) are rows of the same table, with the same columns where they apply, in the
ratios and the target check unless trivial (whatever their product's size: the grid's
product is the few hundred states within the horizon):

* ``grid``: the 2001 x 2001 PRISM grid of ``experiments/bench_explore.py`` (4,004,001
  states; ``--quick`` 201 x 201), task ``F[0,10] goal``.  Ours runs from the PRISM file
  and the spec as the command line runs it (a model file, ``explore = "auto"``: the
  world explored up to the task's horizon); Storm's whole run is on the same PRISM file
  with ``Pmax=? [F<=10 "goal"]`` (``storm_prism``: it builds all 4,004,001 states,
  ``storm_prism_states``), and Storm's best sound check is on our product's DRN as for
  the QVBS rows (``storm_check``; the product is that small, so its check is timed in
  batches, :func:`batched`).  ``storm_prism_inside``: Storm's value inside our bracket
  within 1e-9.
* ``sensed``: the bus case with one camera (``experiments/bench_sensed.py``'s first
  case, ``bus_grid`` with bus 2's camera detecting with 0.5 at epsilon 0.01; ``--quick``
  its smallest, bus 1's), on the ``sensed`` route.  The product is an MDP over
  information states; Storm's sound checks (``storm_check``) read its DRN and compute
  ``Pmax=? [F "target"]`` over every policy of that MDP, which is our lower model's
  optimum (truncated hypotheses lose): they check our solve and certificate on that
  product.  They do not check the sensing build (that the information states, their
  transitions and the observation-based moves are what the cameras allow): that build is
  ours alone, and Storm has no peer of it, so the process ratio is left out
  (``process_note`` says why, the report prints it) while ``process_cpu`` is reported.
  A peer made of Storm's parse and check of our DRN (what ``bench_sensed.py`` sets
  beside its build) would price our build against nothing and flatter neither side, so
  it is not taken.  ``solve_cpu`` is the route's solve (``solve_sensed``) less the
  controller made after it, as the plain route's is; ``product_cpu`` holds the sensing
  build.  No PRISM file, no ``storm_build_cpu``.

Neither case has a published ``reference``; Storm's values (``storm_value`` on the DRN,
``storm_prism_value`` on the PRISM file) stand beside ours, as for every row.

The QVBS files are not part of this repository; give a checkout's ``benchmarks/``::

    python experiments/bench_qvbs.py --qvbs qcomp/benchmarks --out experiments/results
    python experiments/bench_qvbs.py --qvbs qcomp/benchmarks --quick  # two small instances
    python experiments/bench_qvbs.py --qvbs qcomp/benchmarks --only csma.4-2.some_before \
        --compare ../old-checkout --out /tmp/qvbs  # before and after, one run
    python experiments/bench_qvbs.py --quick --cases grid  # the 201 x 201 grid alone

``--start command``: our worker process starts as the command line ``mitld-lp`` starts
(``mitld_lp.startup.lean_start``, the garbage collector held while importing), which is
what a user's ``mitld-lp`` process pays; by default it starts as a program that imports
the package (the package then leaves NumPy, SciPy and lark as they import themselves).

``--memory``: also, in a child of its own, each stage's resident and traced peaks and
what it keeps (``experiments/memory_stages.py``), bytes per transition above the size
before ``synthesize``: ``mem_<stage>_*`` columns and a table per instance.

Written: ``bench_qvbs.csv``, ``bench_qvbs.md`` and ``bench_qvbs_machine.txt``.
"""

from __future__ import annotations

import json
import os
import re
import resource
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

import _common  # noqa: E402
import bench_sweeps as bs  # noqa: E402  (the same routes and targets)

if TYPE_CHECKING:
    import qvbs  # the same instances, posed the same way (imported where used: it
    # imports mitld_lp, NumPy and lark, which Storm's worker process must not pay)

FAMILIES = ("consensus", "csma", "wlan", "wlan_dl", "zeroconf", "zeroconf_dl", "firewire_dl",
            "resource-gathering")
MIN_STATES = 100_000
MAX_STATES = 2_000_000
QUICK_MAX_STATES = 20_000
QUICK_COUNT = 2
BUDGET = 1800.0  # CPU seconds per child
_NOT_A_TASK = ("not a probability", "qualitative")
COLUMNS = ("instance", "value", "upper", "reference", "states", "transitions", "sweep_ms",
           "solve_cpu", "analysis_cpu", "solve_sweeps", "iteration_sweeps", "iteration_s",
           "lp_s", "storm_value", "storm_check_cpu", "storm_check_sweeps", "storm_best",
           "solve_over_storm_check", "whole_cpu", "load_cpu", "product_cpu",
           "storm_build_cpu", "process_cpu", "storm_prism_value", "storm_prism_cpu",
           "storm_process_cpu", "process_over_storm_process", "bytes_per_transition",
           "storm_bytes_per_transition", "process_peak_mb", "storm_process_peak_mb",
           "storm_agrees", "certified")
CASES = ("grid", "sensed")  # the issue's own cases, rows beside the QVBS instances
GRID_N, QUICK_GRID_N = 2001, 201  # the grid's side: 4,004,001 states (--quick 40,401)
SENSED, QUICK_SENSED = 0, 0  # bench_sensed.FULL[0] (one camera), bench_sensed.QUICK[0]
NO_STORM_PROCESS = ("no Storm peer: the information-state product is built by our sensing "
                    "alone (Storm has no such build); Storm checks that product as DRN")


# ----------------------------------------------------------------------------- workers


def _reset_peak() -> bool:
    """Reset the process's peak resident size (Linux: ``5`` to ``/proc/self/clear_refs``);
    ``False`` where that is not possible (the peak then counts from the start)."""
    try:
        with open("/proc/self/clear_refs", "w", encoding="ascii") as f:
            f.write("5")
    except OSError:
        return False
    return True


def _hwm_kb() -> int:
    """The peak resident size since the last reset (``VmHWM``), in KiB."""
    with open("/proc/self/status", encoding="ascii") as f:
        for line in f:
            if line.startswith("VmHWM:"):
                return int(line.split()[1])
    return bs._peak_kb()


def _process_cpu() -> float:
    """This process's CPU seconds so far, with its children that have ended (the capped
    child in which Storm explores a PRISM program)."""
    own, ended = (resource.getrusage(w) for w in (resource.RUSAGE_SELF,
                                                   resource.RUSAGE_CHILDREN))
    return own.ru_utime + own.ru_stime + ended.ru_utime + ended.ru_stime


def _timed_analysis() -> list[float]:
    """The solve stage's graph analysis (``solvers.analysis.analyse``, which the route
    imports when it runs) wrapped in place: its CPU seconds, summed, in the list
    returned."""
    from mitld_lp.solvers import analysis

    spent = [0.0]
    inner = analysis.analyse

    def timed(*args: Any, **kwargs: Any) -> Any:
        c = bs._cpu()
        try:
            return inner(*args, **kwargs)
        finally:
            spent[0] += bs._cpu() - c

    analysis.analyse = timed
    return spent


def _command_start() -> None:
    """The command line's start-up (``mitld_lp.startup.command``, before its verbs):
    the garbage collector off while the imports run, then
    ``mitld_lp.startup.lean_start`` (a checkout from before it: the same steps)."""
    import gc

    from mitld_lp import startup

    gc.disable()
    lean = getattr(startup, "lean_start", None)
    if lean is None:
        from mitld_lp import init_cache

        for step in (startup.dataclass_methods_without_exec, init_cache.install,
                     startup.lean_scipy, startup.numpy_ma_when_used,
                     startup.lark_without_regex):
            step()
    else:
        lean()


def _load(job: dict[str, Any]) -> Any:
    """The job's model: a model file (a QVBS instance, the grid), or the sensed case
    (``bench_sensed``'s case, the bus case with its cameras)."""
    if job.get("case") == "sensed":
        import bench_sensed

        return bench_sensed.case_model(job["index"], job["quick"])
    from mitld_lp import load_model

    return load_model(job["model"], max_states=job["max_states"])


def _timed_sensed_solve() -> list[float]:
    """The sensed route's solve stage (``routes.sensed_solve.solve_sensed``, which the
    route imports when it solves) wrapped in place, less the observation-based
    controller made after it (``controller_of``: the plain route's ``solve_cpu`` stops
    before its controller too): its CPU seconds, summed, in the list returned (the
    sensed route leaves ``Result.solve_cpu`` unset)."""
    from mitld_lp.routes import sensed_solve

    spent = [0.0]
    solve, controller = sensed_solve.solve_sensed, sensed_solve.controller_of

    def timed(inner: Any, sign: float) -> Any:
        def run(*args: Any, **kwargs: Any) -> Any:  # (a failed solve fails the child)
            c = bs._cpu()
            out = inner(*args, **kwargs)
            spent[0] += sign * (bs._cpu() - c)
            return out
        return run

    sensed_solve.solve_sensed = timed(solve, 1.0)
    sensed_solve.controller_of = timed(controller, -1.0)
    return spent


def _goal(r: Any) -> Any:
    """The target our bracket is about, for Storm's check of the DRN: the route's
    acceptance; on the sensed route the information states' (``sensed_acceptance``),
    which is a reachability target only where no end component mixes persistent
    hypotheses with others."""
    if r.acceptance is not None:
        return r.acceptance.goal
    from mitld_lp.routes.sensed_solve import sensed_acceptance

    accept, mixed, _ = sensed_acceptance(r.mdp, r.dta)
    if mixed is not None:
        raise SystemExit("the sensed case's task credits mixed end components: Storm's "
                         "reachability check of the DRN is not the same question")
    return accept.goal


def work_ours(job: dict[str, Any], work: Path) -> dict[str, Any]:
    command = job.get("start") == "command"
    if command:
        _command_start()
    import numpy as np

    from mitld_lp import synthesize

    if command:  # the work starts: the collector on, the imports out of its reach
        import gc

        gc.freeze()
        gc.enable()
    c = _process_cpu()  # with the child in which Storm explores the PRISM program
    model = _load(job)
    load_cpu = _process_cpu() - c
    bs.preload()
    load_peak = _hwm_kb()  # the whole process's peak so far (the load's)
    fresh = _reset_peak()  # the PRISM exploration may have peaked higher than the solve
    before = bs._rss_kb()
    analysis = _timed_analysis()
    sensed = _timed_sensed_solve() if job.get("case") == "sensed" else None
    c = bs._cpu()
    r = synthesize(model)
    synth_cpu = bs._cpu() - c
    solve_cpu = r.solve_cpu if sensed is None else sensed[0]
    process_cpu = _process_cpu()  # the process so far; the bench's extras below are not ours
    peak = _hwm_kb() if fresh else bs._peak_kb()
    import resource  # a capped child's build (Storm's, where the program may not fit)
    child_peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    if r.lower_model is None and r.route == "horizon":  # the world solved, no product
        return _ours_on_the_world(model, r, synth_cpu, dict(
            load_cpu=load_cpu, process_cpu=process_cpu, analysis_cpu=analysis[0],
            peak_kb=max(peak - before, 0), process_peak_mb=max(load_peak, peak,
                                                                child_peak) / 1024))
    mdp = r.mdp
    solved = [m for m in (r.lower_model, r.upper_model) if m is not None]
    lp = _each_once(m.lp for m in solved if m.lp is not None)
    out = dict(states=mdp.n_states, transitions=mdp.n_transitions, lower=r.lower,
               trivial=trivial(solved, mdp.initial),
               iteration_sweeps=max(m.iteration.iterations for m in solved),
               iteration_s=max(m.iteration.seconds for m in solved),
               lp_s=sum(m.seconds for m in lp) if lp else None,
               upper=r.upper, product_value=float(r.lower_model.value),
               certified=r.certified, status=r.status.value, solve_cpu=solve_cpu,
               process_cpu=process_cpu, analysis_cpu=analysis[0],
               whole_cpu=load_cpu + synth_cpu, load_cpu=load_cpu,
               product_cpu=max(synth_cpu - solve_cpu, 0.0),
               bytes_per_transition=max(peak - before, 0) * 1024 / max(mdp.n_transitions, 1),
               process_peak_mb=max(load_peak, peak, child_peak) / 1024)
    # untimed from here: the product's digest, the DRN for Storm and the unit sweep
    out["product_digest"] = product_digest(mdp)
    from mitld_lp.solvers import write_drn  # (the route itself does not import it)

    v = np.random.default_rng(0).random(mdp.n_states)
    starts = np.asarray(mdp.row_groups[:-1])
    times = []
    for _ in range(7):  # batches of at least 0.05 s: the CPU clock ticks in 4 ms here
        c, k = bs._cpu(), 0
        while k == 0 or bs._cpu() - c < 0.05:
            np.maximum.reduceat(mdp.matrix @ v, starts)
            k += 1
        times.append((bs._cpu() - c) / k)
    # (without valuations: Storm checks the file as is; naming 1e6 states costs minutes)
    write_drn(mdp, _goal(r), work / "model.drn", overwrite=True, valuations=False)
    # Storm optimises the DRN's target as we do (a checkout before Result.sense: "max")
    (work / "sense.txt").write_text(getattr(r, "sense", "max"))
    return dict(out, sweep_cpu=float(np.median(times)))


def _each_once(items: Any) -> list[Any]:
    """``items`` with each object once (by identity, in their order): where nothing is
    truncated the result's two models are one object, whose LP counts once."""
    seen: set[int] = set()
    return [x for x in items if not (id(x) in seen or seen.add(id(x)))]


def _ours_on_the_world(model: Any, r: Any, synth_cpu: float, got: dict[str, Any],
                       ) -> dict[str, Any]:
    """``work_ours``'s figures for an answer from the world itself (the step-bounded
    route, ``mitld_lp.routes.horizon``: backward induction over the world, no product):
    the sizes are the world's, the unit sweep one over the world's choices, no DRN (its
    Storm peer is Storm's own check of the PRISM property, ``no_product``)."""
    import numpy as np
    import scipy.sparse as sp

    from mitld_lp.worlds.table import table_of

    t = table_of(model.game)
    n, m = t.n_states, int(t.choices[-1])
    matrix = sp.csr_array((t.probabilities, t.targets, t.branches), shape=(m, n))
    v, starts, times = np.random.default_rng(0).random(n), np.asarray(t.choices[:-1]), []
    for _ in range(7):
        c, k = bs._cpu(), 0
        while k == 0 or bs._cpu() - c < 0.05:
            np.maximum.reduceat(matrix @ v, starts)
            k += 1
        times.append((bs._cpu() - c) / k)
    sol = r.part.solution
    return dict(states=n, transitions=int(t.branches[-1]), lower=r.lower, upper=r.upper,
                trivial=None, iteration_sweeps=sol.steps, iteration_s=sol.seconds,
                lp_s=None, product_value=float(r.lower), certified=r.certified,
                status=r.status.value, solve_cpu=r.solve_cpu,
                process_cpu=got["process_cpu"], analysis_cpu=got["analysis_cpu"],
                whole_cpu=got["load_cpu"] + synth_cpu, load_cpu=got["load_cpu"],
                product_cpu=max(synth_cpu - r.solve_cpu, 0.0),
                bytes_per_transition=got["peak_kb"] * 1024 / max(int(t.branches[-1]), 1),
                process_peak_mb=got["process_peak_mb"], product_digest="",
                sweep_cpu=float(np.median(times)), no_product=True)


def trivial(solved: list[Any], initial: int) -> str | None:
    """Why the answer is decided by the graph alone (both models' qualitative sets put
    the initial state at the same 0 or 1, before any number), or ``None`` if it is not
    (then the instance counts in every ratio, however small its value)."""
    said = set()
    for m in solved:
        q = m.qualitative
        if q is None:
            return None
        if bool(q.zero[initial]):
            said.add(f"0 by the graph (the initial state is in {m.which} model's "
                     f"Prob0{'A' if str(q.sense) == 'max' else 'E'})")
        elif bool(q.one[initial]):
            said.add(f"1 by the graph (the initial state is in {m.which} model's "
                     f"Prob1{'E' if str(q.sense) == 'max' else 'A'})")
        else:
            return None
    values = {w.split(" ")[0] for w in said}
    return "; ".join(sorted(said)) if len(values) == 1 else None


def work_storm_check(job: dict[str, Any], work: Path) -> dict[str, Any]:
    import stormpy

    sense = (work / "sense.txt").read_text().strip()
    prop = stormpy.parse_properties(f'P{sense}=? [F "target"]')[0]
    before = bs._rss_kb()
    c = bs._cpu()
    model = stormpy.build_model_from_drn(str(work / "model.drn"))
    parse_cpu = bs._cpu() - c
    checks = batched(model, prop, bs._checks(model, prop, bs.METHODS))
    peak = bs._peak_kb()
    return dict(parse_cpu=parse_cpu, states=model.nr_states, transitions=model.nr_transitions,
                bytes_per_transition=max(peak - before, 0) * 1024 / max(model.nr_transitions, 1),
                **checks)


BATCH = 0.05  # CPU seconds: a check that reads 0 is timed again in batches this long


def batched(model: Any, prop: Any, checks: dict[str, Any]) -> dict[str, Any]:
    """``bench_sweeps._checks``'s figures with each method's check that read 0 CPU
    seconds (under one tick of the CPU clock, which ticks in milliseconds: a tiny
    product's, the grid's) timed again as the unit sweep is: run until a batch takes
    :data:`BATCH` s, the batch over its runs; the best method chosen again from these.
    A check that the clock sees keeps its one reading (the QVBS rows' as before)."""
    import stormpy

    methods = dict(checks["methods"])
    for name, got in methods.items():
        if got["cpu"] > 0:
            continue
        env = bs.storm_env(name)
        c, k = bs._cpu(), 0
        while k == 0 or bs._cpu() - c < BATCH:
            stormpy.model_checking(model, prop, environment=env)
            k += 1
        methods[name] = dict(got, cpu=(bs._cpu() - c) / k, once_cpu=got["cpu"], runs=k)
    best = min(methods, key=lambda m: methods[m]["cpu"])
    return dict(methods=methods, best=best, best_cpu=methods[best]["cpu"])


def work_storm_prism(job: dict[str, Any], work: Path) -> dict[str, Any]:
    """Storm on the PRISM file and the property as published (``qvbs.storm``'s steps),
    checked with the best method found on the DRN."""
    import stormpy

    c = bs._cpu()
    program = stormpy.parse_prism_program(job["prism"])
    undefined = {k.name for k in program.constants if not k.defined}
    constants = job["constants"]
    given = {k: v for k, v in constants.items() if k in undefined}
    if given:
        program, _ = stormpy.instantiate_constants(program, given)
    text = job["property"]
    for name, value in constants.items():  # the properties file's own constants
        if name not in undefined:
            shown = str(value).lower() if isinstance(value, bool) else str(value)
            text = re.sub(rf"(?<![\w\"]){re.escape(name)}(?![\w\"])", shown, text)
    prop = stormpy.parse_properties(text, program)[0]
    model = stormpy.build_model(program, [prop])
    build_cpu = bs._cpu() - c
    method = job["best"]  # None: every sound method, the best one's check (no DRN)
    checks = bs._checks(model, prop, bs.METHODS if method is None else (method,))
    method = checks["best"]
    others = sum(v["cpu"] for k, v in checks["methods"].items() if k != method)
    return dict(build_cpu=build_cpu, whole_cpu=build_cpu + checks["best_cpu"],
                states=model.nr_states, transitions=model.nr_transitions,
                value=checks["methods"][method]["value"],
                # the process as with the best method alone (the others' checks taken out)
                process_cpu=_process_cpu() - others, process_peak_mb=bs._peak_kb() / 1024,
                **checks)


def work_memory(job: dict[str, Any], work: Path) -> dict[str, Any]:
    """``synthesize`` with each stage's memory tracked (``memory_stages``; ``--memory``)."""
    import memory_stages

    from mitld_lp import synthesize

    model = _load(job)
    bs.preload()
    return memory_stages.Tracker(traced=True).run(
        lambda: synthesize(model), lambda r: r.mdp.n_transitions)[1]


WORKERS = {"ours": work_ours, "storm_check": work_storm_check, "storm_prism": work_storm_prism,
           "memory": work_memory}


def _child(route: str, job: dict[str, Any], work: Path, budget: float,
           code: Path | None = None) -> dict[str, Any]:
    """The route in a child process under a CPU budget; its result with
    ``child_cpu`` (the whole child, ``os.wait4``; ``process_cpu`` too unless the route
    measured it before the bench's own extras), or ``{"error": ...}``.  ``code``: the
    repository whose ``mitld_lp`` the child imports (default this one)."""
    (work / "job.json").write_text(json.dumps(job), encoding="utf-8")
    out = work / f"{route}.json"
    out.unlink(missing_ok=True)
    limit = int(budget)

    def cap() -> None:
        resource.setrlimit(resource.RLIMIT_CPU, (limit, limit + 5))

    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    root = bs.ROOT if code is None else code
    env["PYTHONPATH"] = os.pathsep.join([str(root), *filter(None, [env.get("PYTHONPATH")])])
    with tempfile.TemporaryFile() as errors:
        proc = subprocess.Popen([sys.executable, __file__, "--worker", route, str(work)],
                                cwd=root, stdout=subprocess.DEVNULL, stderr=errors,
                                env=env, preexec_fn=cap)
        _, status, usage = os.wait4(proc.pid, 0)
        code = os.waitstatus_to_exitcode(status)
        errors.seek(0)
        err = errors.read().decode(errors="replace")
    cpu = usage.ru_utime + usage.ru_stime
    if code != 0 or not out.is_file():
        why = (f"over the CPU budget of {limit} s" if cpu >= limit - 1
               else f"exit {code}: {(err.strip().splitlines() or ['no output'])[-1][:200]}")
        return {"error": f"{route}: {why}"}
    result = json.loads(out.read_text(encoding="utf-8"))
    result.setdefault("process_cpu", cpu)
    return dict(result, child_cpu=cpu)


# ----------------------------------------------------------------------------- the runs


def jobs(benchmarks: Path, low: int, high: int, families: tuple[str, ...], work: Path,
         ) -> tuple[list[tuple[qvbs.Instance, dict[str, Any]]], list[tuple[str, str]]]:
    """The instances to run as jobs (their model files written to ``work``), and the
    ones left out with the reason."""
    import qvbs
    found, skipped = qvbs.find_instances(benchmarks, high)
    skipped = [s for s in skipped if s[0].split("/")[0].split(" ")[0] in families]
    out = []
    for inst in found:
        if inst.family not in families or inst.qvbs_states < low:
            continue
        missing = [f.name for f in (inst.prism, inst.props) if not f.is_file()]
        if missing:
            skipped.append((inst.name, f"missing from the checkout: {', '.join(missing)}"))
            continue
        texts = qvbs.read_properties(inst.props)
        if inst.prop not in texts:
            skipped.append((inst.name, f"property not in {inst.props.name}"))
            continue
        labels, undefined = qvbs._labels_of(inst)
        try:
            posed = qvbs.pose(texts[inst.prop], labels, inst.constants)
        except qvbs.NotPosed as exc:
            skipped.append((inst.name, str(exc)))
            continue
        path = work / f"{inst.name}.toml"
        path.write_text(qvbs.model_file(inst, posed, undefined), encoding="utf-8")
        out.append((inst, dict(model=str(path), max_states=max(high, inst.qvbs_states),
                               prism=str(inst.prism.resolve()), constants=inst.constants,
                               property=texts[inst.prop])))
    return out, skipped


class Case(NamedTuple):
    """One of the issue's own cases (:data:`CASES`) as a row: its name; no published
    reference (Storm's values stand beside ours instead)."""

    name: str
    reference: float | None = None


def case_jobs(cases: list[str], quick: bool, work: Path) -> list[tuple[Case, dict[str, Any]]]:
    """The cases as jobs (the grid's PRISM and model files written to ``work``): the
    grid (``bench_explore``'s, side :data:`GRID_N`, --quick :data:`QUICK_GRID_N`) from
    its PRISM file and spec as the command line runs it, Storm's whole run on the same
    file with ``Pmax=? [F<=10 "goal"]``; the sensed case (``bench_sensed``'s case
    :data:`SENSED`, --quick :data:`QUICK_SENSED`), no PRISM file."""
    import bench_explore
    import bench_sensed

    out = []
    for case in cases:
        if case == "grid":
            n = QUICK_GRID_N if quick else GRID_N
            prism, model = bench_explore.write_grid(work, n)
            out.append((Case(f"grid.{n}x{n}.{bench_explore.SPEC.replace(' ', '_')}"),
                        dict(case="grid", model=str(model), max_states=None,
                             prism=str(prism), constants={},
                             property=bench_explore.STORM_PROPERTY)))
        else:
            index = QUICK_SENSED if quick else SENSED
            name = bench_sensed.name_of((bench_sensed.QUICK if quick else
                                         bench_sensed.FULL)[index])
            out.append((Case("sensed." + name.replace(" ", "_")),
                        dict(case="sensed", index=index, quick=quick)))
    return out


def measure(inst: qvbs.Instance, job: dict[str, Any], work: Path,
            budget: float, compare: Path | None = None, memory: bool = False,
            ) -> dict[str, Any]:
    """Every route on one instance and its row; ratios only if not trivial (decided
    by the graph alone, :func:`trivial`).
    ``compare``: also ours from that checkout (``base_*`` columns); ``memory``: also the
    stage-by-stage memory of ours (``mem_*`` columns, :func:`work_memory`)."""
    row = _measure(inst, job, work, budget, compare)
    if not memory or "error" in row:
        return row
    got = _child("memory", job, work, budget)
    if "error" in got:
        return dict(row, mem_error=got["error"])
    flat = {f"mem_{stage}_{k}": v for stage, r in got["stages"].items()
            for k, v in (("peak", r["peak"]), ("traced", r.get("traced_peak")),
                         ("kept", r["kept"]))}
    return dict(row, **flat, mem_breakdown=got)


def _measure(inst: qvbs.Instance, job: dict[str, Any], work: Path,
             budget: float, compare: Path | None) -> dict[str, Any]:
    base: dict[str, Any] = {}
    if compare is not None:
        base = _child("ours", job, work, budget, compare)
        (work / "model.drn").unlink(missing_ok=True)
    ours = _child("ours", job, work, budget)
    if "error" in ours:
        return dict(instance=inst.name, error=ours["error"])
    if ours.get("no_product"):  # Storm's peer: every sound method on its own build
        prism = _child("storm_prism", dict(job, best=None), work, budget)
        if "error" in prism:
            return dict(instance=inst.name, error=prism["error"])
        storm = dict(prism, bytes_per_transition=None)
    else:
        storm = _child("storm_check", job, work, budget)
        (work / "model.drn").unlink(missing_ok=True)
        if "error" in storm:
            return dict(instance=inst.name, error=storm["error"])
        prism = (_child("storm_prism", dict(job, best=storm["best"]), work, budget)
                 if "prism" in job else None)  # the sensed case has no PRISM file
    if prism is not None and "error" in prism:
        prism = None
    reference = None if inst.reference is None else float(inst.reference)
    why = ours["trivial"]
    flat = why is not None
    sweep = ours["sweep_cpu"]

    def ratio(a: float, b: float | None) -> float | None:
        return None if flat or b is None or b <= 0 else a / b

    def sweeps(a: float) -> float | None:  # a tiny product's sweep can time as 0
        return a / sweep if sweep > 0 else None

    values = [m["value"] for m in storm["methods"].values()]
    case = job.get("case")
    extra: dict[str, Any] = {}
    if case is not None:  # the issue's own cases: Storm's PRISM run's world and answer
        extra = dict(case=case, storm_prism_states=prism["states"] if prism else None,
                     storm_prism_inside=None if prism is None else
                     ours["lower"] - 1e-9 <= prism["value"] <= ours["upper"] + 1e-9)
        if case == "sensed":
            extra["process_note"] = NO_STORM_PROCESS
    return dict(
        instance=inst.name, value=ours["lower"], upper=ours["upper"], reference=reference,
        degenerate=flat, trivial=why, states=ours["states"],
        transitions=ours["transitions"], iteration_sweeps=ours["iteration_sweeps"],
        iteration_s=ours["iteration_s"], lp_s=ours["lp_s"],
        storm_states=storm["states"], storm_transitions=storm["transitions"],
        sweep_ms=1e3 * sweep, certified=ours["certified"],
        storm_agrees=all(abs(v - ours["product_value"]) <= 1e-6 for v in values),
        storm_prism_value=prism["value"] if prism else None,
        solve_cpu=ours["solve_cpu"], solve_sweeps=sweeps(ours["solve_cpu"]),
        analysis_cpu=ours["analysis_cpu"],
        whole_cpu=ours["whole_cpu"], process_cpu=ours["process_cpu"],
        load_cpu=ours["load_cpu"], product_cpu=ours.get("product_cpu"),
        storm_build_cpu=prism["build_cpu"] if prism else None,
        storm_best=storm["best"].lower(), storm_check_cpu=storm["best_cpu"],
        storm_value=storm["methods"][storm["best"]]["value"],
        storm_check_sweeps=sweeps(storm["best_cpu"]),
        solve_over_storm_check=ratio(ours["solve_cpu"], storm["best_cpu"]),
        storm_prism_cpu=prism["whole_cpu"] if prism else None,
        storm_process_cpu=prism["process_cpu"] if prism else None,
        process_over_storm_process=ratio(ours["process_cpu"],
                                         prism["process_cpu"] if prism else None),
        bytes_per_transition=ours["bytes_per_transition"],
        storm_bytes_per_transition=storm["bytes_per_transition"],
        process_peak_mb=ours.get("process_peak_mb"),
        storm_process_peak_mb=prism.get("process_peak_mb") if prism else None,
        child_cpu=ours["child_cpu"], storm_child_cpu=prism["child_cpu"] if prism else None,
        harness_cpu=ours.get("harness_cpu"),
        storm_harness_cpu=prism.get("harness_cpu") if prism else None,
        **_compared(base, ours, prism, flat, storm["best_cpu"]),
        **{f"storm_{k.lower()}_cpu": v["cpu"] for k, v in storm["methods"].items()},
        **extra,
    )


def _compared(base: dict[str, Any], ours: dict[str, Any], prism: dict[str, Any] | None,
              flat: bool, storm_check: float) -> dict[str, Any]:
    """The ``base_*`` columns of a ``--compare`` run (empty without one); the solve
    stage's ratio to Storm's best check (``storm_check``) as the after's."""
    if not base:
        return {}
    if "error" in base:
        return dict(base_error=base["error"])
    storm = prism["process_cpu"] if prism else None
    return dict(
        base_value=base["lower"], base_upper=base["upper"], base_certified=base["certified"],
        base_solve_cpu=base["solve_cpu"], base_analysis_cpu=base["analysis_cpu"],
        base_solve_over_storm_check=None if flat or not storm_check
        else base["solve_cpu"] / storm_check,
        base_whole_cpu=base["whole_cpu"], base_process_cpu=base["process_cpu"],
        base_load_cpu=base["load_cpu"], base_product_cpu=base.get("product_cpu"),
        base_bytes_per_transition=base["bytes_per_transition"],
        base_process_peak_mb=base.get("process_peak_mb"),
        base_process_over_storm_process=None if flat or not storm
        else base["process_cpu"] / storm,
        same_bracket=(base["lower"], base["upper"]) == (ours["lower"], ours["upper"]),
        same_product=(base["states"], base["transitions"], base.get("product_digest"))
        == (ours["states"], ours["transitions"], ours.get("product_digest")),
    )


def product_digest(mdp: Any) -> str:
    """A SHA-256 of the product as built: its choices, their actions and rows (indices
    and probabilities, bit for bit), the initial state, the target, sink and truncated
    masks, the states' codes and the records of 64 states spread over it (two products
    with one digest are taken to be the same product, state for state).  Integer arrays
    are hashed as 64-bit values, so a narrower index type is the same product."""
    import hashlib

    import numpy as np

    h = hashlib.sha256()
    m = mdp.matrix
    for a in (mdp.row_groups, mdp.choice_actions, m.indptr, m.indices, m.data, mdp.target,
              mdp.sink, mdp.truncated, getattr(mdp.states, "_keys", np.zeros(0))):
        a = np.ascontiguousarray(a)
        if a.dtype.kind in "iu":  # index values, not their width: int32 and int64 alike
            a = a.astype(np.int64)
        h.update(f"{a.dtype.str}{a.shape}".encode())
        h.update(a.tobytes())
    n = len(mdp.states)
    shown = [repr(mdp.states[int(i)]) for i in np.unique(np.linspace(0, n - 1, 64).astype(int))]
    h.update(repr((mdp.action_names, mdp.initial, m.shape, shown)).encode())
    return h.hexdigest()


COMPARED = ("instance", "value", "base_value", "same_bracket", "same_product", "states",
            "transitions", "base_analysis_cpu", "analysis_cpu", "base_solve_cpu", "solve_cpu",
            "storm_check_cpu",
            "base_solve_over_storm_check", "solve_over_storm_check", "base_whole_cpu",
            "whole_cpu", "base_load_cpu", "load_cpu", "storm_build_cpu", "base_product_cpu",
            "product_cpu", "base_process_cpu", "process_cpu",
            "storm_process_cpu", "base_process_over_storm_process",
            "process_over_storm_process", "base_bytes_per_transition",
            "bytes_per_transition", "storm_bytes_per_transition", "base_process_peak_mb",
            "process_peak_mb", "storm_process_peak_mb")


def _line(row: dict) -> str:
    """A row on one line: every column of :data:`COLUMNS` it has, each answer in full
    beside its times."""
    return "  ".join(f"{k}={bs._full(k, row.get(k))}" for k in COLUMNS
                     if row.get(k) is not None)


def misses(rows: list[dict]) -> list[str]:
    """The targets missed (``bench_sweeps.misses``): on the QVBS instances from
    ``bench_sweeps.BIG`` states up; on the cases whatever their product's size (the
    grid's world has 4,004,001 states, its product those within the horizon; the
    sensed product is built by the route), each ratio that has a peer; trivial rows
    never."""
    out = bs.misses([r for r in rows if not r.get("case")])
    for r in rows:
        if not r.get("case") or r.get("degenerate"):
            continue
        out += bs.target_misses(r)
    return out


def report(rows: list[dict], skipped: list[tuple[str, str]],
           only: list[str] | None = None) -> str:
    def table(part: list[dict]) -> str:
        return _common.markdown_table(COLUMNS, [[bs._fmt(r.get(k)) for k in COLUMNS]
                                                for r in part])

    done = [r for r in rows if "error" not in r]
    good = [r for r in done if not r["degenerate"]]
    flat = [r for r in done if r["degenerate"]]
    text = "## QVBS PRISM MDPs of at least 1e5 states, ours and Storm in one run\n\n"
    if only:
        text += (f"A subset (`--only`): the {len([r for r in rows if not r.get('case')])} "
                 "QVBS instances below; the families' other instances were not run "
                 "here.\n\n")
    text += table(good) if good else "No non-trivial instance was run.\n"
    compared = [r for r in done if "base_value" in r]
    if compared:
        text += ("\nBefore (`base_*`: the package of the `--compare` checkout) and after "
                 "(this checkout), in the same run; ratios only for the non-trivial "
                 "instances:\n\n" + _common.markdown_table(
                     COMPARED, [[bs._fmt(r.get(k)) for k in COMPARED] for r in compared]))
    if flat:
        text += ("\nTrivial instances (the answer decided by the graph alone, exactly 0 or "
                 "1 before any number; no ratio is taken from them):\n\n" + table(flat)
                 + "\n" + "".join(f"- {r['instance']}: {r['trivial']}\n" for r in flat))
    missed = misses(good)
    big = [r for r in good if r["states"] >= bs.BIG or r.get("case")]
    text += (f"\nTargets on the non-trivial instances of at least {bs.BIG:,} states "
             "and on the non-trivial cases (grid, sensed) "
             "(solve <= 2x Storm's best check, whole process <= 1x Storm's, <= 50 bytes "
             f"per transition from {bs.MEMORY_FROM:,} transitions): "
             + ("no such instance was run.\n" if not big else
                                     "all met.\n" if not missed else
                                     "missed:\n\n" + "".join(f"- {m}\n" for m in missed)))
    cases = [r for r in done if r.get("case")]
    if cases:
        text += ("\nThe cases: " + "".join(
            f"\n- {r['instance']}: " + "; ".join(filter(None, [
                f"Storm's PRISM run on {r['storm_prism_states']:,} states, its value "
                f"{'inside' if r['storm_prism_inside'] else 'OUTSIDE'} our bracket (1e-9)"
                if r.get("storm_prism_states") is not None else None,
                f"process ratio left out: {r['process_note']}"
                if r.get("process_note") else None]))
            for r in cases) + "\n")
    left = [(r["instance"], r["error"]) for r in rows if "error" in r] + [
        s for s in skipped if not s[1].startswith(_NOT_A_TASK)]
    if left:
        text += "\nNot run:\n\n" + "".join(f"- {what}: {why}\n" for what, why in left)
    broken = [r for r in done if "mem_breakdown" in r]
    if broken:
        import memory_stages

        text += ("\nMemory by stage (`--memory`, a child of its own under tracemalloc; "
                 "`peak` resident, `traced_peak` Python's traced allocations, `kept` the "
                 "resident size at the stage's exit):\n\n" + "\n".join(
                     memory_stages.text(r["instance"], r["mem_breakdown"]) for r in broken))
    quiet = len(skipped) - len(left) + len([r for r in rows if "error" in r])
    if quiet:
        text += (f"\n{quiet} QVBS properties of these families are not probabilities a "
                 "task expresses (expected rewards, qualitative ones): not run.\n")
    return text


def _write(out: Path, rows: list[dict], skipped: list[tuple[str, str]],
           only: list[str] | None, planned: int, argv: list[str] | None) -> str:
    """``bench_qvbs.csv``, ``.md`` and ``_machine.txt`` of the rows so far (``planned``:
    how many instances the run takes on; the report says how many are still to come)."""
    from bench_scaling import machine_text

    header = sorted({k for r in rows for k in r} - {"mem_breakdown"}, key=lambda k: (
        COLUMNS.index(k) if k in COLUMNS else len(COLUMNS), k))
    _common.write_csv(out / "bench_qvbs.csv", header,  # full precision (the md rounds)
                      [["" if r.get(k) is None else r[k] for k in header] for r in rows])
    text = report(rows, skipped, only)
    if len(rows) < planned:
        text += f"\nRun in progress or cut short: {len(rows)} of {planned} instances done.\n"
    _common.write_text(out / "bench_qvbs.md", text)
    _common.write_text(out / "bench_qvbs_machine.txt", machine_text(
        "shared 2-core machine, other processes running; one run, CPU seconds",
        [f"command: python experiments/bench_qvbs.py {' '.join(argv or sys.argv[1:])}",
         "storm: each sound method (force_soundness, 1e-9 absolute) on our DRN; the best "
         "one again on the PRISM file and property as published, in a process of its own"]))
    return text


def main(argv: list[str] | None = None) -> list[dict]:
    ap = _common.parser(__doc__.splitlines()[0])
    ap.add_argument("--qvbs", type=Path, default=None,
                    help="the benchmarks/ folder of a checkout of github.com/ahartmanns/qcomp "
                    "(without it: the cases alone)")
    ap.add_argument("--cases", nargs="*", choices=CASES, default=list(CASES),
                    help="the issue's own cases, after the QVBS instances (default: both; "
                    "--quick: the 201x201 grid and the smallest sensed case)")
    ap.add_argument("--no-cases", action="store_true", help="the QVBS instances alone")
    ap.add_argument("--min-states", type=int, default=MIN_STATES)
    ap.add_argument("--max-states", type=int, default=MAX_STATES)
    ap.add_argument("--family", action="append", choices=FAMILIES,
                    help="only these families (repeatable)")
    ap.add_argument("--only", nargs="*", default=None, metavar="NAME",
                    help="only these instances (e.g. firewire_dl.3-600.deadline)")
    ap.add_argument("--compare", type=Path, default=None, metavar="DIR",
                    help="also run ours from the checkout DIR (its mitld_lp) on each "
                    "instance, before this checkout's, and report both")
    ap.add_argument("--memory", action="store_true", help="also each instance's memory "
                    "stage by stage (a child of its own): mem_* columns, a table each")
    ap.add_argument("--start", choices=("library", "command"), default="library",
                    help="how our worker process starts: as a program importing the "
                    "package (default), or as the command line starts "
                    "(mitld_lp.startup.lean_start and the collector held while importing)")
    ap.add_argument("--budget", type=float, default=BUDGET,
                    help=f"CPU seconds per child process (default {BUDGET:g})")
    args = ap.parse_args(argv)
    cases = [] if args.no_cases else list(dict.fromkeys(args.cases))
    if args.qvbs is None and not cases:
        ap.error("--qvbs is required unless a case runs (--cases grid sensed)")
    if args.qvbs is not None and not (args.qvbs / "mdp").is_dir():
        ap.error(f"--qvbs {args.qvbs}: no mdp/ folder (give qcomp's benchmarks/ folder)")
    out = _common.out_dir(args)
    low, high = ((0, QUICK_MAX_STATES) if args.quick else (args.min_states, args.max_states))
    families = tuple(args.family or FAMILIES)
    rows: list[dict] = []
    with tempfile.TemporaryDirectory(prefix="bench_qvbs_") as tmp:
        todo: list[tuple[Any, dict[str, Any]]] = []
        skipped: list[tuple[str, str]] = []
        if args.qvbs is not None:
            todo, skipped = jobs(args.qvbs, low, high, families, Path(tmp))
        if args.only:
            todo = [(i, j) for i, j in todo if i.name in set(args.only)]
        todo.sort(key=lambda t: t[0].qvbs_states)  # smallest first: a cut-short run has rows
        if args.quick:
            todo = todo[-QUICK_COUNT:]
        todo += case_jobs(cases, args.quick, Path(tmp))  # after the QVBS instances
        todo = [(i, dict(j, start=args.start)) for i, j in todo]
        text = _write(out, rows, skipped, args.only, len(todo), argv)
        for inst, job in todo:
            work = Path(tmp) / re.sub(r"[^\w.+-]+", "_", inst.name)
            work.mkdir()
            rows.append(measure(inst, job, work, args.budget, args.compare, args.memory))
            row = rows[-1]
            print(f"{inst.name}: not run ({row['error']})" if "error" in row else
                  _line(row) + (f"  apart: {row['trivial']}" if row["trivial"] else ""),
                  flush=True)
            # written after every instance: a run cut short keeps the rows it has
            text = _write(out, rows, skipped, args.only, len(todo), argv)
    print(text)
    print(f"written: {_common.shown(out / 'bench_qvbs.csv')}, "
          f"{_common.shown(out / 'bench_qvbs.md')}")
    return rows


def worker(route: str, work: str) -> None:
    # the CPU before the route: the interpreter and this script's own imports (the
    # same for every route; ``harness_cpu``), included in the process figures
    harness = _process_cpu()
    job = json.loads((Path(work) / "job.json").read_text(encoding="utf-8"))
    result = dict(WORKERS[route](job, Path(work)), harness_cpu=harness)
    (Path(work) / f"{route}.json").write_text(json.dumps(result), encoding="utf-8")


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--worker":
        worker(*sys.argv[2:4])
    else:
        main()
