"""Benchmark: how the planner scales, against Storm on the same task, in one run.

Two families of instances, on the same model per instance:

* ``bus`` -- the case study grown: an ``n x n`` grid (slip 0.1, start (0, 0)), two
  geometric buses, the task
  ``(D[geometric(0.8)] b1 & F(b1 & F[0,d] A)) | (D[geometric(0.3)] b2 & F(b2 & F[0,d] B))``
  with the stations at the 4x4 layout scaled: ``A = (n//4, n//2)``, ``B = (3n//4, 0)``;
* ``bus_scaled`` -- the same task with both hazards scaled by ``4/n`` (the buses come
  later as the grid grows, so the robot still has time to get there) and ``B`` at
  ``(n - 1, 0)``: its optimum stays near 0.25 from ``n = 16`` to ``128``, where the
  ``bus`` family's collapses to 1e-9 and below (a degenerate benchmark); ``n = 4`` is the
  case study itself;
* ``events`` -- no event memoryless: three sites in the far corners of an ``n x n``
  grid, one event each (a pmf on steps 1-4, ``1 + Poisson(n)``, a discretised
  ``Weibull(2, n)``), task: reach the site of some event within ``d`` steps of it;
  epsilon 0.01 (the Poisson and Weibull clocks are truncated, the LPs solve the lower
  model).

For each instance every route runs in its own child process (``--worker``), so its
peak memory is the child's own (``ru_maxrss`` from ``os.wait4``) and its time budget is
enforced: the child arms a ``SIGALRM`` timer when its work starts (after imports and loading the
model), whose default action ends it even inside a native solver call; a route killed
at its budget is recorded as ``skipped`` with the budget, and not run again on a larger
instance of its family (estimated from the state counts: a larger product is not
solved faster).  The routes:

* ``build``: the product (seconds, peak MB); the child then stores the MDP (pickle)
  and our DRN export for the others (untimed; the DRN write time is reported apart);
* ``default``: ``synthesize`` end to end with its defaults, on
  ``Model.from_game(world, spec)`` (or ``synthesize(world, spec)`` before that API); the
  process's wall time including imports is ``default_proc_s``;
* ``topo_lp`` / ``mono_lp``: ``solve_lp(mdp, target, layout="blocks" / "whole")`` (in
  older versions ``decompose=True / False``) with
  Clarabel through cvxpy; without either parameter ``topo_lp`` is
  ``unavailable`` and ``mono_lp`` is plain ``solve_lp`` (monolithic then);
* ``highs_lp``: the monolithic LP with HiGHS through cvxpy;
* ``ii``: ``interval_iteration`` (tolerance 1e-9 on the initial state's gap);
* ``storm_drn``: stormpy reads our DRN (``storm_drn_parse_s``) and checks
  ``Pmax=? [F "target"]`` by sound value iteration, precision 1e-9 absolute
  (``storm_drn_check_s``; ``storm_drn_s`` is their sum);
* ``storm_prism`` (bus family): Storm's whole run on an independent PRISM encoding of
  the task, ``experiments/prism/bus.prism`` with its constants filled in per instance:
  parse, build, sound check as above.  Its value checks our whole pipeline
  (automaton, product, solver); for n = 4, d = 3 it is the case study (0.9244053).

Every value is the optimum at the initial state (lower model); ``max_diff`` is the
largest difference between the routes that returned one.  Printed per row: the ratios
``default / storm_prism`` (whole runs), ``default / storm_drn check`` and
``ii / storm_drn check``, none for an instance whose optimum is below 1e-3 or above
1 - 1e-3 (degenerate: the plain ``bus`` family's from n = 32 on; use ``bus_scaled``).
Written: ``scaling.csv``, ``scaling_machine.txt`` (cpu,
cores, RAM, versions, date, load) and ``scaling.png`` (log-log seconds against states).

The committed first run (moderate budgets) was::

    python experiments/bench_scaling.py --bus-sizes 8 16 32 --deadlines 3 10 \\
        --event-sizes 8 16 24 32 --budget 120 --out experiments/results

The full table (after the faster solvers and product builder land)::

    python experiments/bench_scaling.py --bus-sizes 8 16 32 64 128 --deadlines 3 6 10 \\
        --event-sizes 8 16 32 48 64 --budget 600 --out experiments/results

``--quick`` runs two tiny instances (under a minute) into ``experiments/out/quick``
(or ``--out``), never over ``experiments/results``.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import datetime as dt
import json
import math
import os
import pickle
import platform
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
if str(HERE) not in sys.path:  # run as a script or imported by the tests
    sys.path.insert(0, str(HERE))
# The parent imports experiments/_common.py where it needs it (it loads matplotlib): the
# children, one per route and instance, start without it.

RESULTS = HERE / "results"
QUICK_OUT = HERE / "out" / "quick"
PRISM_TEMPLATE = HERE / "prism" / "bus.prism"

BUS_SPEC = ("(D[geometric({p1})] b1 & F(b1 & F[0,{d}] A)) | "
            "(D[geometric({p2})] b2 & F(b2 & F[0,{d}] B))")
EVENTS_SPEC = ("(D[pmf(0.2, 0.3, 0.3, 0.2)] f1 & F(f1 & F[0,{d}] S1))"
               " | (D[poisson({lam})] f2 & F(f2 & F[0,{d}] S2))"
               " | (D[weibull(2.0, {scale})] f3 & F(f3 & F[0,{d}] S3))")
SLIP = 0.1
BUS_P = (0.8, 0.3)
EVENTS_EPSILON = 0.01
SOUND_PRECISION = "1/1000000000"  # Storm's sound value iteration, absolute 1e-9
AGREE_TOL = 1e-6

ROUTES = ("build", "default", "topo_lp", "mono_lp", "highs_lp", "ii", "storm_drn",
          "storm_prism")
SOLVE_ROUTES = ROUTES[1:]
NEEDS_MDP = ("topo_lp", "mono_lp", "highs_lp", "ii")
# Extra numbers a route reports (besides status, seconds, value) that go to the CSV.
EXTRA = {
    "build": ("states", "choices", "transitions", "delta_mb", "child_mb", "drn_write_s"),
    "default": ("states", "upper", "certified"),
    "ii": ("upper", "iterations"),
    "storm_drn": ("parse_s", "check_s"),
    "storm_prism": ("parse_s", "build_s", "check_s", "states"),
}
SETUP_SLACK = 600.0  # seconds a child may spend importing and loading before its budget


# ---------------------------------------------------------------------------- instances


@dataclass(frozen=True, slots=True)
class Instance:
    """One benchmark instance: a family, a grid size ``n`` and a deadline ``d``."""

    family: str  # "bus", "bus_scaled" or "events"
    n: int
    d: int

    @property
    def name(self) -> str:
        return f"{self.family}_n{self.n}_d{self.d}"

    @property
    def epsilon(self) -> float:
        return EVENTS_EPSILON if self.family == "events" else 0.01

    @property
    def stations(self) -> dict[str, tuple[int, int]]:
        n = self.n
        if self.family == "bus":
            # the 4x4 layout A = (1, 2), B = (3, 0), scaled
            return {"A": (n // 4, n // 2), "B": (3 * n // 4, 0)}
        if self.family == "bus_scaled":
            return {"A": (n // 4, n // 2), "B": (n - 1, 0)}
        return {"S1": (0, n - 1), "S2": (n - 1, n - 1), "S3": (n - 1, 0)}

    @property
    def is_bus(self) -> bool:
        """A bus family (it has a PRISM encoding)."""
        return self.family in ("bus", "bus_scaled")

    @property
    def hazards(self) -> tuple[float, float]:
        """The two buses' per-step probabilities (``bus_scaled``: ``BUS_P * 4 / n``)."""
        if self.family == "bus_scaled":
            return tuple(round(p * 4.0 / self.n, 12) for p in BUS_P)  # type: ignore[return-value]
        return BUS_P

    def spec(self) -> str:
        if self.is_bus:
            p1, p2 = self.hazards
            return BUS_SPEC.format(p1=repr(p1), p2=repr(p2), d=self.d)
        return EVENTS_SPEC.format(lam=float(self.n), scale=float(self.n), d=self.d)

    def world(self) -> Any:
        from mitld_lp import GridWorld

        return GridWorld.make(self.n, self.n, start=(0, 0), slip=SLIP,
                              regions={k: [v] for k, v in self.stations.items()})

    def prism(self) -> str:
        """The PRISM encoding of a bus instance: the template with its constants set."""
        if not self.is_bus:
            raise ValueError(f"{self.name}: only the bus family has a PRISM encoding")
        (ax, ay), (bx, by) = self.stations["A"], self.stations["B"]
        p1, p2 = self.hazards
        consts: dict[str, object] = dict(N=self.n, X0=0, Y0=0, AX=ax, AY=ay, BX=bx, BY=by,
                                         D=self.d, P1=repr(p1), P2=repr(p2), SLIP=SLIP)
        text = PRISM_TEMPLATE.read_text(encoding="utf-8")
        for key, value in consts.items():
            text, found = re.subn(rf"^const (int|double) {key};",
                                  lambda m, k=key, v=value: f"const {m.group(1)} {k} = {v};",
                                  text, flags=re.M)
            if found != 1:
                raise ValueError(f"{PRISM_TEMPLATE}: no line 'const ... {key};' to fill in")
        return text


