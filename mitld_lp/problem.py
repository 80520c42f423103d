"""The one problem a user poses, validated once: a task, its constraints, the world and
its laws, and the settings it is solved with.

    Problem(model, constraints, then, objective) + Settings --pose--> Posed (a route)

Every entry point (``synthesize``, the command line's verbs, sweeps, ``pareto``) poses
its problem here and nowhere else, so each combination is either sent to the one route
that solves exactly that problem or refused with one line naming the combination; an
option a route cannot honour is refused, never dropped.

The routes (which solver chain accepts the problem):

* ``plain``: point laws, no constraints; any supported task class (co-safe, safety,
  obligation) -- :mod:`mitld_lp.synthesis`;
* ``robust``: some law known only within a band (an interval parameter or a fit from
  data), no constraints; co-safe tasks -- :mod:`mitld_lp.routes.robust`;
* ``constrained``: constraints or a ``then`` objective with point laws; co-safe task and
  constraint formulas -- :mod:`mitld_lp.routes.constrained`;
* ``sensed``: some event is reported by a sensor that misses it (``detect < 1``);
  co-safe tasks, point laws, no constraints -- :mod:`mitld_lp.sensing.solve`.

``objective = "min"`` (PRISM's ``Pmin``) is solved as the maximum of the complement:
``Pmin(phi) = 1 - Pmax(not phi)``, with the complement taken on the automaton
(:meth:`mitld_lp.automata.dta.DTA.complement`), so the classes swap (co-safe <-> safety,
obligation stays) and the route is chosen for the complement.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from mitld_lp import defaults
from mitld_lp.logic.fragment import CO_SAFE, OBLIGATION, SAFETY

__all__ = ["Settings", "Problem", "Posed", "ProblemError", "pose", "check_constrained",
           "OBJECTIVES",
           "complement_class", "PLAIN", "ROBUST", "CONSTRAINED", "SENSED"]

PLAIN, ROBUST, CONSTRAINED = "plain", "robust", "constrained"
SENSED = "sensed"
OBJECTIVES = ("max", "min")
METHODS = ("lp", "vi")
BACKENDS = ("auto", "cvxpy", "direct")


class ProblemError(ValueError):
    """A problem no route solves as posed, or an option its route cannot honour: the
    message names the combination (the command line exits 2)."""


def complement_class(fragment: str) -> str:
    """The class of ``not phi`` for a formula ``phi`` of class ``fragment``."""
    return {CO_SAFE: SAFETY, SAFETY: CO_SAFE}.get(fragment, fragment)


@dataclass(frozen=True, slots=True)
class Settings:
    """How a problem is solved: one record for every route and entry point.

    ``decompose``: ``None`` lets the route choose (block LPs in topological order for
    the plain route); ``True`` asks for the block decomposition, ``False`` for one LP.
    ``truncation``: fixed truncation points ``((event, steps), ...)`` instead of the
    epsilon budget.  ``precision``: the relative width a certified bracket may have
    (``upper - lower <= precision * lower``; with truncation, the solver's part).  A
    budget left ``None`` (``max_states``, ``max_automaton_states``, ``max_memory``,
    ``time_limit``) is the model file's ``[budgets]`` one, else the default
    (:meth:`resolved`).  The others are :func:`mitld_lp.synthesis.synthesize`'s.
    """

    method: str = "lp"
    solver: str = defaults.SOLVER
    backend: str = "auto"
    clock_reduction: bool = True
    decompose: bool | None = None
    time_limit: float | None = None
    max_states: int | None = None
    max_automaton_states: int | None = None
    max_memory: int | None = None
    epsilon: float | None = None
    truncation: tuple[tuple[str, int], ...] | None = None
    tol: float = defaults.TOL
    certify_tol: float = defaults.CERTIFY_TOL
    progress: bool = False
    precision: float = defaults.PRECISION

    def identity(self) -> dict[str, Any]:
        """The settings that change an answer (part of a sweep's identity; the precision
        only when it is not the default, so that results files written before it keep
        their identity)."""
        return {"method": self.method, "solver": self.solver, "backend": self.backend,
                "clock_reduction": self.clock_reduction,
                "decompose": self.decompose is not False,
                **({} if self.precision == defaults.PRECISION else
                   {"precision": self.precision})}

    @property
    def truncation_map(self) -> dict[str, int] | None:
        return None if self.truncation is None else dict(self.truncation)

    def checked(self) -> Settings:
        """These settings, each value checked (a :class:`ProblemError` names the first
        that is wrong); the solver's name upper-cased."""
        if self.method not in METHODS:
            raise ProblemError(f"method: must be 'lp' or 'vi', got {self.method!r}")
        if self.backend not in BACKENDS:
            raise ProblemError(f"backend: must be one of {', '.join(BACKENDS)}, "
                               f"got {self.backend!r}")
        if not isinstance(self.solver, str) or not self.solver:
            raise ProblemError(f"solver: must be a solver's name, got {self.solver!r}")
        solver = self.solver.upper()
        if self.backend == "direct" and solver != "CLARABEL":
            raise ProblemError(f"backend 'direct' runs only Clarabel, not {self.solver}; "
                               "use backend 'cvxpy' (or 'auto') for other solvers")
        if solver != defaults.SOLVER.upper():  # another LP solver: one cvxpy has
            import cvxpy

            installed = cvxpy.installed_solvers()
            if solver not in installed:
                raise ProblemError(f"solver: unknown or not installed LP solver "
                                   f"{self.solver!r} (installed: {', '.join(installed)})")
        if self.time_limit is not None and not (
                isinstance(self.time_limit, int | float) and not isinstance(self.time_limit, bool)
                and 0 <= self.time_limit < float("inf")):
            raise ProblemError(f"time_limit: must be a finite number of seconds >= 0 or "
                               f"None, got {self.time_limit!r}")
        for name in ("tol", "certify_tol", "precision"):
            v = getattr(self, name)
            if isinstance(v, bool) or not (isinstance(v, int | float) and 0 < v < 1):
                raise ProblemError(f"{name}: must be a number in (0, 1), got {v!r}")
        for name in ("max_states", "max_automaton_states"):
            v = getattr(self, name)
            if v is not None and not (isinstance(v, int) and not isinstance(v, bool)
                                      and v >= 1):
                raise ProblemError(f"{name}: must be a whole number >= 1, got {v!r}")
        if self.max_memory is not None and not (
                isinstance(self.max_memory, int) and self.max_memory >= 1):
            raise ProblemError(f"max_memory: must be a number of bytes >= 1, "
                               f"got {self.max_memory!r}")
        try:
            eps = None if self.epsilon is None else defaults.check_epsilon(self.epsilon)
        except ValueError as exc:
            raise ProblemError(f"epsilon: {exc}") from None
        return _replace(self, solver=solver, epsilon=eps)

    def resolved(self, budgets: Mapping[str, float]) -> Settings:
        """Every budget set: this record's, else ``budgets`` (a model file's
        ``[budgets]``), else the default (:mod:`mitld_lp.defaults`; no memory or time
        limit)."""
        def pick(name: str, default: Any) -> Any:
            mine = getattr(self, name)
            return mine if mine is not None else budgets.get(name, default)

        return _replace(self, max_states=int(pick("max_states", defaults.MAX_STATES)),
                        max_automaton_states=int(pick("max_automaton_states",
                                                      defaults.MAX_AUTOMATON_STATES)),
                        max_memory=pick("max_memory", None),
                        time_limit=pick("time_limit", None))


def _replace(s: Settings, **changes: Any) -> Settings:
    from dataclasses import replace

    return replace(s, **changes)


def settings_from(**kwargs: Any) -> Settings:
    """:class:`Settings` from :func:`mitld_lp.synthesis.synthesize`'s keywords (a
    ``truncation`` mapping becomes sorted pairs), checked."""
    trunc = kwargs.pop("truncation", None)
    if trunc is not None:
        if not isinstance(trunc, Mapping):
            raise ProblemError(f"truncation: must map event names to steps, got {trunc!r}")
        kwargs["truncation"] = tuple(sorted((str(k), v) for k, v in trunc.items()))
    return Settings(**kwargs).checked()


@dataclass(frozen=True, slots=True, eq=False)
class Problem:
    """What is asked: maximise (or minimise, ``objective="min"``) the probability that
    ``model``'s world satisfies its task, subject to ``constraints`` (the model's own
    first, then these), then optionally minimise ``then`` (``"min-steps"`` /
    ``"min-cost"``) among the optimal policies."""

    model: Any  # mitld_lp.model.Model (not imported: the model imports the worlds)
    constraints: tuple[Any, ...] = ()  # mitld_lp.routes.constraints.Constraint records
    then: str | None = None
    objective: str = "max"


@dataclass(frozen=True, slots=True, eq=False)
class Posed:
    """A problem accepted by one route, with its checked settings.

    ``fragment``: the class of the task as it is solved (the complement's for
    ``objective="min"``); ``robust``: some law is a band."""

    problem: Problem
    settings: Settings
    route: str
    fragment: str
    robust: bool

    @property
    def model(self) -> Any:
        return self.problem.model

    @property
    def minimise(self) -> bool:
        return self.problem.objective == "min"


def pose(model: Any, constraints: Iterable[Any] = (), *, then: str | None = None,
         settings: Settings | None = None, objective: str | None = None,
         constrained: bool = False) -> Posed:
    """Validate the problem once and choose its route (module docs).  ``constraints``:
    texts or :class:`~mitld_lp.routes.constraints.Constraint` records, after the model's own;
    ``objective``: the model's unless given; ``constrained``: the constrained LP's
    route even with no constraint (the trade-off curve's end points).  Raises
    :class:`ProblemError` naming the combination no route solves, or the option the
    route cannot honour."""
    from mitld_lp.logic.fragment import check
    from mitld_lp.model import Model
    from mitld_lp.routes.constraints import THEN, ConstraintError, parse_constraints

    if not isinstance(model, Model):
        raise TypeError(
            f"expected a Model (load_model(path) or Model.from_game(game, spec)), "
            f"got {type(model).__name__}")
    s = (settings or Settings()).checked().resolved(model.budgets)
    goal = model.objective if objective is None else objective
    if goal not in OBJECTIVES:
        raise ProblemError(f"objective: must be 'max' or 'min', got {goal!r}")
    if then is not None and then not in THEN:
        raise ProblemError(f"then: must be one of {', '.join(THEN)}, got {then!r}")
    try:
        cons = parse_constraints(model.constraints) + parse_constraints(list(constraints))
    except ConstraintError as exc:
        raise ProblemError(str(exc)) from None
    fragment = check(model.spec).fragment
    if goal == "min":
        fragment = complement_class(fragment)
    if s.truncation is not None:
        unknown = sorted(set(dict(s.truncation)) - set(model.distributions))
        if unknown:
            raise ProblemError(
                f"truncation: {unknown[0]!r} is not an event of the model (events: "
                f"{', '.join(sorted(model.distributions)) or 'none'})")
    robust = any(d.is_ambiguous for d in model.distributions.values())
    constrained = constrained or bool(cons or then)
    problem = Problem(model, cons, then, goal)
    what = _task_words(fragment, goal)
    # sensors that miss events: the observation-based route, or a refusal naming why
    from mitld_lp.sensing.route import sensed_refusal
    from mitld_lp.sensing.sensors import partial

    if partial(model.sensors):
        why = sensed_refusal(model, fragment, goal, cons, then, robust)
        if why is not None:
            raise ProblemError(why)
        return Posed(problem, s, SENSED, fragment, robust)
    if constrained:
        posed = Posed(problem, s, CONSTRAINED, fragment, robust)
        check_constrained(posed)
        return posed
    if robust:
        _robust_route(s)
        return Posed(problem, s, ROBUST, fragment, robust)
    if fragment not in (CO_SAFE, SAFETY, OBLIGATION):  # check() refuses the others
        raise ProblemError(f"{what}: not a supported class")
    return Posed(problem, s, PLAIN, fragment, robust)


def _task_words(fragment: str, goal: str) -> str:
    article = "an" if fragment[0] in "aeiou" else "a"
    return (f"{article} {fragment} task" if goal == "max" else
            f"objective min (solved as the maximum of the complement, {article} {fragment} "
            "task)")


def _band(model: Any) -> str:
    return ", ".join(f"{e} ~ {d}" for e, d in sorted(model.distributions.items())
                     if d.is_ambiguous)


def check_constrained(posed: Posed) -> None:
    """Raise :class:`ProblemError` unless the constrained LP (one Clarabel LP over the
    joint product's occupancy measures) solves ``posed`` as posed."""
    from mitld_lp.logic.fragment import check

    s, cons, fragment = posed.settings, posed.problem.constraints, posed.fragment
    what = _task_words(fragment, posed.problem.objective)
    if posed.robust and (posed.problem.then is not None
                         or any(c.kind != "prob" for c in cons)):
        what_else = (f"then = {posed.problem.then}" if posed.problem.then is not None else
                     next(str(c) for c in cons if c.kind != "prob"))
        raise ProblemError(
            f"{what_else} with a law known only within a band ({_band(posed.model)}): the "
            "worst case of expected steps or costs is not solved; give the event a point "
            "law, or bound probabilities only")
    if fragment not in (CO_SAFE, SAFETY, OBLIGATION):
        raise ProblemError(f"{what} with constraints: not a supported class")
    for c in cons:
        if c.formula is not None and check(c.formula).fragment != CO_SAFE:
            raise ProblemError(f"constraint {c}: class {check(c.formula).fragment}; "
                               "constraint formulas must be co-safe")
    if s.method != "lp":
        raise ProblemError(f"method {s.method!r} with constraints: the constrained "
                           "optimum is one occupancy LP (method 'lp')")
    if s.solver != "CLARABEL" or s.backend == "cvxpy":
        raise ProblemError(f"solver {s.solver} / backend {s.backend} with constraints: the "
                           "constrained LP is solved by Clarabel directly")
    if s.decompose is True:
        raise ProblemError("decompose with constraints: the constrained LP is one LP over "
                           "the whole product (its rows couple every block)")


def _robust_route(s: Settings) -> None:
    """Robust interval iteration, with the policy's robust LP (Clarabel) for method lp."""
    if s.solver != "CLARABEL" or s.backend == "cvxpy":
        raise ProblemError(f"solver {s.solver} / backend {s.backend} with a law known only "
                           "within a band: the robust policy LP is solved by Clarabel "
                           "directly")
    if s.decompose is True:
        raise ProblemError("decompose with a law known only within a band: robust "
                           "synthesis has no block LPs")
