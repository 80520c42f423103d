"""The names of a PRISM world's choices where it has unlabelled commands, made when first
read.

A choice of a command without an action is named ``<module>_cmd<k>``
(:mod:`mitld_lp.worlds.prism_origins`), which only Storm's choice origins tell: its
choice labels leave such a choice unlabelled.  The origins cost a third of Storm's
plain build (QVBS consensus 6-2, 1,258,240 states: 17.3 s of CPU with them, 13.0 s with
the choice labels alone), and a solve reads no name: only a policy or a controller
shown or exported does.  So a world built whole, without event effects, whose program
has a command without an action or a module with two commands of one action (and no
action named as a command without one, ``[lift_cmd1]``), is built without them, and
without its choice labels either (up to 4% of its build with the task's terminal
states: QVBS zeroconf 1000-4 3.03 -> 2.93 s, csma 4-2 8.59 -> 8.51 s; they name no
choice a solve reads): the deadlock
self-loop (the one choice of a state Storm labels ``deadlock``) and a decided state's
are named at once; every other choice ``c`` gets the id ``LATE + c``
(:data:`mitld_lp.worlds.table.LATE`), and :class:`DeferredNames` names it when first
read, from Storm's build with its choice origins (:func:`origin_codes`), the same second
build that makes the state valuations (:mod:`mitld_lp.worlds.prism_valuations`), so a
reader of states and names pays one build more, as a reader of states alone does: a
labelled choice by its action, unless another choice of its state has its label (both
are then told apart by their commands, ``go@lift_cmd2``), an unlabelled command's by
the command.  Storm numbers states and choices alike in both builds (its breadth-first
order; neither the choice labels nor the origins change a choice), which is checked (the
states, the choices' offsets and targets, the initial state), as is every name the
first build gave (the deadlock and decided self-loops).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mitld_lp.worlds import WorldError
from mitld_lp.worlds.prism_exact import program_of
from mitld_lp.worlds.prism_origins import OriginNames, needs_origins
from mitld_lp.worlds.prism_program import builder_options
from mitld_lp.worlds.prism_tables import (
    DEADLOCK_ACTION,
    DECIDED_ACTION,
    read_export_parts,
    valuations_of,
)
from mitld_lp.worlds.prism_valuations import DeferredValuations, ValuationRecipe, quiet_build
from mitld_lp.worlds.table import LATE, LateNames

__all__ = ["DeferredNames", "command_names", "late_names", "origin_codes",
           "unlabelled_commands"]


def late_names(program: Any) -> bool:
    """Whether ``program``'s choices may be named when first read (the module
    docstring): a command without an action or a module with two commands of one
    action, and no action named as a command without one."""
    if not needs_origins(program):
        return False  # every choice is named by its label at once
    commands = unlabelled_commands(program)
    return not any(cmd.is_labeled and cmd.action_name in commands
                   for module in program.modules for cmd in module.commands)


def command_names(program: Any) -> frozenset[str]:
    """Every name a choice of ``program``'s commands may have but a told-apart one: the
    actions of its commands, ``<module>_cmd<k>`` for a command without one."""
    return unlabelled_commands(program) | frozenset(
        cmd.action_name for module in program.modules for cmd in module.commands
        if cmd.is_labeled)


def unlabelled_commands(program: Any) -> frozenset[str]:
    """The names of the program's commands without an action, ``<module>_cmd<k>``."""
    return frozenset(f"{module.name}_cmd{k}" for module in program.modules
                     for k, cmd in enumerate(module.commands, start=1)
                     if not cmd.is_labeled)


def origin_codes(make: ValuationRecipe, choices: np.ndarray, targets: np.ndarray,
                 states: DeferredValuations | None = None, shared: bool = False,
                 ) -> tuple[np.ndarray, list[str]]:
    """``(of, names)``: each choice's name as an index into ``names`` (-1: no command, a
    self-loop Storm added), from Storm's build of ``make.recipe`` with its choice
    origins and otherwise the first build's options; :class:`WorldError` when that
    build has other states or choices than the first (``choices``: its offsets of each
    state's choices, ``targets``: its branches' targets).  Given ``states`` not built
    yet, the same build makes their values (one build for both).  ``shared``: two
    choices of a state may have one name, then told apart by their commands
    (``go@lift_cmd2``), as :func:`mitld_lp.worlds.prism_tables.read_model` names them."""
    import stormpy  # the world was built by it: installed

    where = make.recipe.where
    program = program_of(stormpy, make.recipe, exact=False)
    values = states is not None and not states.built
    options = builder_options(stormpy, program, make.recipe.terminal, checks=make.checks,
                              origins=True, valuations=values)
    model = quiet_build(stormpy, program, options, where, None)
    found = (model.nr_states, model.nr_choices, int(model.initial_states[0]))
    (offsets, _, again, _), packed, archive = read_export_parts(model, where, origins=True)
    if found != (make.n_states, make.n_choices, make.initial) or not (
            np.array_equal(offsets, choices) and np.array_equal(again, targets)):
        raise WorldError(f"{where}: Storm's build with choice origins has {found[0]:,} "
                         f"states and {found[1]:,} choices, its first build "
                         f"{make.n_states:,} and {make.n_choices:,} (or other moves): the "
                         "choices cannot be named")
    named = OriginNames(program, where)
    names, of = named(model, archive)
    if shared:
        of, names = _told_apart(of, names, choices, named, model, where)
    if values:
        assert states is not None
        states.take(*valuations_of(model, packed=packed))
    return of, names