# ---------------------------------------------------------------------------- workers
# Each runs in a fresh child process and returns a JSON-ready dict.  ``arm()`` starts
# the route's budget: the default action of SIGALRM ends the process.


def _maxrss_mb() -> float:
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _load_mdp(work: Path) -> Any:
    with (work / "mdp.pkl").open("rb") as f:
        return pickle.load(f)


def _decompose_kw(fn: Any, value: bool) -> dict[str, Any] | None:
    """``{"layout": "blocks" / "whole"}`` if ``fn`` takes it, else ``{"decompose": value}``
    (older versions) if it takes that, else None."""
    import inspect

    parameters = inspect.signature(fn).parameters
    if "layout" in parameters:
        return {"layout": "blocks" if value else "whole"}
    return {"decompose": value} if "decompose" in parameters else None


def _storm_env() -> Any:
    import stormpy
    import stormpy.environments

    env = stormpy.Environment()
    env.solver().force_soundness = True
    minmax = env.solver().min_max()
    minmax.method = stormpy.environments.MinMaxMethod.SOUND_VALUE_ITERATION
    minmax.precision = stormpy.Rational(SOUND_PRECISION)
    minmax.relative_termination_criterion = False
    return env


def _storm_value(model: Any, prop: Any, env: Any) -> tuple[float, float]:
    """Storm's value at the (single) initial state, and the seconds of the check."""
    import stormpy

    t = time.perf_counter()
    result = stormpy.model_checking(model, prop, environment=env)
    seconds = time.perf_counter() - t
    (init,) = model.initial_states
    return float(result.get_value(init)), seconds


