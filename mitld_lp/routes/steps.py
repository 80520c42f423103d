"""The expected steps (or cost) of satisfying an MITLD task, as the primary objective:
Storm's ``Rmin=? [F accept]`` on the task's product, asked on the command line with
``--objective min-steps`` / ``min-cost`` (a model file's ``objective`` key is the
probability's ``"max"`` or ``"min"`` and refuses these by name, docs/model-files.md;
``--then min-steps`` after a probability is the constrained route's lexicographic LP).

The product is the plain route's (:func:`mitld_lp.routes.stages.build_posed` of the task
posed for its maximum probability); each of its transitions is one step of the world,
and costs one step (``min-steps``) or the model's cost of the action taken
(``min-cost``: its ``[costs]``, 1 for an action it does not name).  The answer is the
least expected number of steps (cost) until the task's automaton accepts, over the
policies that satisfy the task with probability 1, with the float route's certified
bracket (:func:`mitld_lp.solvers.reward.solve_reward_float`, the product's
probabilities' allowance :func:`~mitld_lp.solvers.rounding.model_eta`); where no policy
satisfies the task with probability 1 it is ``inf``, Storm's infinity, decided by the
product's graph.

Refused by name, before any work (:func:`steps_refusal`): constraints and ``then`` (a
primary objective of its own), a law known only within a band, sensors that miss
events, a task that is not co-safe (a safety task is never satisfied at a step),
``--exact``; and, once
the product is built, a product whose event clocks were truncated (its expected steps
are not the model's: geometric laws and laws of finite support keep it exact).
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from mitld_lp.logic.fragment import CO_SAFE
from mitld_lp.mdp import ABSORB
from mitld_lp.problem import Posed, ProblemError
from mitld_lp.routes.constrained import cost_vector
from mitld_lp.routes.stages import Built
from mitld_lp.solvers.reward import solve_reward_float
from mitld_lp.solvers.rounding import model_eta
from mitld_lp.worlds.prism_rewards import RewardMDP

__all__ = ["STEP_OBJECTIVES", "StepsAnswer", "steps_refusal", "expected_steps"]

STEP_OBJECTIVES = ("min-steps", "min-cost")
"""The objectives that minimise an expected total until the task is satisfied."""


@dataclass(frozen=True, slots=True)
class StepsAnswer:
    """The least expected steps (cost) until the task is satisfied: ``lower <= value <=
    upper`` (both ``inf`` when ``infinite``), ``certified``, the product's sizes, the
    occupancy LP's objective (None when not run) and the seconds of the solve."""

    objective: str
    lower: float
    upper: float
    infinite: bool
    certified: bool
    states: int
    choices: int
    lp_value: float | None
    seconds: float


def steps_refusal(posed: Posed, objective: str) -> list[str]:
    """Every reason ``objective`` (one of :data:`STEP_OBJECTIVES`) is not solved for
    ``posed`` (the task posed for its maximum probability), each naming its feature."""
    if objective not in STEP_OBJECTIVES:
        return [f"objective: must be one of {', '.join(STEP_OBJECTIVES)}, got {objective!r}"]
    p = posed.problem
    head = f"objective {objective}"
    why = []
    if p.constraints or p.unread:
        why.append(f"{head} with constraints: not solved (constraints bound the "
                   "probability-maximising LP; use --then min-steps there)")
    if p.then is not None:
        why.append(f"{head} with then {p.then}: the objective is already the expected "
                   "total; drop --then")
    if posed.robust:
        why.append(f"{head} with a law known only within a band: not solved (point laws "
                   "only)")
    if posed.sensed:
        why.append(f"{head} with sensors that miss events: not solved (fully observed "
                   "worlds only)")
    if posed.fragment != CO_SAFE:
        why.append(f"{head}: a {posed.fragment} task is not satisfied at a step; the "
                   "expected steps until acceptance need a co-safe task")
    if posed.settings.exact:
        why.append(f"{head} with --exact: not solved in rational arithmetic (the answer "
                   "is a certified bracket)")
    return why


def _rewards(built: Built, objective: str, costs: Mapping[str, float]) -> np.ndarray:
    mdp = built.mdp
    actions = np.asarray(mdp.choice_actions)
    if objective == "min-steps":
        return np.where(actions == ABSORB, 0.0, 1.0)
    per_action = cost_vector(mdp, costs)  # an action the world lacks: refused by name
    if (per_action < 0).any() or not np.isfinite(per_action).all():
        raise ProblemError("costs: objective min-cost needs finite costs >= 0")
    out = np.zeros(actions.size)
    moves = actions != ABSORB
    out[moves] = per_action[actions[moves]]
    return out


def expected_steps(posed: Posed, built: Built, objective: str, *,
                   time_limit: float | None = None) -> StepsAnswer:
    """The answer (module docs) on ``built``, the product of ``posed``'s task; raises
    :class:`ProblemError` naming what is refused."""
    reasons = steps_refusal(posed, objective)
    mdp = built.mdp
    if mdp.truncated.any():
        reasons.append(f"objective {objective}: the product truncates event clocks "
                       f"({built.sta.truncation_points}): its expected steps are not the "
                       "model's (geometric laws and laws of finite support keep the "
                       "product exact)")
    if reasons:
        raise ProblemError(*reasons)
    started = time.perf_counter()
    matrix = sp.csr_array(mdp.matrix, copy=True)
    matrix.eliminate_zeros()
    model = RewardMDP(groups=np.asarray(mdp.row_groups, dtype=np.int64),
                      indptr=np.asarray(matrix.indptr, dtype=np.int64),
                      indices=np.asarray(matrix.indices, dtype=np.int64),
                      probabilities=np.asarray(matrix.data, dtype=np.float64),
                      rewards=_rewards(built, objective, posed.model.costs),
                      target=np.asarray(mdp.target, dtype=bool), initial=int(mdp.initial))
    answer = solve_reward_float(model, "min", time_limit=time_limit,
                                eta=model_eta(built.sta))
    return StepsAnswer(objective=objective, lower=answer.lower, upper=answer.upper,
                       infinite=answer.infinite, certified=answer.certified,
                       states=mdp.n_states, choices=mdp.n_choices,
                       lp_value=answer.lp_value, seconds=time.perf_counter() - started)
