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

import json
import math
import os
from collections.abc import Hashable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mitld_lp import defaults
from mitld_lp.files import write as files
from mitld_lp.problem import ProblemError
from mitld_lp.product import Absorbing
from mitld_lp.running.controller import RunStatus
from mitld_lp.running.rollouts import SimulationResult, check_count, sample_successor, wilson
from mitld_lp.running.saved_plan import ControllerFileError, encode_state
from mitld_lp.sensing.belief import Belief, Obs
from mitld_lp.util.progress import tracked
from mitld_lp.worlds.game import Game, world_members

__all__ = ["Observation", "SensedController", "simulate_sensed", "SensedControllerError",
           "save_sensed", "FORMAT", "VERSION"]


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
    """The synthesised observation-based policy, run online (module docs): tables only
    (:meth:`from_belief` makes them from the synthesis; :func:`load_sensed` from a file),
    so a loaded controller runs without the world's class.

    ``status``: ``ACCEPTED`` (resp. ``REJECTED``) once every hypothesis the
    observations leave has satisfied (resp. violated) the task; ``finished``: nothing
    the robot does can change the outcome any more (also when the hypotheses left are
    decided differently); ``beyond_model``: an observation the model gives probability
    0 (an event later than its truncation point): the controller then plays the
    world state's first action (``fallback``)."""

    randomised = False
    sensed = True

    def __init__(self, *, initial: int | Absorbing, actions: Sequence[str | None],
                 moves: Mapping[tuple[int, str], Mapping[Obs, int | Absorbing]],
                 sensed: Sequence[str], events: Iterable[str],
                 game: Game[Any] | None = None,
                 first_actions: Mapping[Hashable, str] | None = None,
                 ignored: Iterable[str] = ()) -> None:
        self.initial, self.actions, self.moves = initial, tuple(actions), moves
        self.sensed_events = frozenset(sensed)
        self.events = frozenset(events)
        # sensed events whose reports come too late to matter (mitld_lp.sensing.horizon)
        self.ignored = frozenset(ignored)
        self.game, self.first_actions = game, dict(first_actions or {})
        self.reset()

    def fallback(self, world: Hashable) -> str:
        """The world state's first action (the world's, else the saved table's)."""
        if self.game is not None:
            return str(next(iter(self.game.actions(world))))
        action = self.first_actions.get(world)
        if action is None:
            raise ValueError(f"Observation.state: {world!r} is not a world state of the "
                             "saved controller")
        return action

    @classmethod
    def from_belief(cls, game: Game[Any], belief: Belief, policy: np.ndarray
                    ) -> SensedController:
        """The controller of ``policy`` (a choice row per state) on ``belief``'s MDP."""
        mdp = belief.mdp
        initial = mdp.states[mdp.initial]
        actions = [None if isinstance(s, Absorbing) or policy[i] < 0 else
                   mdp.action_name(int(policy[i])) for i, s in enumerate(mdp.states)]
        return cls(initial=initial if isinstance(initial, Absorbing) else mdp.initial,
                   actions=actions, moves=belief.moves, sensed=belief.sensed,
                   events=belief.sta.events, game=game, ignored=belief.ignored)

    def reset(self, seed: int | None = None) -> None:
        self.info: int | None = None
        self.last: str | None = None
        self.status = RunStatus.RUNNING
        self.finished = False
        self.beyond_model = False
        self.steps = 0

    def _choose(self, world: Hashable) -> str | None:
        if self.info is None:
            self.last = self.fallback(world)
            return self.last
        self.last = self.actions[self.info]
        if self.last is None:  # nothing can be won from here: any action will do
            self.last = self.fallback(world)
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
        first = self.steps == 0
        self.steps += 1
        if first:
            if observation.reports:
                raise ValueError(f"Observation.reports at step 0: no event happens at step "
                                 f"0, got {sorted(observation.reports)}")
            if isinstance(self.initial, Absorbing):
                self._finish(self.initial)
                return None
            self.info = self.initial
            return self._choose(observation.state)
        if self.beyond_model or self.info is None:
            return self._choose(observation.state)
        sensed, reports = self.sensed_events, observation.reports - self.ignored
        obs = (observation.state, reports - sensed, reports & sensed)
        nxt = self.moves.get((self.info, self.last or ""), {}).get(obs)
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
             max_states: int = defaults.MAX_STATES) -> Path:
        """Write the controller's tables to ``path`` (``.npz``, :func:`save_sensed`; read
        back by :func:`mitld_lp.sensing.saved.load_sensed`)."""
        return save_sensed(self, path, overwrite=overwrite, max_states=max_states)

    def tables(self, max_states: int = defaults.MAX_STATES) -> None:
        raise SensedControllerError(
            "the tables of a controller that acts on sensor reports are its own file "
            "format (save / mitld_lp.sensing.saved.load_sensed), not a SavedPlan")


# --------------------------------------------------------------------- the file

FORMAT, VERSION = "mitld-lp-sensed-controller", 2
_END = {Absorbing.TARGET: -1, Absorbing.SINK: -2, Absorbing.TRUNCATED: -3}
_NAMES = {Absorbing.TARGET: "accepted", Absorbing.SINK: "rejected",
          Absorbing.TRUNCATED: "decided"}