def work_build(inst: Instance, work: Path, arm: Any) -> dict[str, Any]:
    from mitld_lp import Model
    from mitld_lp.solvers import write_drn
    from mitld_lp.synthesis import build_product

    model = Model.from_game(inst.world(), inst.spec(), epsilon=inst.epsilon)
    before = _maxrss_mb()
    arm()
    t = time.perf_counter()
    # the stages exactly as synthesize() wires them
    mdp = build_product(model.game, model.spec, model.distributions, epsilon=model.epsilon,
                        max_states=50_000_000, progress=False).mdp
    seconds = time.perf_counter() - t
    signal.setitimer(signal.ITIMER_REAL, 0)
    peak = _maxrss_mb()
    with (work / "mdp.pkl").open("wb") as f:
        pickle.dump(mdp, f, protocol=pickle.HIGHEST_PROTOCOL)
    t = time.perf_counter()
    write_drn(mdp, mdp.target, work / "model.drn", overwrite=True)
    drn_s = time.perf_counter() - t
    # peak_mb: when the product was done (the pickle and the DRN writer come after)
    return dict(status="built", seconds=seconds, states=mdp.n_states, choices=mdp.n_choices,
                transitions=mdp.n_transitions, delta_mb=peak - before,
                drn_write_s=drn_s, peak_mb=peak)


def work_default(inst: Instance, work: Path, arm: Any) -> dict[str, Any]:
    from mitld_lp import Model, synthesize

    world, spec = inst.world(), inst.spec()
    arm()
    t = time.perf_counter()
    from_game = getattr(Model, "from_game", None)
    if from_game is not None:  # synthesize(model): the API since issue 9
        r = synthesize(from_game(world, spec, epsilon=inst.epsilon))
    else:  # synthesize(game, spec)
        r = synthesize(world, spec, epsilon=inst.epsilon)
    seconds = time.perf_counter() - t
    return dict(status=r.status.value, seconds=seconds, value=r.lower_model.value,
                upper=r.upper, certified=r.certified, states=r.mdp.n_states)


def _work_lp(work: Path, arm: Any, solver: str, decompose: bool) -> dict[str, Any]:
    from mitld_lp.solvers import solve_lp

    kw = _decompose_kw(solve_lp, decompose)
    if kw is None and decompose:
        return dict(status="unavailable", note="solve_lp has no 'layout' parameter")
    mdp = _load_mdp(work)
    arm()
    t = time.perf_counter()
    r = solve_lp(mdp, mdp.target, solver=solver, **(kw or {}))
    seconds = time.perf_counter() - t
    return dict(status=r.status.value, seconds=seconds, value=r.value)


