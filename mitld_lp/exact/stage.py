"""The exact answer as a stage of the plain route: what it refuses, its budget, both
truncation models made exact, the answer in the task's terms.

``synthesize(model, exact=True)`` (``mitld-lp solve --exact``) first solves as ever in
floating point, then, within the budget (:data:`~mitld_lp.defaults.EXACT_MAX_TRANSITIONS`,
:data:`~mitld_lp.defaults.EXACT_MAX_BLOCK`, checked before the exact work from the
product's size and the float policies' chains), recomputes the product's probabilities
as rationals (:mod:`mitld_lp.exact.rows`) and makes each model's float policy exact
(:mod:`mitld_lp.exact.solve`).  When nothing is truncated the two models are one and the
answer is one fraction, ``lower = upper``; a truncated event leaves two models, and the
answer is the exact optimum of each, a bracket of two fractions around the true optimum
(the truncation's width is the model's, not the arithmetic's).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from fractions import Fraction
from typing import Any

import numpy as np

from mitld_lp import defaults
from mitld_lp.checks import Check
from mitld_lp.exact.errors import ExactError, ExactTooLarge, TimeUp
from mitld_lp.exact.rows import exact_rows
from mitld_lp.exact.solve import chain_blocks, solve_exact
from mitld_lp.worlds.exact import exact_successors_of

__all__ = ["ExactAnswer", "exact_refusal", "exact_answer", "float_below", "float_above"]

_INSTALL = "pip install 'mitld_lp[exact]'"


@dataclass(frozen=True, slots=True)
class ExactAnswer:
    """The exact optimum in the task's terms: ``lower`` and ``upper`` (fractions), the
    optima of the two truncation models (equal when nothing is truncated: then
    :attr:`value` is the one fraction); ``rounds``: policy evaluations, ``switched``:
    states whose float choice was changed (both models); ``seconds``."""

    lower: Fraction
    upper: Fraction
    rounds: int
    switched: int
    seconds: float

    @property
    def value(self) -> Fraction | None:
        """The exact optimum when it is one number (nothing truncated), else None."""
        return self.lower if self.lower == self.upper else None


def float_below(x: Fraction) -> float:
    """The largest float ``<= x``."""
    f = float(x)
    return math.nextafter(f, -math.inf) if Fraction(f) > x else f


def float_above(x: Fraction) -> float:
    """The smallest float ``>= x``."""
    f = float(x)
    return math.nextafter(f, math.inf) if Fraction(f) < x else f


def exact_refusal(posed: Any) -> str | None:
    """Why ``exact=True`` cannot be honoured for the posed problem (None when it can):
    the exact answer is the plain route's, on a world with exact probabilities
    (:mod:`mitld_lp.worlds.exact`) and laws with rational hazards, with python-flint; a
    law whose hazards the clock reduction takes for constant from some step (compared in
    floats) must have them constant from there exactly, or the reduced model would not
    be the model as written."""
    model, route, s = posed.model, posed.route, posed.settings
    if not route.exact:
        return (f"exact with the {route.name} route: an exact answer is given for a task without "
                "constraints, bands or sensors")
    try:
        import flint  # noqa: F401
    except ImportError:
        return f"exact needs python-flint for its rational linear algebra: {_INSTALL}"
    fixed = dict(s.truncation or ())
    for event, law in sorted(model.distributions.items()):
        if not law.exact_hazards:
            return (f"exact with {event} ~ {law}: its hazards are not rational numbers; an "
                    "exact answer takes geometric, pmf and uniform laws")
        k0 = law.constant_hazard_from
        if s.clock_reduction and event not in fixed and k0 is not None and \
                law.exact_constant_from() > k0:
            return (f"exact with {event} ~ {law}: its hazards look constant from step {k0} "
                    f"in floating point but are so only from step {law.exact_constant_from()}"
                    "; the clock reduction would change the model (solve with "
                    "--no-clock-reduction, or fix the event's truncation point)")
    reason = getattr(model.game, "inexact_reason", None)  # a world that says why not
    if exact_successors_of(model.game) is None and isinstance(reason, str):
        return f"exact with {reason}"
    if exact_successors_of(model.game) is None:
        return (f"exact with a {type(model.game).__name__} world: its probabilities are "
                "floats with no exact value; an exact answer takes a grid or PRISM world "
                "(or a world with exact_successors, docs/worlds.md)")
    return None


def _check_budget(mdp: Any, policies: list[np.ndarray], targets: list[np.ndarray]) -> None:
    """Refuse, before any exact work, a product with more transitions than
    :data:`EXACT_MAX_TRANSITIONS` or a float policy whose chain has a cyclic block of
    more than :data:`EXACT_MAX_BLOCK` states."""
    if mdp.n_transitions > defaults.EXACT_MAX_TRANSITIONS:
        raise ExactTooLarge(
            f"exact answer: the product has {mdp.n_transitions:,} transitions, more than "
            f"the {defaults.EXACT_MAX_TRANSITIONS:,} an exact answer takes "
            "(mitld_lp.defaults.EXACT_MAX_TRANSITIONS); checked before the exact work")
    for policy, target in zip(policies, targets, strict=True):
        acting = (np.asarray(policy) >= 0) & ~target
        sizes = chain_blocks(mdp, np.asarray(policy, dtype=np.int64), acting)
        if sizes.size and int(sizes.max()) > defaults.EXACT_MAX_BLOCK:
            raise ExactTooLarge(
                f"exact answer: the policy's chain has a cyclic block of {int(sizes.max()):,} "
                f"states, more than the {defaults.EXACT_MAX_BLOCK:,} an exact solve "
                "factorises (mitld_lp.defaults.EXACT_MAX_BLOCK); checked before the exact "
                "work")


def exact_answer(mdp: Any, game: Any, sta: Any, models: tuple[Any, Any],
                 goal: np.ndarray, *, sense: str, complemented: bool,
                 deadline: float = math.inf
                 ) -> tuple[ExactAnswer | None, tuple[Any, Any], Check]:
    """Both truncation models of ``mdp`` (target ``goal``; the upper model's also the
    truncated states) made exact from their float solutions ``models`` (the lower and
    upper :class:`~mitld_lp.routes.plain.ModelSolution`, one object when nothing is
    truncated), optimised in ``sense``; ``complemented``: the models are the
    complement's maximum, read back as ``1 -`` (a minimised task on main's route).

    Returns the :class:`ExactAnswer` (None past ``deadline``), the two models with their
    exact policies (their float values evaluated again where a choice was switched; one
    object twice when nothing is truncated), and the check that says what was done.
    Raises :class:`ExactTooLarge` (a budget) and :class:`ExactError` (a model whose exact
    probabilities cannot be had)."""
    from mitld_lp.solvers.evaluation import evaluate_policy
    from mitld_lp.solvers.result import read_only
    from mitld_lp.worlds import WorldError

    t0 = time.perf_counter()
    low, high = models
    one = high is low
    targets = [np.asarray(goal, dtype=bool)]
    if not one:
        targets.append(targets[0] | np.asarray(mdp.truncated, dtype=bool))
    chosen = [low.policy] if one else [low.policy, high.policy]
    _check_budget(mdp, chosen, targets)
    optima: list[Fraction] = []
    rounds = switched = 0
    policies = []
    try:
        try:
            values = exact_rows(mdp, game, sta, ~targets[0], deadline)
        except WorldError as exc:
            raise ExactError(str(exc)) from None
        for policy, target in zip(chosen, targets, strict=True):
            solved = solve_exact(mdp, values, target, sense, policy,
                                 max_block=defaults.EXACT_MAX_BLOCK, deadline=deadline)
            v = solved.values[mdp.initial]
            optima.append(Fraction(int(v.p), int(v.q)))
            rounds += solved.rounds
            switched += solved.switched
            policies.append(solved.policy)
    except TimeUp:
        return None, (low, high), Check("exact optimum", False,
                                f"time limit after {time.perf_counter() - t0:.1f} s")
    lo, hi = optima[0], optima[-1]
    if complemented:
        lo, hi = 1 - hi, 1 - lo
    answer = ExactAnswer(lo, hi, rounds, switched, time.perf_counter() - t0)
    exact_models = tuple(
        model if np.array_equal(policy, model.policy) else replace(
            model, policy=read_only(policy),
            policy_values=read_only(evaluate_policy(mdp, target, policy)))
        for model, policy, target in zip((low, high)[:len(policies)], policies, targets,
                                         strict=True))
    pair = (exact_models[0], exact_models[-1])
    shown = str(lo) if lo == hi else f"[{lo}, {hi}]"
    detail = (f"{shown if len(shown) <= 80 else 'found'}: {rounds} exact policy "
              f"evaluation{'s' if rounds != 1 else ''}, {switched} float choice"
              f"{'s' if switched != 1 else ''} switched, {answer.seconds:.2f} s")
    return answer, pair, Check("exact optimum", True, detail)
