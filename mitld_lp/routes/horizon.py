"""The step-bounded route: ``F[0,k] phi`` (``psi U[0,k] phi``) over an explored world's
labels, solved by backward induction over the world (:mod:`mitld_lp.solvers.horizon`)
instead of the product with a step-counting automaton.

It claims a problem only when all of these hold: the task is exactly ``F[0,k] phi`` or
``psi U[0,k] phi`` with ``phi`` and ``psi`` Boolean combinations of the world's
propositions (no events, no distribution eventualities); no constraints, band, sensor
that misses or exact answer asked; the world is a table already explored
(:func:`mitld_lp.worlds.table.table_of`: a PRISM program built whole, not a world
explored on the fly or within a state limit); and the product's bound from its factors,
world states times ``k + 1``, and a sharper bound from the world's distances
(:func:`product_bound`) are at least :data:`CLAIM_FROM`.  Every other problem stays
with the routes after it (the plain route's product is exact for it too, and faster on
a small bound).

The answer: the bracket at the initial state (``lower``: what the returned policy
guarantees, for a maximum; ``upper``: what no policy beats), certified by construction
(the induction's directed rounding).  The policy is step-dependent, kept within
:data:`mitld_lp.solvers.horizon.POLICY_MAX_BYTES`; past it :meth:`Result.policy_table`
and the controller refuse with the size and the budget (:class:`HorizonPart`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mitld_lp.checks import Check
from mitld_lp.logic.syntax import And, Const, Formula, Not, Or, Prop, Until
from mitld_lp.problem import Posed, ProblemError
from mitld_lp.result import Part, Result, precision_check
from mitld_lp.routes.route import Route
from mitld_lp.util.stops import TimeUp

__all__ = ["CLAIM_FROM", "HorizonRoute", "HorizonPart", "HorizonBuilt", "step_bounded",
           "HorizonController", "lp_settings"]

#: The product's bound (world states x (k + 1)) from which this route takes a
#: step-bounded reachability from the plain route.  Measured (experiments/
#: horizon_threshold.py, resource-gathering at growing B, synthesize's CPU): bound 15,813
#: plain 0.010 s / this route 0.001 s; 115,107: 0.031 / 0.001; 759,621: 0.371 / 0.002;
#: 4,818,171: 2.6 / 0.007 (docs/results.md, horizon-78).  This route is faster at every
#: size measured; below 100,000 the plain route's whole solve is a few hundredths of a
#: second, and it keeps there what only a product gives (an exact answer, the product's
#: exports, simulate and a saved controller).
CLAIM_FROM = 100_000


def _boolean(f: Formula, names: frozenset[str]) -> bool:
    """Whether ``f`` is a Boolean combination of the world's propositions ``names``."""
    if isinstance(f, Const):
        return True
    if isinstance(f, Prop):
        return f.name in names
    if isinstance(f, Not):
        return _boolean(f.arg, names)
    if isinstance(f, And | Or):
        return all(_boolean(a, names) for a in f.args)
    return False


def _holds(f: Formula, labels: frozenset[str]) -> bool:
    if isinstance(f, Const):
        return f.value
    if isinstance(f, Prop):
        return f.name in labels
    if isinstance(f, Not):
        return not _holds(f.arg, labels)
    if isinstance(f, And):
        return all(_holds(a, labels) for a in f.args)
    return any(_holds(a, labels) for a in f.args)  # Or


def step_bounded(spec: Formula, names: frozenset[str]) -> tuple[Formula, Formula, int] | None:
    """``(psi, phi, k)`` when ``spec`` is ``psi U[0,k] phi`` (``F[0,k] phi``: ``psi``
    true) over the propositions ``names``, else None."""
    if not isinstance(spec, Until) or spec.interval is None or spec.interval.lo != 0:
        return None
    if not (_boolean(spec.left, names) and _boolean(spec.right, names)):
        return None
    return spec.left, spec.right, int(spec.interval.hi)


def _sets(table: Any, psi: Formula, phi: Formula) -> tuple[np.ndarray, np.ndarray]:
    """Per world state: where ``phi`` holds (the goal), where ``psi`` does."""
    labels = table.label_sets
    goal = np.array([_holds(phi, ls) for ls in labels], dtype=bool)[table.label_of]
    allowed = np.array([_holds(psi, ls) for ls in labels], dtype=bool)[table.label_of]
    return goal, allowed