def work_topo_lp(inst: Instance, work: Path, arm: Any) -> dict[str, Any]:
    return _work_lp(work, arm, "CLARABEL", True)


def work_mono_lp(inst: Instance, work: Path, arm: Any) -> dict[str, Any]:
    return _work_lp(work, arm, "CLARABEL", False)


def work_highs_lp(inst: Instance, work: Path, arm: Any) -> dict[str, Any]:
    return _work_lp(work, arm, "HIGHS", False)


def work_ii(inst: Instance, work: Path, arm: Any) -> dict[str, Any]:
    from mitld_lp.solvers import interval_iteration

    mdp = _load_mdp(work)
    arm()
    t = time.perf_counter()
    r = interval_iteration(mdp, mdp.target, progress=False)
    seconds = time.perf_counter() - t
    return dict(status=r.status.value, seconds=seconds, value=r.value_lower,
                upper=r.value_upper, iterations=r.iterations)


def work_storm_drn(inst: Instance, work: Path, arm: Any) -> dict[str, Any]:
    import stormpy

    env = _storm_env()
    prop = stormpy.parse_properties('Pmax=? [F "target"]')[0]
    arm()
    t = time.perf_counter()
    model = stormpy.build_model_from_drn(str(work / "model.drn"))
    parse_s = time.perf_counter() - t
    value, check_s = _storm_value(model, prop, env)
    return dict(status="optimal", seconds=parse_s + check_s, value=value, parse_s=parse_s,
                check_s=check_s)


def work_storm_prism(inst: Instance, work: Path, arm: Any) -> dict[str, Any]:
    import stormpy

    path = work / f"{inst.name}.prism"
    path.write_text(inst.prism(), encoding="utf-8")
    env = _storm_env()
    arm()
    t = time.perf_counter()
    program = stormpy.parse_prism_program(str(path))
    prop = stormpy.parse_properties('Pmax=? [F "target"]', program)[0]
    parse_s = time.perf_counter() - t
    t = time.perf_counter()
    model = stormpy.build_model(program, [prop])
    build_s = time.perf_counter() - t
    value, check_s = _storm_value(model, prop, env)
    return dict(status="optimal", seconds=parse_s + build_s + check_s, value=value,
                parse_s=parse_s, build_s=build_s, check_s=check_s, states=model.nr_states)


WORKERS = {
    "build": work_build, "default": work_default, "topo_lp": work_topo_lp,
    "mono_lp": work_mono_lp, "highs_lp": work_highs_lp, "ii": work_ii,
    "storm_drn": work_storm_drn, "storm_prism": work_storm_prism,
}


# Imported before a route's clock starts (the library imports them on first use): the
# route's seconds are its work, as Storm's are without stormpy's import; the first-use
# cost is in the whole process's time (``*_proc_s``).
PRELOAD = ("scipy.sparse.csgraph", "scipy.stats", "cvxpy", "clarabel", "highspy")


def worker_main(route: str, inst: Instance, work: Path, budget: float) -> None:
    """The child's side: run ``route`` and write ``work/ROUTE.json``."""
    def arm() -> None:
        signal.setitimer(signal.ITIMER_REAL, budget)

    if not route.startswith("storm"):
        import importlib

        for name in PRELOAD:
            try:
                importlib.import_module(name)
            except ImportError:  # an optional solver: its route will say so
                pass
    try:
        out = WORKERS[route](inst, work, arm)
    except Exception as exc:  # a failure of the route is a result of the benchmark
        out = dict(status="failed", note=f"{type(exc).__name__}: {exc}"[:300])
    signal.setitimer(signal.ITIMER_REAL, 0)
    (work / f"{route}.json").write_text(json.dumps(out), encoding="utf-8")


# ---------------------------------------------------------------------------- parent side


@dataclass(frozen=True, slots=True)
class RouteRun:
    """What one child process reported (or why there is no report)."""

    status: str
    seconds: float | None = None
    value: float | None = None
    peak_mb: float | None = None
    proc_s: float | None = None
    extra: dict[str, Any] = dataclasses.field(default_factory=dict)
    note: str = ""


