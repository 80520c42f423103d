"""Monte-Carlo rollouts of a constrained (randomised) controller in the untruncated
world: how often the task and each constraint's formula are satisfied, and the mean
number of steps taken while the task was undecided (what E(steps) counts)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mitld_lp.automata.joint import ACCEPTED
from mitld_lp.controllers.observation import Observation
from mitld_lp.result import Result

__all__ = ["RunStats", "run_constrained"]


@dataclass(frozen=True, slots=True)
class RunStats:
    """Counts over ``runs`` rollouts: ``accepted[i]`` runs in which component ``i``
    (0: the task, then each probability constraint's formula) was satisfied;
    ``steps``: per run, the steps charged; ``unsettled``: runs still open at
    ``max_steps``."""

    runs: int
    accepted: tuple[int, ...]
    steps: np.ndarray
    unsettled: int


def run_constrained(result: Result, *, runs: int = 10_000, seed: int = 0,
                    max_steps: int = 1000) -> RunStats:
    """Roll the result's controller out ``runs`` times (seeded: the events' times, the
    world's moves and the controller's draws all come from one generator)."""
    controller = result.controller
    if controller is None:
        raise ValueError(f"no controller: the synthesis is {result.status}")
    rng = np.random.default_rng(seed)
    controller.rng = rng
    game, sta = controller.game, controller.sta
    k = len(result.joint.parts)
    accepted = np.zeros(k, dtype=np.int64)
    steps = np.zeros(runs)
    unsettled = 0
    for r in range(runs):
        times = {a: float(c.distribution.sample(rng, 1)[0]) for a, c in sta.clocks.items()}
        controller.reset()
        s, events = game.initial, frozenset()
        for t in range(max_steps + 1):
            action = controller.act(Observation(s, events))
            if action is None or controller.settled:
                break
            events = frozenset(a for a, when in times.items() if when == t + 1)
            succ = game.successors(s, action, events)
            states = [x for x, _ in succ]
            probs = np.array([p for _, p in succ])
            s = states[int(rng.choice(len(states), p=probs / probs.sum()))]
        else:
            unsettled += 1
        accepted += np.array([v == ACCEPTED for v in controller.verdicts])
        steps[r] = controller.charged
    return RunStats(runs, tuple(int(a) for a in accepted), steps, unsettled)
