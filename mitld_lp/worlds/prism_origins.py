"""Each choice of a PRISM world named from the commands it comes from (Storm's choice
origins), without changing the program.

A choice of a PRISM MDP is named by its action, ``[go]`` by ``"go"``, and a command
without an action by ``"<module>_cmd<k>"`` (:mod:`mitld_lp.worlds.prism`).  Storm's choice
labels name only the first: a choice of an unlabelled command has no label, as the
deadlock self-loop has none.  Giving each such command a fresh action of its own before
the build names it, but Storm then builds it through its synchronisation path, 8-63 %
slower than its plain build (QVBS consensus 6-2: 9.5 s against 16.3 s).  So a program
with an unlabelled command (or a module with two commands of one action, whose choices
are told apart by their commands) is built as it is, with Storm's choice origins (a
consensus build of 12.8 s): each choice's origin, an identifier of the set of commands
it joins, comes with the transitions in Storm's UMB archive (one integer a choice,
:func:`mitld_lp.worlds.prism_tables.read_model`); one command set is asked of Storm per
identifier (tens to hundreds), and :func:`origin_names` names it: the commands' action,
or the unlabelled command's ``<module>_cmd<k>``; no command is the deadlock self-loop
(or the self-loop of a state not expanded).  The names, the states, the choices and
their distributions are those of the fresh-action build; Storm's own order of them is
its plain build's (an unlabelled command's choices first), the order of Storm's build
of the file (tests/test_worlds_prism_origins.py).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

import numpy as np

from mitld_lp.worlds import WorldError

__all__ = ["OriginNames", "may_share_names", "needs_origins", "origin_names"]

log = logging.getLogger("mitld_lp.worlds.prism")


def may_share_names(program: Any) -> bool:
    """Whether two choices of one state may have one name: a module with two commands
    of one action (a choice of an action joins one enabled command of it from each
    module that has it), or an action named as a command without one is
    (``[a_cmd1]`` beside module ``a``'s first command ``[]``).  Otherwise the check for
    such choices (a sort of every choice by state and name) is left out."""
    names = set()
    for module in program.modules:
        actions = [c.action_name for c in module.commands if c.is_labeled]
        if len(actions) != len(set(actions)):
            return True
        names.update(actions)
    return any(not cmd.is_labeled and f"{module.name}_cmd{k}" in names
               for module in program.modules
               for k, cmd in enumerate(module.commands, start=1))


def needs_origins(program: Any) -> bool:
    """Whether the choices of ``program`` are named from Storm's choice origins: a
    command without an action (Storm's choice labels leave its choices unnamed), or a
    module with two commands of one action (two choices of one state may then carry
    one action's name, told apart by their commands; a choice of an action joins one
    enabled command of it from each module that has it)."""
    for module in program.modules:
        actions = [c.action_name for c in module.commands if c.is_labeled]
        if len(actions) != len(module.commands) or len(actions) != len(set(actions)):
            return True
    return False


class OriginNames:
    """The naming of a program's choices from their origins: called with a model Storm
    built from ``program`` with its choice origins and the archive's origin of each
    choice (``(index, strings)``: :func:`mitld_lp.worlds.prism_tables.read_model`; None
    where the archive has none), it gives :func:`origin_names`'s answer."""

    def __init__(self, program: Any, where: str) -> None:
        self.where = where
        # global command index -> (its action or None, <module>_cmd<k>)
        self.commands = {
            cmd.global_index: (cmd.action_name if cmd.is_labeled else None,
                               f"{module.name}_cmd{k}")
            for module in program.modules
            for k, cmd in enumerate(module.commands, start=1)
        }

    def command_text(self, commands: Any) -> str:
        """The commands of a set, ``robot_cmd2+door_cmd1`` (in their global order)."""
        return "+".join(self.commands[c][1] for c in sorted(commands))

    def name(self, commands: Any) -> str | None:
        """The name of a choice joining ``commands`` (global indices): their action, or
        the one unlabelled command's ``<module>_cmd<k>``; None for none (a self-loop
        Storm added)."""
        found = [self.commands[c] for c in commands]
        if not found:
            return None
        actions = {a for a, _ in found}
        if len(actions) == 1 and None not in actions:
            return found[0][0]
        if len(found) == 1:
            return found[0][1]
        raise WorldError(f"{self.where}: Storm's choice origins join the commands "
                         f"{self.command_text(commands)}: not one action")

    def __call__(self, model: Any, archive: tuple[np.ndarray, list[str]] | None,
                 ) -> tuple[list[str], np.ndarray]:
        return origin_names(model, archive, self.name, self.where)


def origin_names(model: Any, archive: tuple[np.ndarray, list[str]] | None,
                 name: Callable[[Any], str | None], where: str,
                 ) -> tuple[list[str], np.ndarray]:
    """``(names, of)``: the distinct names of the choices of ``model`` (sorted) and each
    choice's as an index into them, -1 for a choice without commands; ``name(commands)``
    names a set of commands.  The origin of each choice comes from ``archive`` (Storm's
    UMB archive writes the identifier of each choice's origin and the text of every
    identifier, :meth:`ChoiceOrigins.get_identifier_info`, in identifier order; taken
    only when it has one text for each of Storm's identifiers, matching theirs), one
    command set asked of Storm per identifier; without it, a call per choice."""
    origins = model.choice_origins
    m = model.nr_choices
    if archive is not None and _is_identifiers(archive, origins):
        index = archive[0].astype(np.int64)
        k = len(archive[1])
        ids = np.flatnonzero(np.bincount(index, minlength=k))
        some = np.zeros(k, dtype=np.int64)
        some[index] = np.arange(m, dtype=np.int64)  # a choice of each identifier (no sort)
        asked = [name(origins.get_command_set(c)) for c in some[ids].tolist()]
    else:  # another archive: Storm asked choice by choice
        log.info("%s: Storm's archive does not hold the choices' origins as read here; "
                 "asked choice by choice", where)
        sets: dict[frozenset[int], int] = {}
        index = np.fromiter((sets.setdefault(frozenset(origins.get_command_set(c)), len(sets))
                             for c in range(m)), dtype=np.int64, count=m)
        ids = np.arange(len(sets), dtype=np.int64)
        asked = [name(s) for s in sets]
    names = sorted({x for x in asked if x is not None})
    position = {x: k for k, x in enumerate(names)}
    of_id = np.full(int(ids.max()) + 1 if ids.size else 1, -1, dtype=np.int64)
    of_id[ids] = [-1 if x is None else position[x] for x in asked]
    return names, of_id[index]


def _is_identifiers(archive: tuple[np.ndarray, list[str]], origins: Any) -> bool:
    """Whether the archive's choice actions are the identifiers of Storm's choice
    origins: one text per identifier, the first (no origin) empty and every other
    Storm's own text of it."""
    _, strings = archive
    if len(strings) != origins.get_number_of_identifiers() or not strings or strings[0]:
        return False
    return all(strings[i] == origins.get_identifier_info(i) for i in range(1, len(strings)))