def run_route(route: str, inst: Instance, work: Path, budget: float,
              mem_budget_mb: float | None) -> RouteRun:
    """Run ``route`` in a child; peak memory from ``os.wait4``, budget by SIGALRM there
    (and a kill from here if setup hangs past ``SETUP_SLACK``)."""
    report = work / f"{route}.json"
    report.unlink(missing_ok=True)
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(
        [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])
    cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", route,
           "--instance", json.dumps(dataclasses.asdict(inst)), "--work", str(work),
           "--budget", str(budget)]

    def limit() -> None:  # runs in the child before exec
        if mem_budget_mb is not None:
            import resource

            cap = int(mem_budget_mb * 2**20)
            resource.setrlimit(resource.RLIMIT_AS, (cap, cap))

    t = time.perf_counter()
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            preexec_fn=limit if mem_budget_mb is not None else None)
    killer = threading.Timer(budget + SETUP_SLACK, proc.kill)
    killer.start()
    assert proc.stderr is not None
    stderr = proc.stderr.read()  # until the child ends (it writes little)
    _, status, usage = os.wait4(proc.pid, 0)
    killer.cancel()
    proc.returncode = os.waitstatus_to_exitcode(status)  # already reaped: tell Popen
    proc_s = time.perf_counter() - t
    peak = usage.ru_maxrss / 1024.0
    code = proc.returncode
    if code == -signal.SIGALRM:
        return RouteRun("skipped", peak_mb=peak, proc_s=proc_s,
                        note=f"over its {budget:g} s budget")
    if code != 0 or not report.exists():
        tail = stderr.decode(errors="replace").strip().splitlines()[-1:] or [""]
        return RouteRun("failed", peak_mb=peak, proc_s=proc_s,
                        note=f"exit {code}: {tail[0][:200]}")
    out = json.loads(report.read_text(encoding="utf-8"))
    if out["status"] == "unavailable":  # nothing ran: no time, no memory to speak of
        return RouteRun("unavailable", note=out.get("note", ""))
    extra = {k: v for k, v in out.items()
             if k not in ("status", "seconds", "value", "note", "peak_mb")}
    if "peak_mb" in out:  # the child says at what point its peak counts
        extra["child_mb"] = peak
        peak = float(out["peak_mb"])
    return RouteRun(out["status"], out.get("seconds"), out.get("value"), peak, proc_s,
                    extra, out.get("note", ""))


@dataclass(frozen=True, slots=True)
class Row:
    """One instance with the runs of all its routes."""

    inst: Instance
    runs: dict[str, RouteRun]
    budget: float

    def values(self) -> list[float]:
        return [r.value for r in self.runs.values()
                if r.value is not None and math.isfinite(r.value)]

    def value_spread(self) -> float:
        values = self.values()
        return max(values) - min(values) if len(values) >= 2 else float("nan")

    def relative_spread(self) -> float:
        """The spread over the largest value (the bus values fall to 1e-4 on big grids,
        where an absolute 1e-8 says less)."""
        values = self.values()
        top = max(values, default=0.0)
        return self.value_spread() / top if top > 0 else float("nan")

    def seconds(self, route: str, part: str | None = None) -> float | None:
        run = self.runs.get(route)
        if run is None or run.seconds is None or run.status in ("skipped", "failed"):
            return None
        return float(run.extra[part]) if part else run.seconds


def _ratio(a: float | None, b: float | None) -> float | None:
    return a / b if a is not None and b else None


RATIO_KEYS = ("default/storm_prism", "default/storm_check", "ii/storm_check")


DEGENERATE = 1e-3
"""An optimum below this (or above 1 - this) leaves a solver almost nothing to do: such
an instance is reported, never in a ratio."""


def degenerate(row: Row) -> bool:
    """Whether the instance's optimum (the largest value any route found) is degenerate."""
    values = row.values()
    return bool(values) and not DEGENERATE <= max(values) <= 1.0 - DEGENERATE


def ratios(row: Row) -> dict[str, float | None]:
    """The speed ratios printed per row (keys: ``RATIO_KEYS``); None where a side is
    missing or the optimum is degenerate (:func:`degenerate`)."""
    if degenerate(row):
        return dict.fromkeys(RATIO_KEYS)
    check = row.seconds("storm_drn", "check_s")
    return dict(zip(RATIO_KEYS, (
        _ratio(row.seconds("default"), row.seconds("storm_prism")),
        _ratio(row.seconds("default"), check),
        _ratio(row.seconds("ii"), check),
    ), strict=True))


