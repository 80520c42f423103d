"""``synthesize`` and ``solve``: the one place that wires the stages, for every problem.

    problem --pose--> Posed --build_posed--> automaton, STA, product (Built)
            --the route's solver and certificate--> Result

The route is the posed problem's (:mod:`mitld_lp.routes.precedence`): this module
names none; it asks the route to build and to solve.  On every route ``lower`` is what the
returned controller achieves in the real, untruncated world and ``upper`` what no policy
beats (docs/results.md).
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

from mitld_lp.checks import Check
from mitld_lp.model import Model
from mitld_lp.problem import Posed, Route, Settings, pose_on, settings_from
from mitld_lp.result import Result
from mitld_lp.routes import precedence
from mitld_lp.routes.stages import Built, build_posed, build_product

__all__ = ["synthesize", "synthesize_constrained", "solve", "build_product", "Built",
           "Result", "Check"]

log = logging.getLogger(__name__)

def pose(model: Any, constraints: Iterable[Any] = (), *, then: str | None = None,
         settings: Settings | None = None, objective: str | None = None,
         routes: Sequence[Route] | None = None) -> Posed:
    """Validate the problem once and choose its route: the first of ``routes`` (default
    :data:`mitld_lp.routes.precedence.ROUTES`) that claims it owns it
    (:func:`mitld_lp.problem.pose_on`, which says every reason a route refuses it)."""
    return pose_on(precedence.ROUTES if routes is None else routes, model, constraints, then=then,
                   settings=settings, objective=objective)


def synthesize(
    model: Model,
    *,
    constraints: Iterable[Any] = (),
    then: str | None = None,
    objective: str | None = None,
    settings: Settings | None = None,
    **options: Any,
) -> Result:
    """Maximise (or, with ``objective="min"`` or the model's own objective, minimise)
    the probability that the model's world satisfies its MITLD spec.

    ``model``: a :class:`Model`, loaded from a file (:func:`mitld_lp.load_model`) or
    made from any game with :meth:`Model.from_game`; ``epsilon`` overrides its
    truncation budget.  ``method``: ``"lp"`` (occupancy LP through Clarabel, called
    directly, or through cvxpy with ``backend="cvxpy"``, which also takes any other
    ``solver`` cvxpy has) or ``"vi"`` (interval iteration alone).  Interval
    iteration always runs, as the cross-check.  ``truncation`` fixes truncation points
    per event instead of ``epsilon``.  The budgets are :func:`build_product`'s (``None``:
    the model file's ``[budgets]``, else the defaults).  ``decompose``: the LP block by
    block in topological order (``None``, the default, or ``True``) or as one LP
    (``False``).  ``time_limit``: seconds for the solve stage; past it the status is
    ``TIME_LIMIT``.  ``progress``: a bar for each long stage where standard error is a
    terminal (``None``), never (``False``) or wherever it goes (``True``;
    :mod:`mitld_lp.util.progress`).  ``precision``: the relative width the certified
    bracket may have (``upper - lower <= precision * lower``; with truncation, the
    solver's part of the width), else the answer is not certified (docs/results.md).
    ``constraints`` / ``then`` (and the model's constraints): the constrained synthesis
    (:mod:`mitld_lp.routes.constrained`); a law known only within a band: the robust
    synthesis (:mod:`mitld_lp.routes.robust`).  ``exact``: also the exact optimum as a
    fraction, ``Result.exact``, the bracket then its point (:mod:`mitld_lp.exact`; the
    plain route, models of modest size, laws and worlds with rational probabilities).

    ``options`` are the fields of :class:`~mitld_lp.problem.Settings` (those above and
    ``clock_reduction``, ``max_states``, ``max_automaton_states``, ``max_memory``,
    ``tol``, ``certify_tol``), each checked by the rule every surface applies; or give
    one ``settings=`` record instead.

    The problem is posed once (:func:`mitld_lp.synthesis.pose`): a combination no route
    solves, or an option its route cannot honour, raises
    :class:`~mitld_lp.problem.ProblemError` naming it.
    """
    if settings is not None and options:
        raise TypeError(f"synthesize: give settings= or its keywords, not both (got "
                        f"settings and {', '.join(sorted(options))})")
    settings = settings if settings is not None else settings_from(**options)
    return solve(pose(model, constraints, then=then, settings=settings, objective=objective))


def solve(posed: Posed, *, costs: Mapping[str, float] | None = None,
          seed: int | None = 0) -> Result:
    """The one wiring of every posed problem (:mod:`mitld_lp.problem`):

        formula --> automaton --> STA --> product (build_posed, one for every route)
                --> the route's solver and certificate --> Result

    The route solves what the problem poses: ``plain`` the occupancy LP (or interval
    iteration) on the product; ``robust`` the interval MDP's robust optimum; ``sensed``
    the optimum over observation-based policies on the information-state product; with
    constraints the constrained occupancy LP on the joint product, and with a band its
    sound robust bracket.  ``costs`` / ``seed``: a constrained problem's action costs
    (default the model's) and its randomised controller's seed."""
    return _with_world_checks(_solve_route(posed, costs, seed), posed.model.game)


def _solve_route(posed: Posed, costs: Mapping[str, float] | None, seed: int | None) -> Result:
    built = build_posed(posed, progress=posed.settings.progress)
    return posed.route.solve(posed, built, costs=costs, seed=seed)


def _with_world_checks(result: Result, game: Any) -> Result:
    """``result`` with a check saying how the world was read, when it was changed: a
    PRISM world's choices whose probabilities summed to 1 only within PRISM's tolerance
    were divided by their sums (:class:`mitld_lp.worlds.successors.Normalisation`), so
    the bracket is the normalised world's."""
    import sys

    # a PrismGame's module is loaded once one exists: a grid world does not load it
    prism = sys.modules.get("mitld_lp.worlds.prism")
    if prism is None or not isinstance(game, prism.PrismGame) or game.normalised is None:
        return result
    from dataclasses import replace

    check = Check("world's probabilities normalised", True, str(game.normalised))
    return replace(result, checks=(*result.checks, check))


def synthesize_constrained(
    model: Model,
    constraints: Iterable[Any] = (),
    *,
    then: str | None = None,
    costs: Mapping[str, float] | None = None,
    seed: int | None = 0,
    **options: Any,
) -> Result:
    """Maximise the task's probability subject to ``constraints`` (texts or records;
    the model's own ``constraints`` come first), then, with ``then`` (``"min-steps"``
    or ``"min-cost"``), minimise the expected steps / cost among the policies within
    :data:`~mitld_lp.logic.constraints.LEXICOGRAPHIC_TOL` of that probability; by the
    constrained LP even with no constraint (docs/constraints.md).  ``costs``: per action
    (default the model's ``[costs]``, 1 for any action not named).  ``seed`` seeds the
    controller's generator.  ``options``: :func:`synthesize`'s settings (epsilon,
    budgets, truncation, ...), each honoured or refused by name (:func:`pose`)."""
    from mitld_lp.routes.precedence import LP

    posed = pose_on(LP, model, constraints, then=then, settings=settings_from(**options))
    return solve(posed, costs=costs, seed=seed)