def _world_states(c: SensedController, max_states: int) -> list[Hashable]:
    """Every world state reachable from the initial one under any action and any of the
    events the world reacts to; a loaded controller's own table."""
    if c.game is None:
        return list(c.first_actions)
    game = c.game
    reacts = sorted(world_members(game).event_names)
    subsets = [frozenset(e for i, e in enumerate(reacts) if mask >> i & 1)
               for mask in range(1 << len(reacts))]
    seen = {game.initial: None}
    todo = [game.initial]
    while todo:
        s = todo.pop()
        for action in game.actions(s):
            for events in subsets:
                for nxt, p in game.successors(s, action, events):
                    if p > 0 and nxt not in seen:
                        if len(seen) >= max_states:
                            raise ControllerFileError(
                                f"the world has more than {max_states:,} states reachable: "
                                "raise max_states to save this controller")
                        seen[nxt] = None
                        todo.append(nxt)
    return list(seen)


def save_sensed(c: SensedController, path: str | os.PathLike[str], *,
                overwrite: bool = False, max_states: int = defaults.MAX_STATES) -> Path:
    """Write ``c``'s tables to ``path`` under the writable-path rule (the format:
    :mod:`mitld_lp.sensing.saved`)."""
    out = files.writable_path(path, overwrite=overwrite, suffixes=(".npz",))
    worlds = _world_states(c, max_states)
    index = {w: i for i, w in enumerate(worlds)}
    events = sorted(c.events)
    bit = {e: 1 << i for i, e in enumerate(events)}
    actions = sorted({a for a in c.actions if a is not None}
                     | {c.fallback(w) for w in worlds})
    number = {a: i for i, a in enumerate(actions)}
    rows = []
    for (src, act), table in c.moves.items():
        if act != c.actions[src]:  # a move the policy never makes
            continue
        for (world, seen, new), dst in table.items():
            mask = sum(bit[e] for e in seen | new)
            rows.append((src, number[act], index[world], mask,
                         _END[dst] if isinstance(dst, Absorbing) else dst))
    meta = {"format": FORMAT, "version": VERSION, "events": events,
            "sensed": sorted(c.sensed_events), "ignored": sorted(c.ignored),
            "actions": actions,
            "initial": (_NAMES[c.initial] if isinstance(c.initial, Absorbing)
                        else int(c.initial))}
    arrays = {
        "meta": np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8),
        "states": np.frombuffer(json.dumps([encode_state(w) for w in worlds]).encode(),
                                dtype=np.uint8),
        "first": np.array([number[c.fallback(w)] for w in worlds], dtype=np.int32),
        "policy": np.array([-1 if a is None else number[a] for a in c.actions],
                           dtype=np.int32),
        "moves": np.array(rows, dtype=np.int64).reshape(-1, 5),
    }
    with files.replacing(out, "wb") as handle:
        np.savez(handle, **arrays)
    return out



def simulate_sensed(model: Any, controller: SensedController, *, runs: int = defaults.RUNS,
                    seed: int | None = 0, max_steps: int = defaults.MAX_STEPS,
                    progress: bool | None = None) -> SimulationResult:
    """Estimate the probability that ``controller`` satisfies ``model``'s task (module
    docs), with a Wilson 95% interval.  Each run draws every event's time from its law,
    then each sensed event's report ``delay + j`` steps after it, ``j ~
    Geometric(detect)`` (``j = 0``: the step its report is first due); the world moves
    on the true events; the task's automaton reads the true events.  ``beyond_model``
    counts the runs in which the controller met an observation the model gives
    probability 0 (an event past its truncation point);
    ``undecided`` the runs whose automaton had no verdict when the controller stopped
    (every hypothesis left was decided) or after ``max_steps``: failures, such as a bus
    missed, which the automaton never rejects (it does not know a bus comes once).
    ``progress``: a bar over the runs (:mod:`mitld_lp.util.progress`)."""
    from mitld_lp.automata.translate import to_dta

    check_count("runs", runs, 1, defaults.MAX_RUNS)
    check_count("max_steps", max_steps, 0, defaults.MAX_STEPS_LIMIT)
    if seed is not None:
        check_count("seed", seed, 0, None)
    rng = np.random.default_rng(seed)
    game, dta = model.game, to_dta(model.spec)
    sensors = {a: s for a, s in model.sensors.items() if a in controller.sensed_events}
    laws = sorted(model.distributions.items())
    ok = beyond = undecided = 0
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
            action = controller.act(Observation(s, reports))
            if action is None:
                break
            events = frozenset(a for a, k in times.items() if k == t + 1)
            reports = frozenset(a for a, k in seen.items() if k == t + 1)
            s = sample_successor(rng, game.successors(s, action, events))
            q = dta.step(q, frozenset(game.propositions(s)) | events)
        if verdict is None and (q == dta.accepting or q == dta.rejecting):
            verdict = q == dta.accepting
        ok += bool(verdict)
        undecided += verdict is None
        beyond += controller.beyond_model
    lo, hi = wilson(ok, runs)
    return SimulationResult(runs, ok, ok / runs, lo, hi, beyond, undecided, seed, max_steps)