def run_instance(inst: Instance, budget: float, mem_budget_mb: float | None,
                 too_big: dict[tuple[str, str], int], work_root: Path) -> Row:
    """All routes on ``inst``; ``too_big[(family, route)]`` is the smallest state count
    at which the route went over its budget (then larger instances skip it unrun)."""
    work = work_root / inst.name
    work.mkdir(parents=True, exist_ok=True)
    runs: dict[str, RouteRun] = {}

    def estimate_skip(route: str, states: int | None) -> RouteRun | None:
        known = too_big.get((inst.family, route))
        if known is not None and states is not None and states >= known:
            return RouteRun("skipped", note=f"estimate: over the {budget:g} s budget at "
                                            f"{known:,} states already")
        return None

    # the build's size is not known before it runs: a grid at least as large, with the
    # same deadline, as one whose build went over the budget is skipped
    build_key = (f"{inst.family}/d{inst.d}", "build")
    if build_key in too_big and inst.n >= too_big[build_key]:
        build = RouteRun("skipped", note=f"estimate: the {too_big[build_key]}x"
                                         f"{too_big[build_key]} build was over the "
                                         f"{budget:g} s budget")
    else:
        build = run_route("build", inst, work, budget, mem_budget_mb)
    runs["build"] = build
    states = build.extra.get("states")
    for route in SOLVE_ROUTES:
        if route == "storm_prism" and not inst.is_bus:
            runs[route] = RouteRun("n/a", note="no PRISM encoding of this family")
            continue
        if states is None and route != "storm_prism":
            runs[route] = RouteRun("skipped", note="no product (build did not finish)")
            continue
        run = estimate_skip(route, states) or run_route(route, inst, work, budget,
                                                        mem_budget_mb)
        if run.status == "skipped" and not run.note.startswith("estimate") and states:
            too_big[inst.family, route] = min(states, too_big.get((inst.family, route),
                                                                  states))
        runs[route] = run
    if build.status == "skipped" and build_key not in too_big:
        too_big[build_key] = inst.n
    for f in ("mdp.pkl", "model.drn"):  # large; the CSV has what matters
        (work / f).unlink(missing_ok=True)
    return Row(inst, runs, budget)


# ---------------------------------------------------------------------------- output


def _fmt(x: Any, digits: int = 3) -> str:
    if x is None:
        return ""
    if isinstance(x, bool):
        return str(x)
    if isinstance(x, float):
        if not math.isfinite(x):
            return "nan"
        return f"{x:.{digits}g}" if abs(x) < 1e-3 or abs(x) >= 1e5 else f"{x:.{digits}f}"
    return str(x)


def csv_header() -> list[str]:
    head = ["family", "n", "deadline", "budget_s"]
    for route in ROUTES:
        head += [f"{route}_status", f"{route}_s", f"{route}_mb", f"{route}_value"]
        head += [f"{route}_{k}" for k in EXTRA.get(route, ())]
        if route in ("default", "storm_prism"):
            head.append(f"{route}_proc_s")
        head.append(f"{route}_note")
    head += ["max_diff", "max_rel_diff"]
    head += [f"ratio_{k.replace('/', '_over_')}" for k in RATIO_KEYS]
    return head


def csv_row(row: Row) -> list[object]:
    inst = row.inst
    cells: list[object] = [inst.family, inst.n, inst.d, row.budget]
    for route in ROUTES:
        run = row.runs[route]
        cells += [run.status, _num(run.seconds, ".4g"), _num(run.peak_mb, ".1f"),
                  _num(run.value, ".10f")]
        cells += [_num(run.extra.get(k), ".10f" if k == "upper" else ".4g")
                  for k in EXTRA.get(route, ())]
        if route in ("default", "storm_prism"):
            cells.append(_num(run.proc_s, ".3f"))
        cells.append(run.note)
    cells += [_num(row.value_spread(), ".3g"), _num(row.relative_spread(), ".3g")]
    cells += [_num(v, ".3g") for v in ratios(row).values()]
    return cells


def _num(x: Any, spec: str) -> object:
    """A CSV cell: floats formatted by ``spec``, ints and bools as they are, None empty."""
    if x is None:
        return ""
    if isinstance(x, float):
        return format(x, spec) if math.isfinite(x) else "nan"
    return x