def product_bound(table: Any, goal: np.ndarray, moving: np.ndarray, steps: int,
                  enough: int) -> int:
    """A bound on the product's states for ``steps`` steps, from the world's distances:
    a product state (world state ``s``, step ``t``) is reachable only if ``s`` is at most
    ``t <= steps`` moves from the initial state through ``moving`` states, so the product
    has at most the sum over those ``s`` of ``steps + 1 - distance(s)`` states.  The
    breadth-first search stops once the sum reaches ``enough`` (then returned as it is):
    a world explored whole whose task reads only a few states near the start (a grid with
    ``F[0,10] goal``) keeps its small product, as when it is explored to the horizon."""
    choices, branches = np.asarray(table.choices), np.asarray(table.branches)
    targets = np.asarray(table.targets)
    seen = np.zeros(table.n_states, dtype=bool)
    front = np.array([table.initial])
    seen[front] = True
    total = 0
    for d in range(steps + 1):
        total += front.size * (steps + 1 - d)
        if total >= enough or d == steps:
            return total
        front = front[moving[front]]
        cs = _ranges(choices[front], choices[front + 1])
        nxt = np.unique(targets[_ranges(branches[cs], branches[cs + 1])])
        front = nxt[~seen[nxt]]
        seen[front] = True
        if front.size == 0:
            return total
    return total


