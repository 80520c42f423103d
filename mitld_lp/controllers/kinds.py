"""The controllers a synthesis returns, run online: the robot reports what it sees, the
controller answers with an action, tracking its memory itself.

    controller.reset()
    action = controller.act(Observation(state=s0))          # step 0: no events yet
    ...                                                     # the robot moves; events happen
    action = controller.act(Observation(state=s1, events={"b1"}))

``act`` returns ``None`` once the task is decided (``status`` says how).  Every kind is
one class over one step rule (:class:`~mitld_lp.controllers.stepper.Stepper`); they
differ only in their plan, which is where their decisions differ:

* :class:`Controller`: a deterministic policy on the product (``synthesize``);
* :class:`ConstrainedController`: a randomised one, drawn from a seeded generator
  (``synthesize_constrained``);
* :class:`SensedController`: a policy on what the robot knows when sensors miss events
  (:mod:`mitld_lp.sensing`), which reads the observations' reports;
* the decision tree's controller (:mod:`mitld_lp.running.tree`).

A controller is saved as a file of plain tables (:meth:`PlanController.save`, format
in :mod:`mitld_lp.controllers.format`) that :meth:`PlanController.load` and
:func:`load_controller` parse without running anything from it, in a process that
needs neither the world's class nor a solver.
"""

from __future__ import annotations

import os
from collections.abc import Hashable, Iterable, Mapping, Sequence
from collections.abc import Set as AbstractSet
from pathlib import Path
from typing import Any, ClassVar, Protocol

import numpy as np

from mitld_lp import defaults
from mitld_lp.automata.joint import Joint
from mitld_lp.automata.sta import STA
from mitld_lp.controllers.format import ControllerFileError
from mitld_lp.controllers.live import LivePlan, LiveRandomPlan, tabulate_sensed
from mitld_lp.controllers.observation import Observation, RunStatus
from mitld_lp.controllers.stepper import Plan, Stepper
from mitld_lp.controllers.tables import MixedSensedPlan, Obs, SavedPlan, SensedPlan
from mitld_lp.files import write as files
from mitld_lp.mdp import MDP
from mitld_lp.worlds.game import Game

__all__ = ["ConstrainedController", "Controller", "ControllerLike", "MixedSensedController",
           "PlanController", "SensedController", "load_controller", "save_tables"]

_LOADERS = {"deterministic": "mitld_lp.Controller.load",
            "randomised": "mitld_lp.ConstrainedController.load",
            "sensed": "mitld_lp.SensedController.load",
            "sensed-randomised": "mitld_lp.load_controller"}


class ControllerLike(Protocol):
    """What every controller offers (:class:`Controller`, deterministic,
    :class:`ConstrainedController`, randomised, and :class:`SensedController`), and what
    :func:`simulate <mitld_lp.running.simulate.simulate>`, ``mitld-lp simulate``, the
    exports and the runtime take: ``act`` on an observation (None once the task is
    decided), ``reset`` to start a new run, the memory (``automaton_state``, ``pending``,
    ``clock`` for a controller that follows the task's automaton), the task's
    ``status``, ``plan`` (what it acts by) and ``save``.  A randomised controller draws
    from ``rng``, a seeded ``numpy.random.Generator`` (``reset(seed=...)`` reseeds it); a
    deterministic one never draws."""

    @property
    def randomised(self) -> bool: ...
    @property
    def plan(self) -> Plan: ...
    @property
    def events(self) -> frozenset[str]: ...
    @property
    def status(self) -> RunStatus: ...
    @property
    def automaton_state(self) -> int | None: ...
    @property
    def pending(self) -> frozenset[str]: ...
    @property
    def clock(self) -> int: ...
    @property
    def beyond_model(self) -> bool: ...
    @property
    def settled(self) -> bool: ...
    @property
    def steps(self) -> int: ...

    def reset(self, seed: int | None = None) -> None: ...
    def act(self, observation: Observation) -> str | None: ...
    def task_verdict(self, state: int) -> int: ...
    def tables(self, max_states: int = defaults.MAX_STATES) -> SavedPlan | SensedPlan: ...
    def save(self, path: str | os.PathLike[str], *, overwrite: bool = False,
             max_states: int = defaults.MAX_STATES) -> Path: ...


def _observed(observation: Any) -> tuple[Hashable, frozenset[str], frozenset[str]]:
    """The state, events and reports of an :class:`Observation`; a ``TypeError`` naming
    the class for anything else."""
    if isinstance(observation, Observation):
        return observation.state, observation.events, observation.reports
    events = getattr(observation, "events", None)  # a record with the same fields
    reports = getattr(observation, "reports", frozenset())
    if not (isinstance(events, AbstractSet) and isinstance(reports, AbstractSet)
            and hasattr(observation, "state")):
        raise TypeError(f"act: expected a mitld_lp.Observation(state, events, reports), got "
                        f"{type(observation).__module__}.{type(observation).__qualname__}")
    return observation.state, frozenset(events), frozenset(reports)


