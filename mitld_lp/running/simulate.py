"""Monte-Carlo rollouts of a controller in the *untruncated* world of a model.

The world is the model's: event times are drawn from the events' real laws
(``model.distributions``) by inverse CDF, not through the hazards the product uses, and
the game (``model.game``) moves by its own successor distributions.  The controller
only chooses the actions; success is decided by its automaton on the trace of labels.
The estimate comes with a Wilson 95% confidence interval.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from mitld_lp import defaults
from mitld_lp.model import Model
from mitld_lp.running.controller import ControllerLike, Observation, RunStatus
from mitld_lp.util.progress import bar as progress_bar

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


@dataclass(frozen=True, slots=True)
class SimulationResult:
    runs: int
    successes: int
    estimate: float
    ci_low: float
    ci_high: float
    beyond_model: int  # runs in which an event came later than its truncation point
    undecided: int  # runs stopped at max_steps without a verdict (counted as failures)
    seed: int | None
    horizon: int = 0  # max_steps: the steps each run was watched for a violation
    kept: int = 0  # successes that were keeping a safety part, unviolated, at the horizon


def _wilson(k: int, n: int, z: float = 1.959963984540054) -> tuple[float, float]:
    """The Wilson score interval of ``k`` successes in ``n`` runs (95% by default).

    In exact arithmetic its lower end is 0 when ``k = 0`` and its upper end 1 when
    ``k = n``; the floating-point formula misses them by an ulp either way, which would
    exclude a true value of exactly 0 or 1, so the ends are set there exactly.
    """
    if n == 0:
        return 0.0, 1.0
    p = k / n
    denom = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    low = 0.0 if k == 0 else max(0.0, centre - half)
    high = 1.0 if k == n else min(1.0, centre + half)
    return low, high


def _sample_successor(rng: np.random.Generator, succ) -> Any:
    u = rng.random()
    acc = 0.0
    for s, p in succ:
        acc += p
        if u < acc:
            return s
    return succ[-1][0]


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
        s = _sample_successor(rng, game.successors(s, action, events))
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
    :class:`~mitld_lp.running.controller.ControllerLike`) satisfies ``model``'s task in the
    model's untruncated world (module docs).  A randomised controller draws from its own
    generator, reseeded with ``seed`` first, so a seed gives the same estimate.

    Each run is watched for ``max_steps`` steps (the result's ``horizon``).  A task with
    a safety part (``G !h``) is never decided by a finite run: a run that reaches the
    horizon in a persistent automaton state (the safety part kept, nothing left to do)
    counts as a success (``kept``); a violation after the horizon is not seen, so choose
    the horizon well beyond the steps the task needs.

    Raises ``ValueError`` naming the argument when ``runs`` is not an integer in
    ``1..defaults.MAX_RUNS``, ``max_steps`` not an integer in
    ``0..defaults.MAX_STEPS_LIMIT``, or ``seed`` negative.
    """
    _check_count("runs", runs, 1, defaults.MAX_RUNS)
    _check_count("max_steps", max_steps, 0, defaults.MAX_STEPS_LIMIT)
    if seed is not None:
        _check_count("seed", seed, 0, None)
    rng = np.random.default_rng(seed)
    if controller.randomised:
        controller.reset(seed=int(rng.integers(2**63)))
    ok = beyond = undecided = kept = 0
    # a randomised controller runs the joint automaton of the task and its constraints,
    # where the task's safety part is kept by a *keep* choice (the status is then
    # accepted); otherwise the run keeps the task in a persistent state of its automaton
    persistent = frozenset() if controller.randomised else _persistent_states(model)
    # objective "min": the controller runs the complement's automaton (same states): the
    # task holds where the complement rejects, or in the task's persistent states
    win = RunStatus.REJECTED if model.objective == "min" else RunStatus.ACCEPTED
    bar = progress_bar(progress, total=runs, leave=False, desc="simulate")
    for _ in range(runs):
        status, _ = rollout(model, controller, rng, max_steps=max_steps)
        keeping = status is RunStatus.RUNNING and controller.automaton_state in persistent
        ok += status is win or keeping
        kept += keeping
        undecided += status is RunStatus.RUNNING and not keeping
        beyond += controller.beyond_model
        bar.update()
    bar.close()
    lo, hi = _wilson(ok, runs)
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


def _check_count(name: str, value: object, low: int, high: int | None) -> None:
    if isinstance(value, bool) or not isinstance(value, int | np.integer):
        raise ValueError(f"{name}: must be an integer, got {value!r}")
    if value < low or (high is not None and value > high):
        bound = f"in {low}..{high:,}" if high is not None else f">= {low}"
        raise ValueError(f"{name}: must be {bound}, got {value!r}")


def _persistent_states(model: Model) -> frozenset[int]:
    """The automaton states in which staying forever satisfies ``model``'s task (none
    for a co-safe task, whose runs end when decided).  The controller tracks the minimal
    DTA of the same spec, and the translation is deterministic, so a fresh translation
    numbers its states as the controller's (a saved controller need not carry them)."""
    from mitld_lp.automata.translate import to_dta
    from mitld_lp.logic.fragment import check

    report = check(model.spec)
    return frozenset() if report.co_safe else frozenset(to_dta(report).persistent)