def machine_text(load_note: str, details: Sequence[str] | None = None) -> str:
    """The machine, the versions, the load and the code; ``details`` (how the figures
    were taken) replaces this script's own lines."""
    import importlib.metadata as md

    def version(pkg: str) -> str:
        try:
            return md.version(pkg)
        except md.PackageNotFoundError:
            return "not installed"

    cpu = "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    ram = "unknown"
    try:
        kb = int(Path("/proc/meminfo").read_text().split("MemTotal:")[1].split()[0])
        ram = f"{kb / 2**20:.1f} GiB"
    except (OSError, IndexError, ValueError):
        pass
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    lines = [
        f"date: {dt.datetime.now(dt.UTC).isoformat(timespec='seconds')}",
        f"cpu: {cpu}",
        f"cores: {os.cpu_count()}",
        f"ram: {ram}",
        f"os: {platform.platform()}",
        f"python: {platform.python_version()}",
        *[f"{p}: {version(p)}" for p in ("numpy", "scipy", "cvxpy", "clarabel", "highspy",
                                         "numba", "stormpy", "mitld_lp")],
        f"load average at the end (1, 5, 15 min): {load}",
        f"note: {load_note}",
        f"code: {_commit()}",
    ]
    if details is not None:
        return "\n".join([*lines, *details]) + "\n"
    lines += [
        "storm: sound value iteration, precision 1e-9 absolute, on our DRN and on "
        "experiments/prism/bus.prism",
        "times: seconds inside the child process after its imports and model loading; "
        "*_proc_s: the whole child process (interpreter start, imports, work); "
        "*_mb: the child's peak resident memory (ru_maxrss, includes the interpreter)",
    ]
    return "\n".join(lines) + "\n"


def _commit() -> str:
    """The checkout's commit (and ``+changes`` if its tracked files other than the
    results being written differ from it)."""
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, text=True,
                              capture_output=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", "--",
                                ".", ":(exclude)experiments/results"],
                               cwd=ROOT, text=True, capture_output=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return head + (" +changes" if dirty else "")


