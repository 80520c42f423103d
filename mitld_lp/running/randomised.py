"""The randomised controller of a constrained synthesis (:mod:`mitld_lp.routes.constrained`),
behind the same interface as the deterministic :class:`mitld_lp.Controller`
(:class:`mitld_lp.running.controller.ControllerLike`): ``act`` on an
:class:`~mitld_lp.Observation`, ``reset``, ``save`` / ``load`` (the same file format,
kind ``"randomised"``), run by :func:`mitld_lp.running.simulate.simulate` and the exports.

:func:`load_controller` loads a saved controller of either kind.
"""

from __future__ import annotations

import os
from collections.abc import Hashable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mitld_lp import defaults
from mitld_lp.automata.joint import Joint
from mitld_lp.automata.sta import STA
from mitld_lp.mdp import MDP
from mitld_lp.product import ProductState, ProductStates
from mitld_lp.running.controller import Controller, Observation, RunStatus, _events, save_tables
from mitld_lp.running.controller_file import (
    ControllerFileError,
    SavedPlan,
    read_plan,
    tabulate_randomised,
)
from mitld_lp.running.saved_plan import SensedControllerFile
from mitld_lp.runtime import KEEP, Decision, Stepper

__all__ = ["ConstrainedController", "load_controller"]


@dataclass(frozen=True, slots=True, eq=False)
class _LiveRandomPlan:
    """The constrained synthesis's model: the world, the STA of the joint automaton,
    the product, the merged model and the randomised policy on it."""

    game: Any
    sta: STA
    joint: Joint
    merged: Any  # mitld_lp.solvers.constrained_model.Merged
    mdp: MDP
    prob: np.ndarray
    stay: np.ndarray

    @property
    def events(self) -> frozenset[str]:
        return self.sta.events

    @property
    def initial(self) -> int:
        return self.joint.dta.initial

    @property
    def verdicts(self) -> tuple[tuple[int, ...], ...]:
        return tuple(tuple(v) for v in self.joint.verdicts)

    def read(self, q: int, state: Hashable, events: frozenset[str]) -> int:
        return self.joint.dta.step(q, self.game.propositions(state) | events)

    def advance(self, pending: frozenset[str], clock: int) -> tuple[int, bool]:
        step = self.sta.advance(pending, clock)
        return step.clock, step.truncated

    def decide(self, state: Hashable, q: int, pending: frozenset[str], clock: int) -> Decision:
        states = self.mdp.states
        record = ProductState(state, q, pending, clock)
        i = states.position(record) if isinstance(states, ProductStates) else None
        m = self.merged
        s = -1 if i is None else int(m.of_product[i])
        if s < 0 or m.absorbing[s]:
            return Decision((), np.zeros(0))
        lo, hi = int(m.mdp.row_groups[s]), int(m.mdp.row_groups[s + 1])
        names = tuple(KEEP if m.keep[c] else m.mdp.action_name(c) for c in range(lo, hi))
        inside = tuple(n for n, flag in zip(names, m.internal[lo:hi], strict=True) if flag)
        kept = tuple(n for n, flag in zip(names, m.keep_internal[lo:hi], strict=True) if flag)
        keep = tuple(bool(k) for k in m.keep[lo:hi])
        return Decision(names, np.asarray(self.prob[lo:hi]), float(self.stay[s]), inside,
                        charged=bool(m.undecided[s]), keep=keep if any(keep) else (),
                        kept=kept)

    def fallback(self, state: Hashable) -> str:
        return self.game.actions(state)[0]

    def tables(self, max_states: int) -> SavedPlan:
        m = self.merged
        return tabulate_randomised(
            self.game, self.sta, self.joint.verdicts, self.mdp, m.of_product, m.mdp,
            self.prob, self.stay, m.internal, m.undecided, m.absorbing,
            keep=m.keep, kept=m.keep_internal, max_states=max_states)


class ConstrainedController(Stepper):
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

    randomised = True

    def __init__(self, game: Any, sta: STA, joint: Joint, merged: Any, mdp: MDP,
                 prob: np.ndarray, stay: np.ndarray, *, seed: int | None = 0) -> None:
        self._begin(_LiveRandomPlan(game, sta, joint, merged, mdp, prob, stay),
                    np.random.default_rng(seed))

    def __repr__(self) -> str:
        return f"ConstrainedController(status={self.status.value}, steps={self.steps})"

    @property
    def status(self) -> RunStatus:
        return RunStatus(self.status_name)

    @property
    def game(self) -> Any:
        """The world (a controller made by a synthesis; a loaded one has only tables)."""
        return self._live().game

    @property
    def sta(self) -> STA:
        """The stochastic timed automaton of the joint automaton (as :attr:`game`)."""
        return self._live().sta

    def _live(self) -> _LiveRandomPlan:
        if not isinstance(self._plan, _LiveRandomPlan):
            raise AttributeError("a loaded controller has its tables only, not the model")
        return self._plan

    @property
    def task_status(self) -> str:
        return self.status_name

    def reset(self, seed: int | None = None) -> None:
        """Start a new run; with ``seed`` a new generator, else the generator runs on."""
        if seed is not None:
            self.rng = np.random.default_rng(seed)
        self._restart()

    def act(self, observation: Observation) -> str | None:
        """The action in ``observation.state`` after its events; None once nothing is
        left to decide."""
        return self._step(observation.state, _events(observation))

    def tables(self, max_states: int = defaults.MAX_STATES) -> SavedPlan:
        """The controller as plain tables (what :meth:`save` writes)."""
        plan = self._plan
        return plan if isinstance(plan, SavedPlan) else plan.tables(max_states)  # type: ignore[attr-defined]

    def save(self, path: str | os.PathLike[str], *, overwrite: bool = False,
             max_states: int = defaults.MAX_STATES) -> Path:
        """Write the controller to ``path`` as plain tables (kind ``"randomised"`` of
        the format in :mod:`mitld_lp.running.controller_file`); as :meth:`Controller.save`."""
        return save_tables(self, path, overwrite=overwrite, max_states=max_states)

    @classmethod
    def load(cls, path: str | os.PathLike[str], *, seed: int | None = 0) -> ConstrainedController:
        """The randomised controller saved at ``path``, at step 0, drawing from a
        generator seeded with ``seed``; :class:`ControllerFileError` as
        :meth:`Controller.load` (also for a deterministic controller's file)."""
        plan = read_plan(Path(path))
        if not plan.randomised:
            raise ControllerFileError(
                f"{path}: cannot load the controller: a deterministic controller; load it "
                "with mitld_lp.Controller.load or mitld_lp.load_controller")
        controller = cls.__new__(cls)
        controller._begin(plan, np.random.default_rng(seed))
        return controller


def load_controller(path: str | os.PathLike[str], *,
                    seed: int | None = 0) -> Controller | ConstrainedController:
    """The controller saved at ``path``, of whichever kind the file holds: deterministic,
    randomised (drawing from a generator seeded with ``seed``) or acting on sensor
    reports (:class:`~mitld_lp.sensing.observe.SensedController`)."""
    try:
        plan = read_plan(Path(path))
    except SensedControllerFile:
        from mitld_lp.sensing.saved import load_sensed

        return load_sensed(path)  # type: ignore[return-value]
    controller: Controller | ConstrainedController
    controller = (ConstrainedController if plan.randomised else Controller).__new__(
        ConstrainedController if plan.randomised else Controller)
    controller._begin(plan, np.random.default_rng(seed))
    return controller
