"""Acting on what the robot observes when sensors miss events.

    controller.reset()
    action = controller.act(Observation(state=s0))                   # step 0
    ...                                                              # the robot moves
    action = controller.act(Observation(state=s1, reports={"b1"}))   # the camera saw b1

The controller of a model with sensors (:class:`SensedController`, in
:mod:`mitld_lp.controllers.kinds` with every other controller, and the one
:class:`Observation`) reads an observation's world state and *reports*: the sensed events
a sensor reported in the step that led there, and the events without a sensor that
happened in it (given as events or as reports: a perfect sensor reports an event the
step it happens).  It never reads a sensed event itself: it follows the information
state of :mod:`mitld_lp.sensing.belief` from the observations and its own actions.
:func:`controller_of` makes it from the synthesis's information states.

:func:`simulate_sensed` draws the hidden event times from their laws and each sensor's
reports, runs the controller on the observations only, and judges each run by the
task's automaton on the *true* events.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from mitld_lp import defaults
from mitld_lp.controllers.kinds import SensedController
from mitld_lp.controllers.observation import Observation
from mitld_lp.product import Absorbing
from mitld_lp.sensing.belief import Belief
from mitld_lp.util.progress import tracked
from mitld_lp.util.rollouts import SimulationResult, check_count, sample_successor, wilson
from mitld_lp.worlds.game import Game

__all__ = ["Observation", "SensedController", "controller_of", "simulate_sensed"]


def controller_of(game: Game[Any], belief: Belief, policy: np.ndarray) -> SensedController:
    """The controller of ``policy`` (a choice row per state) on ``belief``'s MDP."""
    mdp = belief.mdp
    initial = mdp.states[mdp.initial]
    chosen = np.asarray(policy)
    absorbing = getattr(mdp.states, "absorbing", None)  # InfoStates: no record made
    kept = (chosen >= 0) & ~(absorbing() if absorbing is not None else np.array(
        [isinstance(s, Absorbing) for s in mdp.states], bool))
    # each kept state's action name, read through one choice of each action code (a
    # name a choice was a Python call a state: 16-35 ms on issue 45's sensed case)
    picked = chosen[kept]
    codes, first, inverse = np.unique(np.asarray(mdp.choice_actions)[picked],
                                      return_index=True, return_inverse=True)
    names = np.array([mdp.action_name(int(c)) for c in picked[first]] + [None], object)
    table = np.full(len(chosen), len(codes))  # None where nothing is kept
    table[kept] = inverse.reshape(-1)
    actions = names[table].tolist()
    return SensedController(
        initial=initial if isinstance(initial, Absorbing) else mdp.initial, actions=actions,
        moves=belief.moves, sensed=belief.sensed, events=belief.sta.events, game=game,
        ignored=belief.ignored)


def simulate_sensed(model: Any, controller: SensedController, *, runs: int = defaults.RUNS,
                    seed: int | None = 0, max_steps: int = defaults.MAX_STEPS,
                    progress: bool | None = None) -> SimulationResult:
    """Estimate the probability that ``controller`` satisfies ``model``'s task (module
    docs), with a Wilson 95% interval.  Each run draws every event's time from its law,
    then each sensed event's report ``delay + j`` steps after it, ``j ~
    Geometric(detect)`` (``j = 0``: the step its report is first due), or, for a sensor
    with false alarms, a report at every step with probability ``false_alarm`` before
    step ``K + delay`` and ``detect`` from it on; the world moves
    on the true events; the task's automaton reads the true events.  ``beyond_model``
    counts the runs in which the controller met an observation the model gives
    probability 0 (an event past its truncation point);
    ``undecided`` the runs whose automaton had no verdict when the controller stopped
    (every hypothesis left was decided) or after ``max_steps``: failures, such as a bus
    missed, which the automaton never rejects (it does not know a bus comes once); a run
    that reaches ``max_steps`` in a safe automaton state (a task's safety part kept)
    counts as a success, ``kept``, as :func:`mitld_lp.simulate` counts it.
    ``progress``: a bar over the runs (:mod:`mitld_lp.util.progress`)."""
    from mitld_lp.automata.translate import to_dta

    check_count("runs", runs, 1, defaults.MAX_RUNS)
    check_count("max_steps", max_steps, 0, defaults.MAX_STEPS_LIMIT)
    if seed is not None:
        check_count("seed", seed, 0, None)
    rng = np.random.default_rng(seed)
    game, dta = model.game, to_dta(model.spec)
    hidden = controller.sensed_events
    sensors = {a: s for a, s in model.sensors.items() if a in hidden}
    alarms = sorted(a for a, s in sensors.items() if s.false_alarm > 0.0)  # every step
    laws = sorted(model.distributions.items())
    ok = beyond = undecided = kept = 0
    persistent = dta.persistent - {dta.accepting}  # safe states (a task's safety part)
    for _ in tracked(range(runs), progress, total=runs, desc="simulate", unit=" runs",
                     leave=False):
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
            # the events without a sensor are seen, the sensed ones only reported
            action = controller.act(Observation(s, reports - hidden, reports & hidden))
            if action is None:
                break
            events = frozenset(a for a, k in times.items() if k == t + 1)
            reports = frozenset(a for a, k in seen.items() if k == t + 1 and a not in alarms)
            reports |= {a for a in alarms if rng.random() < (
                sensors[a].detect if t + 1 >= times[a] + sensors[a].delay
                else sensors[a].false_alarm)}
            s = sample_successor(rng, game.successors(s, action, events))
            q = dta.step(q, frozenset(game.propositions(s)) | events)
        if verdict is None and (q == dta.accepting or q == dta.rejecting):
            verdict = q == dta.accepting
        if verdict is None and q in persistent:  # a safety part kept to the horizon
            verdict = True
            kept += 1
        ok += bool(verdict)
        undecided += verdict is None
        beyond += controller.beyond_model
    lo, hi = wilson(ok, runs)
    return SimulationResult(runs, ok, ok / runs, lo, hi, beyond, undecided, seed, max_steps,
                            kept)
