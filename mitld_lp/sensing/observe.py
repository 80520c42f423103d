"""Acting on what the robot observes when sensors miss events.

    controller.reset()
    action = controller.act(Observation(state=s0))                   # step 0
    ...                                                              # the robot moves
    action = controller.act(Observation(state=s1, reports={"b1"}))   # the camera saw b1

An :class:`Observation` holds the world state and the *reports* of the step that led
there: the sensed events a sensor reported in that step, and the events without a
sensor that happened in it (a perfect sensor reports an event the step it happens).
The controller never reads a sensed event itself: it follows the information state of
:mod:`mitld_lp.sensing.belief` from the observations and its own actions.

:func:`simulate_sensed` draws the hidden event times from their laws and each sensor's
reports, runs the controller on the observations only, and judges each run by the
task's automaton on the *true* events.
"""

from __future__ import annotations

import math
import os
from collections.abc import Hashable
from dataclasses import dataclass
from typing import Any

import numpy as np

from mitld_lp import defaults
from mitld_lp.controller import RunStatus
from mitld_lp.game import Game
from mitld_lp.problem import ProblemError
from mitld_lp.product import Absorbing
from mitld_lp.sensing.belief import Belief
from mitld_lp.simulate import SimulationResult, _check_count, _sample_successor, _wilson

__all__ = ["Observation", "SensedController", "simulate_sensed", "SensedControllerError"]


class SensedControllerError(ProblemError):
    """A use of the observation-based controller it does not support (saving it, its
    tables): a problem error, so the command line exits 2 naming it."""


@dataclass(frozen=True, slots=True)
class Observation:
    """What the robot sees after a step: the world ``state`` and the ``reports`` of the
    step (module docs), any collection of event names (stored as a frozenset; a bare
    string is refused, write ``reports={"b1"}``)."""

    state: Hashable
    reports: frozenset[str] = frozenset()

    def __post_init__(self) -> None:
        try:
            hash(self.state)
        except TypeError:
            raise TypeError(f"Observation.state: a world state is hashable, got "
                            f"{type(self.state).__name__}") from None
        reports: Any = self.reports
        if isinstance(reports, str | bytes):
            raise TypeError(f"Observation.reports: expected a set of event names, got the "
                            f"string {reports!r}; write reports={{{reports!r}}}")
        try:
            reports = frozenset(reports)
        except TypeError:
            raise TypeError("Observation.reports: expected a set of event names, got "
                            f"{type(reports).__name__}") from None
        if not all(isinstance(e, str) for e in reports):
            raise TypeError(f"Observation.reports: event names are strings, got {reports!r}")
        object.__setattr__(self, "reports", reports)


class SensedController:
    """The synthesised observation-based policy, run online (module docs).

    ``status``: ``ACCEPTED`` (resp. ``REJECTED``) once every hypothesis the
    observations leave has satisfied (resp. violated) the task; ``finished``: nothing
    the robot does can change the outcome any more (also when the hypotheses left are
    decided differently); ``beyond_model``: an observation the model gives probability
    0 (an event later than its truncation point): the controller then plays the
    world's first action."""

    randomised = False
    sensed = True

    def __init__(self, game: Game[Any], belief: Belief, policy: np.ndarray) -> None:
        self.game, self.belief = game, belief
        self.policy = np.asarray(policy)
        self.events = frozenset(belief.sta.events)
        self.reset()

    def reset(self, seed: int | None = None) -> None:
        self.info: int | None = None
        self.last: str | None = None
        self.status = RunStatus.RUNNING
        self.finished = False
        self.beyond_model = False
        self.steps = 0

    @property
    def state(self) -> Any:
        """The current information state (an :class:`~mitld_lp.sensing.belief.InfoState`),
        None before the first observation, once finished, or beyond the model."""
        return None if self.info is None else self.belief.mdp.states[self.info]

    def _choose(self, world: Hashable) -> str | None:
        mdp = self.belief.mdp
        if self.info is None:
            self.last = str(next(iter(self.game.actions(world))))
            return self.last
        state = mdp.states[self.info]
        if isinstance(state, Absorbing):
            self._finish(state)
            return None
        self.last = mdp.action_name(int(self.policy[self.info]))
        return self.last

    def _finish(self, end: Absorbing) -> None:
        self.finished = True
        self.info = None
        self.status = {Absorbing.TARGET: RunStatus.ACCEPTED,
                       Absorbing.SINK: RunStatus.REJECTED}.get(end, RunStatus.RUNNING)

    def act(self, observation: Observation) -> str | None:
        """The action for ``observation`` (None once finished)."""
        if not isinstance(observation, Observation):
            raise TypeError("SensedController.act: expected a mitld_lp.sensing.observe."
                            f"Observation (state, reports), got {type(observation).__name__}")
        unknown = sorted(observation.reports - self.events)
        if unknown:
            raise ValueError(f"Observation.reports: {unknown[0]!r} is not an event of the "
                             f"task (events: {', '.join(sorted(self.events))})")
        if self.finished:
            return None
        mdp = self.belief.mdp
        first = self.steps == 0 and self.last is None
        self.steps += 1
        if first:
            if observation.reports:
                raise ValueError(f"Observation.reports at step 0: no event happens at step "
                                 f"0, got {sorted(observation.reports)}")
            self.info = mdp.initial
            return self._choose(observation.state)
        if self.beyond_model or self.info is None:
            return self._choose(observation.state)
        sensed = frozenset(self.belief.sensed)
        obs = (observation.state, observation.reports - sensed, observation.reports & sensed)
        nxt = self.belief.moves.get((self.info, self.last or ""), {}).get(obs)
        if nxt is None:
            self.beyond_model = True
            self.info = None
            return self._choose(observation.state)
        if isinstance(nxt, Absorbing):
            self._finish(nxt)
            return None
        self.info = nxt
        return self._choose(observation.state)

    def save(self, path: str | os.PathLike[str], *, overwrite: bool = False,
             max_states: int = defaults.MAX_STATES) -> None:
        raise SensedControllerError(
            "saving a controller that acts on sensor reports is not supported yet: its "
            "memory is the information state; run it from the synthesis result")

    def tables(self, max_states: int = defaults.MAX_STATES) -> None:
        raise SensedControllerError(
            "the tables of a controller that acts on sensor reports are not written yet")