class PlanController(Stepper):
    """A controller over a plan (module docs): ``act``, ``reset``, ``status``, ``save``
    and ``load``, the same for every kind.  ``kind`` is the kind of file its ``load``
    reads."""

    kind: ClassVar[str]

    def __repr__(self) -> str:
        return f"{type(self).__name__}(status={self.status.value}, steps={self.steps})"

    @property
    def status(self) -> RunStatus:
        return RunStatus(self.status_name)

    def reset(self, seed: int | None = None) -> None:
        """Start a new run (the next ``act`` is step 0); with ``seed`` a new generator,
        else the generator runs on (a deterministic controller never draws)."""
        if seed is not None:
            self.rng = np.random.default_rng(seed)
        self._restart()

    def act(self, observation: Observation) -> str | None:
        """The action to take in ``observation.state`` after what the observation says
        happened; ``None`` once the task is decided."""
        return self._step(*_observed(observation))

    def tables(self, max_states: int = defaults.MAX_STATES) -> SavedPlan | SensedPlan:
        """The controller as plain tables (what :meth:`save` writes)."""
        plan: Any = self._plan
        return plan if isinstance(plan, SavedPlan) else plan.tables(max_states)

    def save(self, path: str | os.PathLike[str], *, overwrite: bool = False,
             max_states: int = defaults.MAX_STATES) -> Path:
        """Write the controller to ``path`` (by convention ``*.npz``) as plain tables
        (:mod:`mitld_lp.controllers.format`): what it remembers and decides, and every
        world state it may observe.  :meth:`load` reads it back in any process, without
        the world's class.  The file holds data only, never pickled objects.  The path
        follows the package's one rule for output files (:mod:`mitld_lp.files.write`):
        checked before any work, written to a temporary file renamed into place.

        Raises ``FileExistsError`` if ``path`` exists and not ``overwrite``;
        ``ValueError`` (before writing) if a world state is not made of None, booleans,
        numbers, strings and tuples, or if the world states to tabulate exceed
        ``max_states``.
        """
        return save_tables(self, path, overwrite=overwrite, max_states=max_states)

    @classmethod
    def load(cls, path: str | os.PathLike[str], *, seed: int | None = 0) -> Any:
        """The controller saved at ``path``, reset to step 0 (a randomised one draws from
        a generator seeded with ``seed``).

        The file is parsed as data (NumPy arrays with ``allow_pickle=False`` and JSON);
        nothing in it is executed.  A file that is not a controller of this class's kind
        of a format version this package reads (foreign, damaged, truncated, another
        version, unreadable, another kind) raises :class:`ControllerFileError` (a
        ``ValueError``) naming the file and the fault; :func:`load_controller` loads
        every kind.
        """
        from mitld_lp.controllers.reader import read  # a solve never reads one

        plan = read(Path(path))
        if plan.kind != cls.kind:
            raise ControllerFileError(
                f"{path}: cannot load the controller: a {plan.kind} controller; load it "
                f"with {_LOADERS[plan.kind]} or mitld_lp.load_controller")
        return _made(cls, plan, seed)


def _made(cls: type[PlanController], plan: Any, seed: int | None) -> Any:
    controller = cls.__new__(cls)
    controller._begin(plan, seed=seed)
    return controller


class Controller(PlanController):
    """A deterministic stationary policy on product states, run on the original game.

    ``Controller(game, sta, mdp, policy, hopeless=None)``: ``policy`` gives a choice of
    ``mdp`` per state (-1: none, any action will do); the optional ``hopeless`` mask
    marks states from which no policy can satisfy the task even if every truncated event
    came in time (``prob0_max`` of the upper model): the controller reports
    ``REJECTED`` there instead of acting on forever.

    Beyond a truncation point (an event later than the model looked) it keeps acting
    with the clock held at the last modelled value and sets ``beyond_model``.
    """

    kind = "deterministic"

    def __init__(self, game: Game[Any], sta: STA, mdp: MDP, policy: np.ndarray,
                 hopeless: np.ndarray | None = None) -> None:
        self._begin(LivePlan(game, sta, mdp, policy, hopeless), seed=0)  # never draws


