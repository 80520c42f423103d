"""The one problem a user poses, validated once: a task, its constraints, the world and
its laws, and the settings it is solved with.

    Problem(model, constraints, then, objective) + Settings --pose--> Posed (a route)

Every entry point (``synthesize``, the command line's verbs, sweeps, ``pareto``) poses
its problem here and nowhere else, so each combination is either sent to the one route
that solves exactly that problem or refused with one line naming the combination; an
option a route cannot honour is refused, never dropped.

The routes (which solver chain accepts the problem: :data:`mitld_lp.routes.precedence.ROUTES`,
asked in that order, the first that claims the problem owns it):

* ``plain``: point laws, no constraints; any supported task class (co-safe, safety,
  obligation) -- :mod:`mitld_lp.synthesis`;
* ``robust``: some law known only within a band (an interval parameter or a fit from
  data), no constraints; co-safe tasks -- :mod:`mitld_lp.routes.robust`;
* ``constrained``: constraints or a ``then`` objective with point laws; co-safe task and
  constraint formulas -- :mod:`mitld_lp.routes.constrained`; with a band,
  :mod:`mitld_lp.routes.robust_constrained`;
* ``sensed``: some event is reported by a sensor that misses it (``detect < 1``);
  co-safe tasks, point laws, no constraints -- :mod:`mitld_lp.routes.sensed_solve`.

``objective = "min"`` (PRISM's ``Pmin``) is posed as the maximum of the complement:
``Pmin(phi) = 1 - Pmax(not phi)``, with the complement taken on the automaton
(:meth:`mitld_lp.automata.dta.DTA.complement`), so the classes swap (co-safe <-> safety,
obligation stays) and the route is chosen for the complement; the plain route then
solves a co-safe task's minimum as a minimum, on the task's own automaton
(:mod:`mitld_lp.routes.stages`), which keeps a rare probability's digits.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from mitld_lp import defaults
from mitld_lp.logic.fragment import CO_SAFE, SAFETY

__all__ = ["Settings", "Problem", "Posed", "ProblemError", "Route", "pose_on", "OBJECTIVES",
           "complement_class", "task_words", "band_text"]

OBJECTIVES = defaults.OBJECTIVES


class ProblemError(ValueError):
    """A problem no route solves as posed, or an option its route cannot honour: the
    message names the combination (the command line exits 2).  ``reasons``: every
    reason found, each naming its feature, all in the message (one run tells them all)."""

    def __init__(self, *reasons: str) -> None:
        self.reasons = reasons
        super().__init__(reasons[0] if len(reasons) == 1 else
                         f"not solved, for {len(reasons)} reasons: "
                         + "; ".join(f"({i}) {r}" for i, r in enumerate(reasons, 1)))


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
    (:meth:`resolved`).  ``bands``: how a law known only within a band is read,
    ``"worst"`` (nature against the robot, the default) or ``"best"`` (nature with it,
    PRISM's ``Pmaxmax``; :data:`mitld_lp.defaults.BANDS`).  The others are
    :func:`mitld_lp.synthesis.synthesize`'s.
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
    progress: bool | None = None  # bars: None on a terminal only (mitld_lp.util.progress)
    exact: bool = False  # the optimum as a fraction too (mitld_lp.exact)
    precision: float = defaults.PRECISION  # the relative precision asked (defaults)
    bands: str = "worst"  # a band read for the worst law or the best (defaults.BANDS)

    def identity(self) -> dict[str, Any]:
        """The settings that change an answer (part of a sweep's identity; the precision
        and the bands' reading only when they are not the default, so that results files
        written before them keep their identity)."""
        return {"method": self.method, "solver": self.solver, "backend": self.backend,
                "clock_reduction": self.clock_reduction,
                "decompose": self.decompose is not False,
                **({} if self.precision == defaults.PRECISION else
                   {"precision": self.precision}),
                **({} if self.bands == "worst" else {"bands": self.bands})}

    @property
    def truncation_map(self) -> dict[str, int] | None:
        return None if self.truncation is None else dict(self.truncation)

    def checked(self) -> Settings:
        """These settings, each value checked (a :class:`ProblemError` names the first
        that is wrong); the solver's name upper-cased."""
        if self.method not in defaults.METHODS:
            raise ProblemError(f"method: must be 'lp' or 'vi', got {self.method!r}")
        if self.backend not in defaults.BACKENDS:
            raise ProblemError(f"backend: must be one of {', '.join(defaults.BACKENDS)}, "
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
        for name, rule in _RULES.items():  # the rule every surface applies (defaults)
            v = getattr(self, name)
            if v is not None:
                try:
                    rule(v)
                except ValueError as exc:
                    raise ProblemError(f"{name}: {exc}") from None
        if self.decompose is not None and not isinstance(self.decompose, bool):
            raise ProblemError(f"decompose: must be True, False or None, got "
                               f"{self.decompose!r}")
        for name in ("clock_reduction", "exact"):
            if not isinstance(getattr(self, name), bool):
                raise ProblemError(f"{name}: must be True or False, got "
                                   f"{getattr(self, name)!r}")
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


#: The numbers of :class:`Settings`, each with its one rule (:mod:`mitld_lp.defaults`:
#: the command line, a model file's ``[budgets]`` and a sweep's ``[solve]`` apply the
#: same).
_RULES = {"time_limit": defaults.check_seconds, "max_states": defaults.check_count,
          "max_automaton_states": defaults.check_count, "max_memory": defaults.check_bytes,
          "tol": defaults.check_unit, "certify_tol": defaults.check_unit,
          "precision": defaults.check_unit, "bands": defaults.check_bands}


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
    unknown = sorted(set(kwargs) - set(Settings.__dataclass_fields__))
    if unknown:
        raise TypeError(f"unknown setting {unknown[0]!r} (settings: "
                        f"{', '.join(Settings.__dataclass_fields__)})")
    return Settings(**kwargs).checked()


@dataclass(frozen=True, slots=True, eq=False)
class Problem:
    """What is asked: maximise (or minimise, ``objective="min"``) the probability that
    ``model``'s world satisfies its task, subject to ``constraints`` (the model's own
    first, then these), then optionally minimise ``then`` (``"min-steps"`` /
    ``"min-cost"``) among the optimal policies."""

    model: Any  # mitld_lp.model.Model (not imported: the model imports the worlds)
    constraints: tuple[Any, ...] = ()  # mitld_lp.logic.constraints.Constraint records
    then: str | None = None
    objective: str = "max"
    unread: tuple[Any, ...] = ()  # constraints given that did not parse (each refused)

    @property
    def constrained(self) -> bool:
        """Whether constraints or a ``then`` objective are asked."""
        return bool(self.constraints or self.unread) or self.then is not None


@dataclass(frozen=True, slots=True, eq=False)
class Posed:
    """A problem accepted by one route, with its checked settings.

    ``route``: the :class:`~mitld_lp.routes.route.Route` that owns it (the bare base
    class while the routes are asked); ``fragment``: the class of the task as it is solved (the
    complement's for ``objective="min"``); ``robust``: some law is a band."""

    problem: Problem
    settings: Settings
    route: Route  # a bare Route only while pose asks the routes
    fragment: str
    robust: bool

    @property
    def model(self) -> Any:
        return self.problem.model

    @property
    def minimise(self) -> bool:
        return self.problem.objective == "min"

    @property
    def sensed(self) -> bool:
        """Whether some event's sensor misses it (:mod:`mitld_lp.sensing`)."""
        from mitld_lp.sensing.sensors import partial

        return bool(partial(self.problem.model.sensors))

    def beyond_points(self) -> dict[str, str]:
        """What this problem asks beyond point laws, no constraints and perfect sensors,
        by feature (``constraints``, ``band``, ``sensors``): the plain and robust
        routes' refusal of a problem not of their kind."""
        p = self.problem
        said = {"constraints": ("constraints or a then objective are solved by the "
                                "constrained LP", p.constrained),
                "band": (f"a law known only within a band ({band_text(p.model)})",
                         self.robust),
                "sensors": ("sensors that miss events are solved on the information-state "
                            "product", self.sensed)}
        return {k: why for k, (why, asked) in said.items() if asked}


class Route:
    """A route (module docs).  ``name``: the answer's ``route`` (the JSON's key, the
    word a refusal uses).  Capabilities, for the readers that would otherwise compare
    names: ``exact`` (an exact answer is given on it, :mod:`mitld_lp.exact`),
    ``takes_constraints`` (the answer carries the constraints' values and a randomised
    policy), ``observation_based`` (the controller acts on what sensors report, not on
    the product's states: the fully observed product, its chain, tree and policy map
    answer another problem), ``optimistic`` (a band is read for its best law when the
    settings ask, ``Settings.bands = "best"``)."""

    name: str = "route"
    exact: bool = False
    takes_constraints: bool = False
    observation_based: bool = False
    optimistic: bool = False

    def claims(self, posed: Posed) -> bool:
        """Whether ``posed`` (its route not yet chosen) is of this route's kind: the
        first of the precedence list to claim a problem owns it."""
        raise NotImplementedError

    def refusal(self, posed: Posed) -> list[str]:
        """Every reason this route does not solve ``posed`` as posed, each naming its
        feature (empty: it does).  Never raises."""
        raise NotImplementedError

    def build(self, posed: Posed, progress: bool | None = None) -> Any:
        """The automaton, STA and product this route's solver works on, under the
        problem's budgets (a :class:`mitld_lp.routes.stages.Built`)."""
        raise NotImplementedError

    def solve(self, posed: Posed, built: Any, *, costs: Mapping[str, float] | None = None,
              seed: int | None = 0) -> Any:
        """The answer on ``built`` (``costs`` / ``seed``: a randomised policy's action
        costs and generator, for the routes that have one): a
        :class:`mitld_lp.result.Result`."""
        raise NotImplementedError

    def __repr__(self) -> str:
        return f"<route {self.name}>"


def pose_on(routes: Sequence[Route], model: Any, constraints: Iterable[Any] = (), *,
            then: str | None = None, settings: Settings | None = None,
            objective: str | None = None) -> Posed:
    """Validate the problem once and choose its route (module docs).  ``constraints``:
    texts or :class:`~mitld_lp.logic.constraints.Constraint` records, after the model's own;
    ``objective``: the model's unless given; ``routes``: the routes to ask, in
    precedence (:func:`mitld_lp.synthesis.pose` asks
    :data:`mitld_lp.routes.precedence.ROUTES`; the trade-off curve's end points ask the
    constrained LP's, :data:`~mitld_lp.routes.precedence.LP`).
    Raises :class:`ProblemError` naming the combination no route solves, or the option
    the route cannot honour: every reason at once, not the first alone."""
    from mitld_lp.logic.constraints import THEN, ConstraintError, parse_constraints
    from mitld_lp.logic.fragment import check
    from mitld_lp.model import Model

    if not isinstance(model, Model):
        raise TypeError(
            f"expected a Model (load_model(path) or Model.from_game(game, spec)), "
            f"got {type(model).__name__}")
    s = (settings or Settings()).checked().resolved(model.budgets)
    refused: list[str] = []  # every reason, each naming its feature
    goal = model.objective if objective is None else objective
    if goal not in OBJECTIVES:
        refused.append(f"objective: must be 'max' or 'min', got {goal!r}")
    if then is not None and then not in THEN:
        refused.append(f"then: must be one of {', '.join(THEN)}, got {then!r}")
    cons: tuple[Any, ...] = ()
    unread: tuple[Any, ...] = ()
    for item in (*model.constraints, *constraints):
        try:
            cons += parse_constraints([item])
        except ConstraintError as exc:
            refused.append(str(exc))
            unread += (item,)
    fragment = check(model.spec).fragment
    if goal == "min":
        fragment = complement_class(fragment)
    if s.truncation is not None:
        unknown = sorted(set(dict(s.truncation)) - set(model.distributions))
        if unknown:
            refused.append(
                f"truncation: {unknown[0]!r} is not an event of the model (events: "
                f"{', '.join(sorted(model.distributions)) or 'none'})")
    robust = any(d.is_ambiguous for d in model.distributions.values())
    asked = Posed(Problem(model, cons, then, goal, unread), s, Route(), fragment, robust)
    candidates = routes
    owner = next((r for r in candidates if r.claims(asked)), None)
    if owner is None:  # no route's kind: every route's reasons
        refused += [why for r in candidates for why in r.refusal(asked)] or [
            f"no route solves {task_words(fragment, goal)} as posed"]
        raise ProblemError(*refused)
    refused += owner.refusal(asked)
    if robust and s.bands != "worst" and not owner.optimistic:
        extra = [k for k in asked.beyond_points() if k != "band"]
        said = f"with {' and '.join(extra)}" if extra else f"on the {owner.name} route"
        refused.append(f"bands {s.bands!r} {said}: a band is read for "
                       "its best law only without a sensor that misses (the robust and "
                       f"constrained routes); the {owner.name} route reads it for the "
                       "worst law (bands 'worst')")
    posed = Posed(asked.problem, s, owner, fragment, robust)
    if s.exact:  # an exact answer (mitld_lp.exact): what it cannot take, before any work
        from mitld_lp.exact.stage import exact_refusal

        why = exact_refusal(posed)
        if why is not None:
            refused.append(why)
    if refused:
        raise ProblemError(*refused)
    return posed


def task_words(fragment: str, goal: str) -> str:
    """How a refusal names the task: its class, and for a minimum the complement's."""
    article = "an" if fragment[0] in "aeiou" else "a"
    return (f"{article} {fragment} task" if goal == "max" else
            f"objective min (solved as the maximum of the complement, {article} {fragment} "
            "task)")


def band_text(model: Any) -> str:
    """The model's laws known only within a band, as ``event ~ law, ...``."""
    return ", ".join(f"{e} ~ {d}" for e, d in sorted(model.distributions.items())
                     if d.is_ambiguous)