def plot(rows: Sequence[Row], path: Path) -> Path:
    """Seconds against product states, log-log, one panel per family; a line per route
    and deadline (marker: deadline)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import NullFormatter

    # (label, route, part of its time or None for all of it, line style)
    series = [("build", "build", None, "k:"), ("default", "default", None, "C0-"),
              ("topo_lp", "topo_lp", None, "C1-"), ("mono_lp", "mono_lp", None, "C2-"),
              ("highs_lp", "highs_lp", None, "C3-"), ("ii", "ii", None, "C4-"),
              ("Storm check (DRN)", "storm_drn", "check_s", "C5--"),
              ("Storm parse+check (DRN)", "storm_drn", None, "C7--"),
              ("Storm whole run (PRISM)", "storm_prism", None, "C6--")]
    fig, axes = plt.subplots(1, 2, figsize=(12, 5), sharey=True)
    for ax, family in zip(axes, ("bus", "events"), strict=True):
        mine = [r for r in rows if r.inst.family == family and "states" in r.runs["build"].extra]
        ds = sorted({r.inst.d for r in mine})
        for label, route, part, style in series:
            for i, d in enumerate(ds):
                pts = sorted((r.runs["build"].extra["states"], r.seconds(route, part))
                             for r in mine if r.inst.d == d and r.seconds(route, part))
                if pts:
                    ax.loglog([p[0] for p in pts], [p[1] for p in pts], style,
                              marker="os^vD<>"[i % 7], label=label if i == 0 else None,
                              alpha=0.85)
        ax.set_title(f"{family} family (markers: deadline {', '.join(map(str, ds))})")
        ax.set_xlabel("product states (ours)")
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.grid(True, which="both", alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8)
    axes[0].set_ylabel("seconds (the route's own work; skipped routes omitted)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def print_row(row: Row) -> None:
    inst, runs = row.inst, row.runs
    states = runs["build"].extra.get("states")
    parts = [f"{inst.name}: {states if states is not None else '?'} states"]
    for route in ROUTES:
        run = runs[route]
        if run.seconds is not None and run.status not in ("skipped", "failed"):
            parts.append(f"{route} {run.seconds:.3g}s")
        else:
            parts.append(f"{route} {run.status}")
    print(", ".join(parts))
    rs = ratios(row)
    print("    ratios: " + ", ".join(f"{k} = {_fmt(v, 3) or '-'}" for k, v in rs.items())
          + f"; max value difference {_fmt(row.value_spread(), 2)}", flush=True)


def summary_rows(rows: Sequence[Row]) -> tuple[list[str], list[list[str]]]:
    header = ["instance", "states", "build", "default", "topo_lp", "mono_lp", "highs_lp",
              "ii", "storm_drn chk", "storm_prism", "value", "max diff", "def/prism",
              "def/chk", "ii/chk"]
    out = []
    def cell(row: Row, route: str, part: str | None = None) -> str:
        s = row.seconds(route, part)
        return _fmt(s, 3) if s is not None else row.runs[route].status

    for row in rows:
        value = next((r.value for r in row.runs.values() if r.value is not None), None)
        out.append([row.inst.name, str(row.runs["build"].extra.get("states", "?")),
                    *[cell(row, r) for r in ("build", "default", "topo_lp", "mono_lp",
                                             "highs_lp", "ii")],
                    cell(row, "storm_drn", "check_s"), cell(row, "storm_prism"),
                    _fmt(value, 7), _fmt(row.value_spread(), 2),
                    *[_fmt(v, 3) or "-" for v in ratios(row).values()]])
    return header, out


# ---------------------------------------------------------------------------- main


def instances(args: argparse.Namespace) -> list[Instance]:
    if args.quick:
        return [Instance("bus", 4, 3), Instance("events", 4, 2)]
    out = [Instance("bus", n, d) for d in args.deadlines for n in args.bus_sizes]
    out += [Instance("events", n, args.event_deadline) for n in args.event_sizes]
    return out


def main(argv: list[str] | None = None) -> list[Row]:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--quick", action="store_true",
                    help="two tiny instances (seconds), into experiments/out/quick")
    ap.add_argument("--out", type=Path, default=None,
                    help=f"directory for the CSV, sidecar and figure (default {RESULTS}, "
                         f"with --quick {QUICK_OUT})")
    ap.add_argument("--bus-sizes", type=int, nargs="+", default=[8, 16, 32])
    ap.add_argument("--deadlines", type=int, nargs="+", default=[3, 10])
    ap.add_argument("--event-sizes", type=int, nargs="+", default=[8, 16, 24, 32])
    ap.add_argument("--event-deadline", type=int, default=4)
    ap.add_argument("--budget", type=float, default=120.0, help="seconds per route")
    ap.add_argument("--mem-budget-mb", type=float, default=None,
                    help="address-space cap per child (off by default)")
    ap.add_argument("--load-note", default="shared 2-core machine: 4 other engineers ran "
                    "tests at the same time, so times are noisy (ratios are within one run)")
    ap.add_argument("--worker", choices=ROUTES, help=argparse.SUPPRESS)
    ap.add_argument("--instance", help=argparse.SUPPRESS)
    ap.add_argument("--work", type=Path, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)

    if args.worker:
        worker_main(args.worker, Instance(**json.loads(args.instance)), args.work,
                    args.budget)
        return []
    from _common import shown, text_table, write_text
    for name in ("budget",):
        if getattr(args, name) <= 0:
            ap.error(f"--{name}: must be positive, got {getattr(args, name)}")
    for opt, vals in (("--bus-sizes", args.bus_sizes), ("--deadlines", args.deadlines),
                      ("--event-sizes", args.event_sizes),
                      ("--event-deadline", [args.event_deadline])):
        if any(v < 1 for v in vals):
            ap.error(f"{opt}: must be positive integers, got {vals}")
    out = args.out or (QUICK_OUT if args.quick else RESULTS)
    if args.quick and out.resolve() == RESULTS.resolve():
        ap.error(f"--quick never writes into {shown(RESULTS)} (the committed results)")
    out.mkdir(parents=True, exist_ok=True)

    rows: list[Row] = []
    too_big: dict[tuple[str, str], int] = {}
    with tempfile.TemporaryDirectory(prefix="bench_scaling_") as tmp:
        for inst in instances(args):
            row = run_instance(inst, args.budget, args.mem_budget_mb, too_big, Path(tmp))
            rows.append(row)
            print_row(row)
            with (out / "scaling.csv").open("w", newline="", encoding="utf-8") as f:
                w = csv.writer(f)  # rewritten per row: a long run keeps what it has
                w.writerow(csv_header())
                w.writerows(csv_row(r) for r in rows)
    write_text(out / "scaling_machine.txt", machine_text(args.load_note))
    plot(rows, out / "scaling.png")
    header, table = summary_rows(rows)
    print()
    print(text_table(header, table))
    worst = max((r.value_spread() for r in rows if math.isfinite(r.value_spread())),
                default=float("nan"))
    print(f"\nlargest value difference between routes: {_fmt(worst, 2)} "
          f"({'agree' if worst <= AGREE_TOL else 'DISAGREE'} to {AGREE_TOL:g})")
    print(f"wrote {shown(out / 'scaling.csv')}, {shown(out / 'scaling_machine.txt')}, "
          f"{shown(out / 'scaling.png')}")
    return rows


if __name__ == "__main__":
    main()