def simulate_sensed(model: Any, controller: SensedController, *, runs: int = defaults.RUNS,
                    seed: int | None = 0, max_steps: int = defaults.MAX_STEPS
                    ) -> SimulationResult:
    """Estimate the probability that ``controller`` satisfies ``model``'s task (module
    docs), with a Wilson 95% interval.  Each run draws every event's time from its law,
    then each sensed event's report ``delay + j`` steps after it, ``j ~
    Geometric(detect)`` (``j = 0``: the step its report is first due); the world moves
    on the true events; the task's automaton reads the true events.  ``beyond_model``
    counts the runs in which the controller met an observation the model gives
    probability 0 (an event past its truncation point);
    ``undecided`` the runs whose automaton had no verdict when the controller stopped
    (every hypothesis left was decided) or after ``max_steps``: failures, such as a bus
    missed, which the automaton never rejects (it does not know a bus comes once)."""
    from mitld_lp.automata.translate import to_dta

    _check_count("runs", runs, 1, defaults.MAX_RUNS)
    _check_count("max_steps", max_steps, 0, defaults.MAX_STEPS_LIMIT)
    if seed is not None:
        _check_count("seed", seed, 0, None)
    rng = np.random.default_rng(seed)
    game, dta = model.game, to_dta(model.spec)
    sensors = controller.belief.sensors
    laws = sorted(model.distributions.items())
    ok = beyond = undecided = 0
    for _ in range(runs):
        times = {a: float(law.sample(rng, 1)[0]) for a, law in laws}
        seen = dict(times)
        for a in sorted(sensors):
            d = sensors[a].detect
            seen[a] = times[a] + sensors[a].delay + (rng.geometric(d) - 1 if d > 0
                                                     else math.inf)
        controller.reset()
        s = game.initial
        q = dta.step(dta.initial, frozenset(game.propositions(s)))
        reports: frozenset[str] = frozenset()
        verdict = None
        for t in range(max_steps + 1):
            if q == dta.accepting or q == dta.rejecting:
                verdict = q == dta.accepting
                break
            action = controller.act(Observation(s, reports))
            if action is None:
                break
            events = frozenset(a for a, k in times.items() if k == t + 1)
            reports = frozenset(a for a, k in seen.items() if k == t + 1)
            s = _sample_successor(rng, game.successors(s, action, events))
            q = dta.step(q, frozenset(game.propositions(s)) | events)
        if verdict is None and (q == dta.accepting or q == dta.rejecting):
            verdict = q == dta.accepting
        ok += bool(verdict)
        undecided += verdict is None
        beyond += controller.beyond_model
    lo, hi = _wilson(ok, runs)
    return SimulationResult(runs, ok, ok / runs, lo, hi, beyond, undecided, seed, max_steps)