class ConstrainedController(PlanController):
    """Run a randomised constrained policy: track the joint automaton, the pending events
    and the clock; in each state sample the action from the policy's distribution with
    a seeded ``numpy`` generator (or, once it has drawn *stay*, keep to the end
    component for ever with its internal actions, drawn uniformly).  ``act`` returns
    None once every component (task and constraints) is decided; :attr:`settled` also
    says when the run stays in an end component for ever (nothing is decided any more).

    ``status``: the task's (a run that stays for ever with the task undecided counts as
    rejected); ``verdicts``: per component, accepted 1 / rejected 0 / undecided -1;
    ``charged``: the steps taken while the task was undecided (what E(steps) counts).
    """

    kind = "randomised"

    def __init__(self, game: Any, sta: STA, joint: Joint, merged: Any, mdp: MDP,
                 prob: np.ndarray, stay: np.ndarray, *, seed: int | None = 0) -> None:
        self._begin(LiveRandomPlan(game, sta, joint, merged, mdp, prob, stay),
                    np.random.default_rng(seed))

    @property
    def game(self) -> Any:
        """The world (a controller made by a synthesis; a loaded one has only tables)."""
        return self._live().game

    @property
    def sta(self) -> STA:
        """The stochastic timed automaton of the joint automaton (as :attr:`game`)."""
        return self._live().sta

    def _live(self) -> LiveRandomPlan:
        if not isinstance(self._plan, LiveRandomPlan):
            raise AttributeError("a loaded controller has its tables only, not the model")
        return self._plan

    @property
    def task_status(self) -> str:
        return self.status_name


class SensedController(PlanController):
    """The synthesised observation-based policy, run online: it follows the information
    state (:mod:`mitld_lp.sensing.belief`) from the observations' reports and its own
    actions, never reading a sensed event itself.

    ``SensedController(initial=..., actions=..., moves=..., sensed=..., events=...,
    game=None, first_actions=None, ignored=())``: the plan's tables
    (:class:`~mitld_lp.controllers.tables.SensedPlan`; the synthesis makes them from
    its information states, :func:`load_controller` from a file).

    ``status``: ``ACCEPTED`` (resp. ``REJECTED``) once every hypothesis the
    observations leave has satisfied (resp. violated) the task; it acts no more also
    when the hypotheses left are decided differently (``settled``, the status stays
    ``RUNNING``); ``beyond_model``: an observation the model gives probability 0 (an
    event later than its truncation point): the controller then plays the world
    state's first action."""

    kind = "sensed"
    sensed = True

    def __init__(self, *, initial: int | str, actions: Sequence[str | None],
                 moves: Mapping[tuple[int, str], Mapping[Obs, int | str]],
                 sensed: Iterable[str], events: Iterable[str], game: Any = None,
                 first_actions: Mapping[Hashable, str] | None = None,
                 ignored: Iterable[str] = ()) -> None:
        plan = SensedPlan(initial=initial, actions=tuple(actions), moves=moves,
                          sensed=frozenset(sensed), events=frozenset(events),
                          ignored=frozenset(ignored), game=game,
                          first=dict(first_actions or {}))
        self._begin(plan, seed=0)

    def _sensed_plan(self) -> SensedPlan:
        assert isinstance(self._plan, SensedPlan)
        return self._plan

    @property
    def game(self) -> Any:
        """The world (a controller made by a synthesis; None for a loaded one)."""
        return self._sensed_plan().game

    @property
    def sensed_events(self) -> frozenset[str]:
        """The events the robot learns of through its sensors only."""
        return self._sensed_plan().sensed

    @property
    def ignored(self) -> frozenset[str]:
        """The sensed events whose reports come too late to matter (dropped)."""
        return self._sensed_plan().ignored

    def tables(self, max_states: int = defaults.MAX_STATES) -> SensedPlan:
        return tabulate_sensed(self._sensed_plan(), max_states)


class MixedSensedController(SensedController):
    """A randomised policy over information states (the ``sensed-constrained`` route,
    :mod:`mitld_lp.sensing.mixed`), drawing from a generator seeded with ``seed``: in
    each information state *stay* with its probability, else an action by its weights
    (:class:`~mitld_lp.controllers.tables.MixedSensedPlan`)."""

    kind = "sensed-randomised"

    def __init__(self, plan: MixedSensedPlan, *, seed: int | None = 0) -> None:
        self._begin(plan, np.random.default_rng(seed))


_CLASSES: dict[str, type[PlanController]] = {
    c.kind: c for c in (Controller, ConstrainedController, SensedController,
                        MixedSensedController)}


def load_controller(path: str | os.PathLike[str], *, seed: int | None = 0) -> Any:
    """The controller saved at ``path``, of whichever kind the file holds: a
    :class:`Controller`, a :class:`ConstrainedController` (drawing from a generator
    seeded with ``seed``) or a :class:`SensedController`; :class:`ControllerFileError`
    as :meth:`PlanController.load`."""
    from mitld_lp.controllers.reader import read

    plan = read(Path(path))
    return _made(_CLASSES[plan.kind], plan, seed)


def save_tables(controller: ControllerLike, path: str | os.PathLike[str], *,
                overwrite: bool, max_states: int) -> Path:
    """Write ``controller.tables()`` to ``path`` under the package's rule for outputs."""
    out = files.writable_path(path, overwrite=overwrite)
    data = controller.tables(max_states).to_bytes()
    with files.replacing(out, "wb") as handle:
        handle.write(data)
    return out
