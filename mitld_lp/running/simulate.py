"""Monte-Carlo rollouts of a controller in the *untruncated* world of a model.

The world is the model's: event times are drawn from the events' real laws
(``model.distributions``) by inverse CDF, not through the hazards the product uses, and
the game (``model.game``) moves by its own successor distributions.  The controller
only chooses the actions; success is decided by its automaton on the trace of labels.
The estimate comes with a Wilson 95% confidence interval.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from mitld_lp import defaults
from mitld_lp.controllers.kinds import ControllerLike
from mitld_lp.controllers.observation import Observation, RunStatus
from mitld_lp.model import Model
from mitld_lp.util.progress import bar as progress_bar
from mitld_lp.util.rollouts import (
    SimulationResult,
    check_count,
    sample_successor,
    wilson,
)

__all__ = ["SimulationResult", "simulate", "rollout", "Step"]


@dataclass(frozen=True, slots=True)
class Step:
    """One step of a rollout, for people: where the robot is, what happened, what the
    automaton and the clock say, and what the controller chose."""

    t: int
    state: Any
    events: frozenset[str]
    automaton: int
    pending: frozenset[str]
    clock: int
    action: str | None


def rollout(
    model: Model,
    controller: ControllerLike,
    rng: np.random.Generator,
    *,
    max_steps: int = defaults.MAX_STEPS,
    record: bool = False,
) -> tuple[RunStatus, list[Step]]:
    """One run of ``controller`` (deterministic or randomised) in ``model``'s world:
    returns the controller's final status and (if ``record``) the steps.  Each event's
    time is drawn from its law once, at the start (events in name order, so a seed gives
    the same run).  The run ends when the controller stops acting, or when the task is
    decided (a randomised controller may go on deciding its constraints)."""
    game = model.game
    times = {a: float(law.sample(rng, 1)[0]) for a, law in sorted(_laws(model, controller))}
    controller.reset()
    s = game.initial
    events: frozenset[str] = frozenset()
    steps: list[Step] = []
    for t in range(max_steps + 1):
        action = controller.act(Observation(s, events))
        if record:
            steps.append(
                Step(t, s, events, controller.automaton_state or 0, controller.pending,
                     controller.clock, action)
            )
        if action is None or controller.status is not RunStatus.RUNNING:
            return controller.status, steps
        events = frozenset(a for a, k in times.items() if k == t + 1)
        s = sample_successor(rng, game.successors(s, action, events))
    return RunStatus.RUNNING, steps


def simulate(
    model: Model,
    controller: ControllerLike,
    *,
    runs: int = defaults.RUNS,
    seed: int | None = 0,
    max_steps: int = defaults.MAX_STEPS,
    progress: bool | None = None,
) -> SimulationResult:
    """Estimate the probability that ``controller`` (deterministic or randomised: any
    :class:`~mitld_lp.controllers.kinds.ControllerLike`) satisfies ``model``'s task in the
    model's untruncated world (module docs).  A randomised controller draws from its own
    generator, reseeded with ``seed`` first, so a seed gives the same estimate.

    Each run is watched for ``max_steps`` steps (the result's ``horizon``).  A task with
    a safety part (``G !h``) is never decided by a finite run: a run that reaches the
    horizon in a persistent automaton state (the safety part kept, nothing left to do)
    counts as a success (``kept``); a violation after the horizon is not seen, so choose
    the horizon well beyond the steps the task needs.

    A model with sensors that miss events is run by its sensed controller: each run then
    draws the hidden event times and the sensors' reports
    (:func:`mitld_lp.sensing.observe.simulate_sensed`).

    Raises ``ValueError`` naming the argument when ``runs`` is not an integer in
    ``1..defaults.MAX_RUNS``, ``max_steps`` not an integer in
    ``0..defaults.MAX_STEPS_LIMIT``, or ``seed`` negative.
    """
    check_count("runs", runs, 1, defaults.MAX_RUNS)
    check_count("max_steps", max_steps, 0, defaults.MAX_STEPS_LIMIT)
    if seed is not None:
        check_count("seed", seed, 0, None)
    # sensors that miss events: the robot never sees them; its controller acts on the
    # reports, which these rollouts draw (mitld_lp.sensing.observe.simulate_sensed)
    sensed = any(not s.perfect for s in model.sensors.values())
    if sensed or getattr(controller, "sensed", False):
        if not (sensed and getattr(controller, "sensed", False)):
            raise ValueError("simulate: a model with sensors that miss events is run by "
                             "its sensed controller (the one its synthesis returns), and "
                             "a sensed controller by a model with those sensors")
        from mitld_lp.sensing.observe import simulate_sensed

        return simulate_sensed(model, controller,  # type: ignore[arg-type]
                               runs=runs, seed=seed, max_steps=max_steps, progress=progress)
    rng = np.random.default_rng(seed)
    if controller.randomised:
        controller.reset(seed=int(rng.integers(2**63)))
    ok = beyond = undecided = kept = 0
    # a randomised controller runs the joint automaton of the task and its constraints,
    # where the task's safety part is kept by a *keep* choice (the status is then
    # accepted); otherwise the run keeps the task in a persistent state of its automaton
    persistent = frozenset() if controller.randomised else _persistent_states(model)
    # a minimum read back from the complement's maximum: the controller runs the
    # complement's automaton (same states): the task holds where the complement rejects,
    # or in the task's persistent states
    win = RunStatus.REJECTED if _runs_complement(model, controller) else RunStatus.ACCEPTED
    bar = progress_bar(progress, total=runs, leave=False, desc="simulate", unit=" runs")
    for _ in range(runs):
        status, _ = rollout(model, controller, rng, max_steps=max_steps)
        keeping = status is RunStatus.RUNNING and controller.automaton_state in persistent
        ok += status is win or keeping
        kept += keeping
        undecided += status is RunStatus.RUNNING and not keeping
        beyond += controller.beyond_model
        bar.update()
    bar.close()
    lo, hi = wilson(ok, runs)
    return SimulationResult(runs, ok, ok / runs, lo, hi, beyond, undecided, seed,
                            max_steps, kept)


def _laws(model: Model, controller: ControllerLike) -> list[tuple[str, Any]]:
    """The law of every event of the model and of the controller: a constraint's own
    event (an inline law in the constraint) is the controller's, read from its STA."""
    laws = dict(model.distributions)
    missing = sorted(controller.events - set(laws))
    if missing:
        try:
            clocks = controller.sta.clocks  # type: ignore[attr-defined]
        except AttributeError:
            raise ValueError(
                f"the controller reads the event {missing[0]!r}, which the model has no law "
                "for; simulate it with the controller of the synthesis") from None
        laws.update((a, clocks[a].distribution) for a in missing)
    return list(laws.items())


def _runs_complement(model: Model, controller: ControllerLike) -> bool:
    """Whether ``controller`` runs the complement of ``model``'s minimised task: a
    randomised (constrained) controller does; a deterministic one does when its
    automaton's verdict in one of the task's decided states is the opposite of the
    task's (the translation is deterministic, so a fresh one numbers the states as the
    controller's; a co-safe task minimised on the plain route runs its own automaton)."""
    if model.objective != "min":
        return False
    if controller.randomised:
        return True
    from mitld_lp.automata.translate import to_dta
    from mitld_lp.logic.fragment import check

    task = to_dta(check(model.spec))
    if task.accepting is not None:
        return controller.task_verdict(task.accepting) == 0
    if task.rejecting is not None:
        return controller.task_verdict(task.rejecting) == 1
    return True  # nothing is ever decided: the verdict is read from the persistent states


def _persistent_states(model: Model) -> frozenset[int]:
    """The automaton states in which staying forever satisfies ``model``'s task (none
    for a co-safe task, whose runs end when decided).  The controller tracks the minimal
    DTA of the same spec, and the translation is deterministic, so a fresh translation
    numbers its states as the controller's (a saved controller need not carry them)."""
    from mitld_lp.automata.translate import to_dta
    from mitld_lp.logic.fragment import check

    report = check(model.spec)
    return frozenset() if report.co_safe else frozenset(to_dta(report).persistent)
