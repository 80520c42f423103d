"""Reward-bounded reachability as Storm reads it: ``Pmax=? [F{"r"}<=b "goal"]``,
``Pmin=? [left U{"r"}<=b right]``, ``F{"r"}<b`` (``P~p`` as well), on a PRISM or JANI
file whose reward structure ``r`` has non-negative integer rewards.

The semantics (Storm's): a path satisfies ``left U{"r"}<=b right`` when it reaches a
``right`` state at some step ``n``, every state before is a ``left`` state, and the
reward collected by the choices taken before step ``n`` (each choice's action reward
plus its state's state reward) is at most ``b``; ``<b`` asks for less than ``b``.

:func:`pose_reward_bounded` reads Storm's property into a :class:`RewardBounded` (the
bound made an integer ``B``: ``<=b`` is ``floor(b)``, ``<b`` is ``ceil(b) - 1``) or
refuses it by name: a lower bound, an interval, several bounds, a bound below 0 or not a
number, a step (time) bound together with it, a filter, a file without the structure.
The answer (:mod:`mitld_lp.exact.reward_bounded`) unfolds the collected reward,
``0..B``, into the states.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from fractions import Fraction
from typing import Any

from mitld_lp.worlds.prism_rewards import RewardQuery
from mitld_lp.worlds.properties import (
    INIT_FILTER,
    PropertyError,
    Query,
    probability_objective,
)

__all__ = ["RewardBounded", "is_reward_bounded", "pose_reward_bounded"]

_BOUND = re.compile(r'U\s*rew\s*\{\s*"([^"]*)"\s*\}\s*(<=|<)\s*(\S+)\s')


@dataclass(frozen=True)
class RewardBounded:
    """One reward-bounded ``P`` property.

    Attributes:
        query: its name, text, objective and ``P~p`` comparison (``spec`` the formula as
            Storm prints it; it is no MITLD task).
        reward: the reward structure's name.
        bound: ``B``, the most reward a path may collect before ``right``.
        reward_query: what the model is built for (:func:`mitld_lp.worlds.prism_rewards.
            reward_mdp`): the structure, ``right`` as its target, ``left``.
    """

    query: Query
    reward: str
    bound: int
    reward_query: RewardQuery


def is_reward_bounded(prop: Any) -> bool:
    """Whether Storm's property is a ``P`` operator over a reward-bounded until."""
    import stormpy.logic as logic  # pyright: ignore[reportMissingImports]

    formula = prop.get_raw_formula()
    if not isinstance(formula, logic.ProbabilityOperatorFormula):
        return False
    sub = formula.subformula
    if not isinstance(sub, logic.BoundedUntilFormula):
        return False
    rest = str(sub)[len(str(sub.left_subformula)):].lstrip()
    return rest.startswith(("Urew", "U^{"))


def _refuse(name: str, text: str, form: str, why: str) -> PropertyError:
    return PropertyError(f"property {name} ({text}): {form} is refused: {why}")


def pose_reward_bounded(name: str, prop: Any, reward_names: list[str], *,
                        chain: bool = False) -> RewardBounded:
    """The :class:`RewardBounded` of Storm's property ``prop`` (one for which
    :func:`is_reward_bounded` holds) over a file whose reward structures are
    ``reward_names`` (``chain``: a DTMC, ``P=?`` needs no ``min`` or ``max``), or
    :class:`PropertyError` naming the form refused."""
    formula = prop.get_raw_formula()
    text = str(formula)
    if not INIT_FILTER.search(str(prop)):
        raise _refuse(name, text, "a filter", "only the value at the initial state is "
                      "answered")
    objective, comparison, threshold = probability_objective(name, formula, chain=chain)
    sub = formula.subformula
    left, right = sub.left_subformula, sub.right_subformula
    rest = str(sub)[len(str(left)):].lstrip()
    if rest.startswith("U^{"):
        raise _refuse(name, text, "several bounds on one until", "one reward bound "
                      "F{\"r\"}<=b is answered")
    m = _BOUND.match(rest)
    if m is None or sub.has_lower_bound:
        shown = rest.split(" ")[0]
        raise _refuse(name, text, f"the reward bound {shown!r}",
                      "a lower bound or an interval is not answered; F{\"r\"}<=b and "
                      "F{\"r\"}<b are")
    reward, strict, given = m[1], m[2] == "<", m[3]
    try:
        value = Fraction(str(sub.upper_bound_expression.evaluate_as_rational()))
    except (RuntimeError, ValueError):
        raise _refuse(name, text, f"the reward bound {given!r}", "it is not a number (a "
                      "constant without a value? give it with --const)") from None
    bound = math.ceil(value) - 1 if strict else math.floor(value)
    if bound < 0:
        raise _refuse(name, text, f"the reward bound {m[2]}{given}", "no collected reward "
                      "is below 0 (rewards are >= 0)")
    if reward not in reward_names:
        known = ", ".join(f'"{r}"' for r in reward_names) or "none"
        raise PropertyError(f"property {name} ({text}): the file has no reward structure "
                            f"\"{reward}\" (reward structures: {known})")
    query = Query(name=name, text=text, spec=str(sub), objective=objective,
                  comparison=comparison, threshold=threshold)
    keep = None if str(left).strip() == "true" else left
    posed = RewardQuery(name=name, text=text, reward=reward, objective=objective,
                        target=right, kind="bounded", formula=formula, left=keep)
    return RewardBounded(query=query, reward=reward, bound=bound, reward_query=posed)