def _ranges(starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """The indices ``starts[i]:ends[i]`` for every ``i``, concatenated."""
    sizes = ends - starts
    total = int(sizes.sum())
    if total == 0:
        return np.zeros(0, dtype=np.int64)
    offsets = np.repeat(starts - np.concatenate(([0], np.cumsum(sizes)[:-1])), sizes)
    return np.arange(total) + offsets


@dataclass(frozen=True, slots=True, eq=False)
class HorizonBuilt:
    """What the route solves on: the world's table, the states where ``phi`` holds
    (``goal``) and where ``psi`` does (``allowed``), the steps and the sense."""

    table: Any  # mitld_lp.worlds.table.WorldTable
    goal: np.ndarray
    allowed: np.ndarray
    steps: int
    sense: str
    timings: dict[str, float]
    dta: Any = None  # the unbounded task's automaton (the step counter is the policy's rows)
    sta: Any = None

    @property
    def mdp(self) -> Any:
        """Refused: this route builds no product (what ``info`` and ``export`` read)."""
        raise ProblemError(
            f"horizon route: no product is built for a step-bounded reachability over "
            f"{self.table.n_states:,} world states and {self.steps:,} steps (a bound of "
            f"{self.table.n_states * (self.steps + 1):,} product states, at least "
            f"mitld_lp.routes.horizon.CLAIM_FROM = {CLAIM_FROM:,}): it is solved by "
            "backward induction over the world; this command reads the product")


def lp_settings(s: Any) -> list[str]:
    """The settings given that only the product route's solve reads (its method, its LP
    solver and backend, its decomposition): with any, this route leaves the problem to
    the product route rather than answer it without them."""
    from mitld_lp import defaults

    return [name for name, given in (("method", s.method != "lp"),
                                     ("solver", s.solver != defaults.SOLVER),
                                     ("backend", s.backend != "auto"),
                                     ("decompose", s.decompose is not None)) if given]


@dataclass(frozen=True, eq=False)
class WorldSize:
    """The sizes a result reports of the model solved: the world itself (``product``
    False: the readers that print a product's size say that none was built)."""

    n_states: int
    n_choices: int
    n_transitions: int
    initial: int
    product: bool = False


class HorizonController:
    """The step-dependent policy as a controller: :meth:`act` on the world state seen,
    the steps counted from :meth:`reset`; every method refuses, naming the reason and
    the size, where the policy was not kept."""

    def __init__(self, game: Any, table: Any, built: HorizonBuilt, solution: Any) -> None:
        self.game, self.table, self.built, self.solution = game, table, built, solution
        self.randomised, self._steps, self._index = False, 0, None

    def _kept(self) -> None:
        if self.solution is None:
            raise ProblemError("horizon route: no policy: the time limit passed")
        if self.solution.picks is None:
            raise ProblemError(f"horizon route: no policy kept: {self.solution.why_no_policy}")

    @property
    def steps(self) -> int:
        return self._steps

    def reset(self, seed: int | None = None) -> None:
        self._kept()
        self._steps = 0

    def act(self, observation: Any) -> str | None:
        """The action at the world state ``observation`` (an Observation or the state),
        None once the task is decided (``phi`` reached, ``psi`` broken, no steps left)."""
        self._kept()
        state = getattr(observation, "state", observation)
        if self._index is None:
            self._index = {s: i for i, s in enumerate(self.table.states)}
        i = self._index[state]
        left = self.built.steps - self._steps
        self._steps += 1
        if self.built.goal[i] or not self.built.allowed[i] or left <= 0:
            return None
        local = self.solution.choice(i, left)
        return self.game.actions(state)[local]

    def __getattr__(self, name: str) -> Any:  # plan, tables, save...: not for this route
        if name.startswith("_"):
            raise AttributeError(name)
        self._kept()
        raise ProblemError(f"horizon route: the step-dependent controller answers act() and "
                           f"reset() only, not {name!r} (what simulate, run and a saved "
                           "controller read); its decisions are Result.policy_table()")


@dataclass(frozen=True, slots=True, eq=False)
class HorizonPart(Part):
    """The step-bounded route's part: the induction's record and what it solved."""

    solution: Any = field()
    built: HorizonBuilt = field()
    max_rows: int = field()  # the problem's max_states: a product's table has no more rows

    def policy_table(self, result: Result) -> list[dict[str, Any]]:
        """One row per step left and state with a decision, in the product route's
        columns (:data:`mitld_lp.files.write.POLICY_COLUMNS`): the world state, the
        steps left as the automaton state (``"<j> steps left"``), the action; ``value``
        NaN (the values of the steps before the last are not kept).  Refused, with the
        size, where the policy was not kept."""
        from mitld_lp.report import state_record

        sol, built = self.solution, self.built
        if sol is None:
            raise ProblemError("horizon route: no policy table: the time limit passed")
        if sol.picks is None:
            raise ProblemError(f"horizon route: no policy table: {sol.why_no_policy}")
        limit = self.max_rows
        if int(sol.offsets[-1]) > limit:
            raise ProblemError(
                f"horizon route: no policy table: {int(sol.offsets[-1]):,} rows (one per "
                f"step and state with a choice) are more than the {limit:,} of max_states, "
                "the most rows a product's table has; the controller's act() reads the "
                "policy kept")
        game, table = result.model.game, built.table
        rows = []
        for step in range(built.steps):
            states, picks = sol.decisions(step)
            for i, c in zip(states.tolist(), picks.tolist(), strict=True):
                state = table.states[i]
                rows.append({"game_state": state_record(game, state),
                             "automaton_state": f"{step + 1} steps left", "pending": [],
                             "clock": 0, "action": game.actions(state)[c],
                             "value": float("nan"), "accepting_component": False})
        return rows

    def summary(self, result: Result) -> dict[str, Any]:
        mdp, sol = result.mdp, self.solution
        out = {"states": mdp.n_states, "choices": mdp.n_choices,
               "transitions": mdp.n_transitions, "lp": None}
        out["iteration"] = {"status": str(result.status), "steps": self.built.steps} | (
            {} if sol is None else {"decisions": int(sol.offsets[-1]),
                                    "policy_kept": sol.picks is not None,
                                    "no_policy": sol.why_no_policy or None})
        return out


def _policy_budget(max_memory: int | None) -> int:
    """The policy's bytes: :data:`~mitld_lp.solvers.horizon.POLICY_MAX_BYTES`, and at
    most half of the problem's memory budget where one is set (the rest for the world's
    arrays and the induction's vectors)."""
    from mitld_lp.solvers import horizon

    cap = horizon.POLICY_MAX_BYTES
    return cap if max_memory is None else min(cap, int(max_memory) // 2)


class HorizonRoute(Route):
    """Step-bounded reachability on an explored world, by backward induction (module
    docs).  ``first``: listed before the plain route (its precedence entry)."""

    name = "horizon"

    def __init__(self, first: bool = True) -> None:
        self.first = first

    def claims(self, posed: Posed) -> bool:
        from mitld_lp.worlds.table import table_of

        s, game = posed.settings, posed.model.game
        if posed.robust or posed.problem.constrained or posed.sensed or s.exact:
            return False
        if lp_settings(s):  # asked of the product's solve: the product route answers them
            return False
        shape = step_bounded(posed.model.spec, frozenset(game.proposition_names))
        if shape is None:
            return False
        table = table_of(game)
        if table is None or table.n_states * (shape[2] + 1) < CLAIM_FROM:
            return False
        goal, allowed = _sets(table, shape[0], shape[1])
        return product_bound(table, goal, allowed & ~goal, shape[2],
                             CLAIM_FROM) >= CLAIM_FROM

    def refusal(self, posed: Posed) -> list[str]:
        """The induction's work past :data:`mitld_lp.solvers.horizon.MAX_WORK` (from
        the world's sizes and the steps, before any work)."""
        from mitld_lp.solvers import horizon
        from mitld_lp.worlds.table import table_of

        game = posed.model.game
        shape = step_bounded(posed.model.spec, frozenset(game.proposition_names))
        table = table_of(game)
        if shape is None or table is None:
            return []
        work = horizon.horizon_work(table.choices, table.branches, shape[2])
        if work <= horizon.MAX_WORK:
            return []
        return [f"horizon route: {shape[2]:,} steps x ({int(table.branches[-1]):,} "
                f"transitions + {int(table.choices[-1]):,} choices) = {work:,} updates, "
                f"more than the {horizon.MAX_WORK:,} of "
                "mitld_lp.solvers.horizon.MAX_WORK"]

    def build(self, posed: Posed, progress: bool | None = None) -> HorizonBuilt:
        from mitld_lp.automata.sta import make_sta
        from mitld_lp.automata.translate import to_dta
        from mitld_lp.logic.syntax import until
        from mitld_lp.worlds.table import table_of

        t0 = time.perf_counter()
        game = posed.model.game
        psi, phi, k = step_bounded(posed.model.spec, frozenset(game.proposition_names))
        table = table_of(game)
        goal, allowed = _sets(table, psi, phi)
        dta = to_dta(until(psi, phi))
        sta = make_sta(dta, {}, posed.model.epsilon)
        return HorizonBuilt(table, goal, allowed, k, "min" if posed.minimise else "max",
                            {"automaton": time.perf_counter() - t0}, dta, sta)

    def solve(self, posed: Posed, built: HorizonBuilt, *, costs: Any = None,
              seed: int | None = 0) -> Result:
        from mitld_lp.solvers import horizon
        from mitld_lp.solvers.result import Status

        s, t = posed.settings, built.table
        t0, c0 = time.perf_counter(), time.process_time()
        try:
            sol = horizon.horizon_reach(
                np.asarray(t.choices), np.asarray(t.branches), np.asarray(t.targets),
                np.asarray(t.probabilities), built.goal, built.allowed, built.steps,
                built.sense, initial=t.initial, time_limit=s.time_limit,
                policy_max_bytes=_policy_budget(s.max_memory), progress=s.progress)
        except TimeUp:  # the trivial bracket, uncertified, no policy
            sol, status = None, Status.TIME_LIMIT
            lower, upper = 0.0, 1.0
            checks: tuple[Check, ...] = (Check("step-bounded induction", False,
                                               f"time limit of {s.time_limit} s passed"),)
        else:
            status = Status.OPTIMAL
            lower, upper = float(sol.lo[t.initial]), float(sol.hi[t.initial])
            checks = (Check("step-bounded induction", bool(lower <= upper),
                            f"{sol.steps} steps over the states read at each "
                            f"({len(sol.order):,} of {t.n_states:,} ever); every sum "
                            "rounded outward"),
                      precision_check(lower, upper, upper - lower, 0.0, s.precision))
        timings = {**built.timings, "solve": time.perf_counter() - t0}
        near = lower if built.sense == "max" else upper  # the policy's guarantee
        size = WorldSize(t.n_states, int(t.choices[-1]), int(t.branches[-1]), t.initial)
        eps = posed.model.epsilon if s.epsilon is None else s.epsilon
        return Result(
            route=self.name, model=posed.model, objective=posed.problem.objective,
            method=s.method, epsilon=eps, status=status, lower=lower, upper=upper,
            value=near, certified=all(c.passed for c in checks), checks=checks,
            controller=HorizonController(posed.model.game, t, built, sol), sta=built.sta,
            mdp=size, timings=timings, part=HorizonPart(sol, built, int(s.max_states)),
            solve_cpu=time.process_time() - c0, dta=built.dta, precision=s.precision,
            width={"total": upper - lower, "truncation": 0.0, "solver": upper - lower},
            sense=built.sense)
