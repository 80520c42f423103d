"""Which problems with sensors that miss the ``sensed`` route solves, and the refusal
naming each combination it does not (:func:`mitld_lp.problem.pose` raises it)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from mitld_lp.logic.fragment import CO_SAFE
from mitld_lp.sensing.sensors import partial
from mitld_lp.worlds.game import GameError, world_members

__all__ = ["sensed_refusals"]


def sensed_refusals(model: Any, fragment: str, objective: str, constraints: Sequence[Any],
                    then: str | None, robust: bool) -> list[str]:
    """Why the ``sensed`` route cannot solve this problem as posed: every reason, each
    naming its feature (empty: it can).  ``model`` has at least one sensor that is not
    perfect."""
    sensors = partial(model.sensors)
    named = ", ".join(f"{a} = {s}" for a, s in sensors.items())
    head = f"sensors ({named})"
    refused = []
    for a, s in sensors.items():
        if s.false_alarm:
            refused.append(f"sensors.{a}.false_alarm = {s.false_alarm:g}: with false alarms "
                           "the robot's belief depends on the time of every report, so the "
                           "information state is not finite; not solved (give "
                           "false_alarm = 0)")
    if constraints or then is not None:
        what = f"then = {then}" if then is not None else f"constraint {constraints[0]}"
        refused.append(f"{what} with {head}: the constrained LP over observation-based "
                       "policies is not solved; drop the constraints or the sensors")
    if robust:
        bands = ", ".join(f"{e} ~ {d}" for e, d in sorted(model.distributions.items())
                          if d.is_ambiguous)
        refused.append(f"{head} with a law known only within a band ({bands}): the worst "
                       "case over observation-based policies is not solved; give the event "
                       "a point law")
    if objective == "min":
        refused.append(f"objective min with {head}: the complement is a safety task, which "
                       "the observation-based route does not solve")
    elif fragment != CO_SAFE:
        refused.append(f"a {fragment} task with {head}: only co-safe tasks are solved on "
                       "what the robot observes")
    for a in sensors:
        if model.distributions[a].never > 0:
            refused.append(f"sensors.{a}: the law of {a!r} leaves probability "
                           f"{model.distributions[a].never:.3g} that it never happens, so "
                           "the belief that it has not happened yet changes at every step "
                           "without end; not solved (give a law that surely happens)")
    try:
        reacts = world_members(model.game).event_names
    except GameError:  # the model's loader checked the world; nothing to add here
        reacts = frozenset()
    for a in sorted(reacts & set(sensors)):
        refused.append(f"sensors.{a}: the world's moves react to the sensed event {a!r} "
                       "(event_names), so the world's state reveals it; not solved")
    return refused