def _told_apart(of: np.ndarray, names: list[str], choices: np.ndarray, named: OriginNames,
                model: Any, where: str) -> tuple[np.ndarray, list[str]]:
    """The choices of a state that share a name renamed ``<name>@<their commands>``."""
    state_of = np.repeat(np.arange(choices.size - 1, dtype=np.int64), np.diff(choices))
    key = state_of * (len(names) + 1) + of + 1
    some = of >= 0  # a self-loop Storm added is alone in its state
    keys, counts = np.unique(key[some], return_counts=True)
    clash = np.flatnonzero(some & np.isin(key, keys[counts > 1]))
    if clash.size == 0:
        return of, names
    names, of = list(names), of.copy()
    position = {x: k for k, x in enumerate(names)}
    for c in clash.tolist():
        name = f"{names[int(of[c])]}@{named.command_text(model.choice_origins.get_command_set(c))}"
        of[c] = position.setdefault(name, len(position))
        if of[c] == len(names):
            names.append(name)
    for s in np.unique(state_of[clash]).tolist():
        row = of[choices[s]:choices[s + 1]].tolist()
        for k in sorted({x for x in row if row.count(x) > 1}):
            raise WorldError(f"{where}: two choices named {names[k]!r} at state number {s}")
    return of, names


class DeferredNames(LateNames):
    """A PRISM world's action names where its unlabelled commands' choices are named
    when first read (the module docstring): ``known`` are the names of the first build
    (indexed by the tables' ids below :data:`~mitld_lp.worlds.table.LATE`), ``make``
    builds the world again, ``commands`` are the names of the program's commands
    without an action (every name a late choice may have), ``choices``, ``targets`` and
    ``action_index`` are the first build's, to check the second against."""

    def __init__(self, known: tuple[str, ...], make: ValuationRecipe,
                 commands: frozenset[str], choices: np.ndarray, targets: np.ndarray,
                 action_index: np.ndarray, shared: bool = False) -> None:
        self.known = known
        self.shared = shared
        self.make = make
        self.commands = commands
        self.choices, self.targets, self.action_index = choices, targets, action_index
        self._of: np.ndarray | None = None
        self._names: tuple[str, ...] = ()
        self.states: DeferredValuations | None = None

    def share(self, states: Any) -> None:
        """Make the world's ``states``, if their values are made when first read too,
        in the same second build as the names (whichever is read first)."""
        if isinstance(states, DeferredValuations):
            self.states = states
            states.joint = self.resolve

    @property
    def resolved(self) -> bool:
        """Whether Storm has named the late choices yet."""
        return self._of is not None

    def names_of(self, choices: np.ndarray) -> tuple[np.ndarray, tuple[str, ...]]:
        """The names of ``choices``: those known at once as their ids, the late ones
        (Storm's second build, made on the first) after them."""
        choices = np.asarray(choices, dtype=np.int64)
        codes = self.action_index[choices].astype(np.int64)
        late = codes >= LATE
        if not late.any():
            return codes, self.known
        self.resolve()
        assert self._of is not None
        codes[late] = len(self.known) + self._of[choices[late]]
        return codes, self.known + self._names

    def resolve(self) -> None:
        """Name the late choices (Storm's second build), once."""
        if self._of is not None:
            return
        of, names = origin_codes(self.make, self.choices, self.targets, self.states,
                                 self.shared)
        where = self.make.recipe.where
        ids = self.action_index
        late = ids >= LATE
        # every name the first build gave is the origins' (a label: the commands'
        # action; the deadlock and decided self-loops: no command)
        known = np.array([self.known.index(x) if x in self.known else -2 for x in names]
                         + [-3], dtype=np.int64)  # -3: a choice without commands
        given = known[np.where(of < 0, len(names), of)]
        now = ~late & (ids >= 0)
        loops = np.array([x in (DEADLOCK_ACTION, DECIDED_ACTION) for x in self.known]
                         + [False], dtype=bool)
        first = np.where(now, ids, len(self.known))
        agree = np.where(given == -3, loops[first], given == ids)
        if not (agree[now].all() and (of[late] >= 0).all()):
            raise WorldError(f"{where}: Storm's build with choice origins names the "
                             "choices otherwise than its first build")
        self._of = np.asarray(of, dtype=np.int64)
        self._names = tuple(names)
