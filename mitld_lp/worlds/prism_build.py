"""Storm's build of a PRISM program into :class:`~mitld_lp.worlds.prism_tables.Tables`,
within the world's budgets, whole or the first states of its breadth-first exploration.

:func:`build_tables` runs Storm's explicit builder (its exploration checks on; where only
a sum within PRISM's tolerance fails them, without them, the sums checked on the copy)
and copies the model; given ``limit`` it stops expanding once Storm has found that many
states (Storm's ``exploration_state_limit``): the states found but not expanded carry
Storm's label ``"unexplored"`` (:attr:`Tables.unexplored`), and every expanded state has
the number, the choices and the rows it has in the whole build, because Storm numbers
states in the order its breadth-first search finds them
(:class:`mitld_lp.worlds.prism.LazyPrismGame` builds on that; :class:`Grower` explores
further, within the budgets).  :func:`build_within` runs a build in a memory-capped
child process when it may not fit (:mod:`mitld_lp.worlds.prism_bounded`).
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Callable
from typing import Any

import numpy as np
import scipy.sparse as sp

from mitld_lp.util.memory import ProductTooLarge, byte_text, default_max_memory
from mitld_lp.worlds import WorldError
from mitld_lp.worlds.prism_bounded import OutOfBudget, can_cap, run_capped
from mitld_lp.worlds.prism_exact import PrismRecipe
from mitld_lp.worlds.prism_names import DeferredNames, command_names
from mitld_lp.worlds.prism_names import late_names as is_late
from mitld_lp.worlds.prism_origins import OriginNames, may_share_names, needs_origins
from mitld_lp.worlds.prism_program import (
    SUM_TOLERANCE,
    builder_options,
    check_program,
    show_sum,
    storm_build,
    storm_error,
    storm_quiet,
    storm_sum,
)
from mitld_lp.worlds.prism_tables import DEADLOCK_ACTION, OUT_OF_BOUNDS, Tables, read_model
from mitld_lp.worlds.prism_valuations import (
    DeferredValuations,
    ValuationRecipe,
    head,
    program_head,
    rebuild,
)
from mitld_lp.worlds.table import LATE

__all__ = ["PrismTooLarge", "BYTES_PER_STATE", "CAP_BYTES_PER_STATE", "UNEXPLORED",
           "check_budgets", "build_within", "build_tables", "expanded_within", "Grower"]

log = logging.getLogger("mitld_lp.worlds.prism")

UNEXPLORED = "unexplored"
"""Storm's label of the states it found but did not expand (a build with a state limit)."""

BYTES_PER_STATE = 1024
"""Memory per state of a PRISM world while it is built, for the bound from the variables'
ranges (a program whose range product fits ``max_states`` and, at this much a state,
``max_memory``, is built in this process): Storm's explicit model with valuations,
labels and choice origins (measured about 550 bytes per state with 4 choices and 7
transitions per state, stormpy 2.0) and the game's copy (arrays, one tuple and one index
entry per state), rounded up."""

CAP_BYTES_PER_STATE = 16 << 10
"""The memory allowed per state of ``max_states`` when Storm explores under a cap: 16 KiB,
enough for about 100 transitions a state (ij.20 of QVBS, 17.5 transitions a state, takes
2.6 KB), so that the cap stops a program far larger than ``max_states`` early and does
not stop a dense one within it; ``max_memory`` caps it as well."""


class PrismTooLarge(WorldError, ProductTooLarge):
    """Storm's exploration of the PRISM program passed ``max_states`` states or the
    memory budget (it was stopped there, in a capped child process): a budget stop
    (exit 3 on the command line), whose message names the budget and how to raise it."""



def check_budgets(max_states: int, max_memory: int | None) -> int:
    """The memory budget in bytes (``max_memory``, or the default); ``ValueError`` for a
    budget that is not a positive integer."""
    for name, value in (("max_states", max_states), ("max_memory", max_memory)):
        if value is not None and (isinstance(value, bool) or not isinstance(value, int)
                                  or value < 1):
            raise ValueError(f"{name} must be a positive integer, got {value!r}")
    return default_max_memory() if max_memory is None else max_memory


def build_within(work: Callable[[], Tables], where: str, fits: bool, note: str,
                 max_states: int, memory: int) -> Tables:
    """``work()`` (Storm's build of a world, copied into tables) here when ``fits`` (every
    valuation fits the budgets), else in a child process capped at the memory budget
    (:mod:`mitld_lp.worlds.prism_bounded`): :class:`PrismTooLarge` when it passes it.
    ``note`` says what bounds the states, for the message."""
    if fits:
        return work()  # every valuation fits: no cap needed
    budget = min(memory, max_states * CAP_BYTES_PER_STATE)
    if not can_cap():
        log.info("%s: %s; no memory cap on this platform", where, note)
        return work()
    try:
        return run_capped(work, budget)
    except OutOfBudget as exc:
        raise PrismTooLarge(
            f"{where}: Storm's exploration passed the budget of {byte_text(budget)} "
            f"({exc.detail}; max_states = {max_states:,} at {byte_text(CAP_BYTES_PER_STATE)} a "
            f"state, max_memory = {byte_text(memory)}; {note}): raise max_states "
            "(--max-world-states) or max_memory (--max-memory)"
        ) from None


class Grower:
    """A lazily explored world's next exploration: ``grower(limit)``, Storm's build of
    the states it expands before it has found ``limit`` (``work(limit)``), within the
    budgets (:func:`build_within`; ``note`` says what bounds the states)."""

    def __init__(self, work: Callable[[int], Tables], where: str, memory: int, note: str,
                 max_states: int) -> None:
        self.work, self.where, self.memory = work, where, memory
        self.note, self.max_states = note, max_states

    def __reduce__(self) -> Any:
        raise TypeError(f"{self.where}: a world explored as the task reaches it does not "
                        "pickle (Storm explores it on demand): load it with explore='full'")

    def __call__(self, limit: int) -> Tables:
        fits = limit * BYTES_PER_STATE <= self.memory
        return build_within(lambda: self.work(limit), self.where, fits, self.note,
                            self.max_states, self.memory)

    def within(self, first: int, steps: int | None, growth: int) -> tuple[Tables, int]:
        """The first exploration, of ``first`` states (all of them when the world is that
        small), grown ``growth`` times at a time until every state within ``steps`` moves
        is expanded (a task of that horizon; None: the first alone) or ``max_states``
        are found; the tables and the limit they were explored with."""
        tables = self(first)
        while (steps is not None and not expanded_within(tables, steps)
               and first < self.max_states):
            first = min(first * growth, self.max_states)
            tables = self(first)
        return tables, first


def build_tables(stormpy: Any, program: Any, plain: Any, where: str, chosen: frozenset[str],
                 events: frozenset[str], terminal: str,
                 max_states: int, limit: int | None = None,
                 recipe: PrismRecipe | None = None, late_names: bool = True,
                 own: bool = True) -> Tables:
    """Storm's build of ``program``, copied into :class:`Tables`; with ``limit``, only
    the states Storm expands before it has found ``limit`` states (the module docstring).
    Given the ``recipe`` to build it again, a whole build without event effects leaves
    out the state valuations, which Storm makes when a state other than the initial
    one is first named (:mod:`mitld_lp.worlds.prism_valuations`).

    Storm's exploration checks refuse updates out of a variable's range (without them
    it stores values modulo the range) and probabilities that do not sum to 1, compared
    *exactly* in floating point: ``0.8 + 0.1 + 0.1`` fails.  When only a sum fails, and
    by no more than PRISM's :data:`~mitld_lp.worlds.prism_program.SUM_TOLERANCE`, the
    model is built again without the checks, with Storm's out-of-bounds state:
    :func:`~mitld_lp.worlds.prism_tables.read_model` then checks (and normalises) every
    sum, with the tolerance, and refuses an update that reached that state.  Storm's
    checked build in exact arithmetic (``1/10`` is exact there; three times the float
    build: zeroconf 20-4, 6.4 s against 2.1 s) runs only when that refuses the world, so
    that the refusal names the module and command where Storm's checks find them
    (:func:`_exact_refusal`).

    The choices are named by Storm's choice labels, or, where a command has no action
    or a module two commands of one action, by the commands they come from (Storm's
    choice origins: :mod:`mitld_lp.worlds.prism_origins`); where the valuations are
    left out (and no action is named as a command), every choice but Storm's own
    self-loops is named when first read (``late_names``; :mod:`mitld_lp.worlds.prism_names`),
    and Storm builds neither choice origins nor choice labels (up to 4% of its build),
    the names made by the second build that makes the valuations."""
    if limit is None and recipe is not None and not events and late_names and own:
        tables = own_build(stormpy, plain, where, chosen, terminal, max_states, None)
        if tables is not None:
            return tables
    # (a world whose events change it is read state by state, every state named: built
    # with its valuations at once)
    deferred = limit is None and recipe is not None and not events
    late = late_names and deferred and is_late(program)
    origins = needs_origins(program) and not late

    def options(checks: bool) -> Any:  # late: no choice labels, every choice named late
        return builder_options(stormpy, program, terminal, checks=checks, origins=origins,
                               valuations=not deferred, labels=not late)

    errors = (RuntimeError, stormpy.exceptions.StormError)
    try:
        with storm_quiet():
            model = storm_build(stormpy, program, options(True), float, limit)
    except errors as exc:
        total = storm_sum(str(exc))
        if total is None or abs(total - 1) > SUM_TOLERANCE:  # the float sum, 1e-16 off
            raise storm_error(exc, where, program, plain) from None
        model = None
    checks = model is not None
    if model is None:  # a sum within PRISM's tolerance: read_model checks the rest
        log.info("%s: probabilities sum to %s somewhere, within PRISM's tolerance %g; "
                 "built without Storm's checks, the sums checked on the model",
                 where, show_sum(total), SUM_TOLERANCE)
        try:
            with storm_quiet():
                model = storm_build(stormpy, program, options(False), float, limit)
        except errors as exc:
            raise storm_error(exc, where, program, plain) from None
    built = set(model.labeling.get_labels())
    unexplored = np.zeros(model.nr_states, dtype=bool)
    if UNEXPLORED in built and limit is not None:
        unexplored[np.fromiter(model.labeling.get_states(UNEXPLORED), dtype=np.int64)] = True
    if model.nr_states - int(np.count_nonzero(unexplored)) > max_states:
        raise PrismTooLarge(
            f"{where}: Storm explored {model.nr_states:,} states, more than max_states = "
            f"{max_states:,}: raise max_states (--max-world-states)"
        )
    if not chosen <= built:  # cannot happen with build_all_labels; never trust it silently
        raise WorldError(f"{where}: Storm did not build labels {sorted(chosen - built)}")
    known = {lab.name for lab in program.labels} | {"init", "deadlock", OUT_OF_BOUNDS}
    if limit is not None:
        known.add(UNEXPLORED)
    stopped = sorted(built - known) if terminal else []
    named = OriginNames(program, where) if origins else None

    def origin(choice: int) -> str:
        """The commands a choice comes from, ``robot_cmd2``."""
        if named is None:  # no module has two commands of one action: see above
            raise AssertionError("two choices of one action without two such commands")
        cmds = model.choice_origins.get_command_set(choice)
        return named.command_text(cmds) if cmds else DEADLOCK_ACTION

    valuations = None
    if deferred:
        assert recipe is not None
        make = ValuationRecipe(recipe, checks, model.nr_states, model.nr_choices,
                               int(model.initial_states[0]))
        read = program_head(plain)  # from the program; else Storm's build of one state
        if read is not None:
            variables, known, booleans = read
            initial = make.initial
        else:
            variables, initial, known, booleans = head(stormpy, program, terminal, origins,
                                                       where)
        valuations = ((variables, DeferredValuations(make, known, booleans, variables))
                      if initial == make.initial else rebuild(make))
    if late and model.nr_choices >= LATE:  # the ids would not fit: named at once
        return build_tables(stormpy, program, plain, where, chosen, events, terminal,
                            max_states, limit, recipe, late_names=False)
    try:
        tables = read_model(model, where, chosen, events, {}, origin,
                            stopped[0] if len(stopped) == 1 else None, valuations=valuations,
                            named=named, shared=may_share_names(program), late=late)
    except WorldError:
        if late:  # refused: built again with the choice origins, to name the choice
            return build_tables(stormpy, program, plain, where, chosen, events, terminal,
                                max_states, limit, recipe, late_names=False)
        if not checks and limit is None:  # Storm's own words where its exact checks
            _exact_refusal(stormpy, program, plain, where, options(True))  # find it
        raise
    if late:
        names = DeferredNames(tuple(tables.action_names), make, command_names(program),
                              tables.choices, tables.targets, tables.action_index,
                              may_share_names(program))
        names.share(tables.states)  # one second build for the values and the names
        tables = dataclasses.replace(tables, action_names=names)
    return dataclasses.replace(tables, unexplored=unexplored) if unexplored.any() else tables


OWN_FROM_STATES = 20_000
"""Under ``auto``, a program of fewer valuations (the product of its variables' numbers of
values, :class:`~mitld_lp.worlds.prism_program.SizeBound`) is built by Storm: a build of
that size costs Storm a few milliseconds, about what loading the explorer's machine code
(numba's runtime, the link) costs, and it leaves numba unloaded."""


_COLD_SAID: list[str] = []
"""Whether a load was built by Storm because the own explorer is not compiled: "" until
:func:`cold_note` has said so, then "said" (once a process)."""


def cold_note() -> str:
    """The words the load's line adds the first time a world was built by Storm because
    the own explorer is not compiled (after the build: an error stays one line)."""
    if _COLD_SAID != [""]:
        return ""
    _COLD_SAID[0] = "said"
    return ("; built by Storm's explicit builder: the own PRISM explorer is not compiled on "
            "this machine yet (`mitld-lp warm` compiles it once)")


def own_build(stormpy: Any, plain: Any, where: str, chosen: frozenset[str], terminal: str,
              max_states: int, memory: int | None) -> Tables | None:
    """The own explorer's tables of a whole build (:mod:`mitld_lp.worlds.prism_explore`)
    where the builder chosen (``MITLD_PRISM_BUILDER``; ``auto``: its kernel cached) takes
    the program; None for Storm's build (the reason logged).  Given ``memory``, only
    where ``max_states`` states at :data:`~mitld_lp.worlds.prism_explore.OWN_BYTES_PER_STATE`
    fit it (it runs here, its state budget checked as it explores: no capped child)."""
    from mitld_lp.worlds import prism_explore

    builder = prism_explore.chosen_builder()
    if builder == "storm":
        return None
    if builder == "auto" and check_program(plain, where).states < OWN_FROM_STATES:
        return None  # Storm's build is quicker than loading the explorer's machine code
    if builder == "auto" and not prism_explore.kernel_ready():
        if not _COLD_SAID:  # said once a process, with the build's line (cold_note)
            _COLD_SAID.append("")
        return None
    if memory is not None and max_states * prism_explore.OWN_BYTES_PER_STATE > memory:
        return None
    tables, reason = prism_explore.explore_tables(stormpy, plain, where, chosen,
                                                  frozenset(), terminal, max_states)
    if tables is None:
        log.debug("%s: Storm builds it, not the own explorer: %s", where, reason)
    return tables


def _exact_refusal(stormpy: Any, program: Any, plain: Any, where: str, options: Any) -> None:
    """Storm's checked build in exact arithmetic, on a world already refused from its
    unchecked build: its own message (the module and command) when it stops at an update
    out of a variable's range or a sum beyond PRISM's tolerance; nothing when it stops
    at a sum within the tolerance first or passes (the caller's refusal stands).  Run
    only on a refusal: it costs three times the build."""
    try:
        with storm_quiet():
            storm_build(stormpy, program, options, stormpy.Rational, None)
    except (RuntimeError, stormpy.exceptions.StormError) as exc:
        total = storm_sum(str(exc))
        if total is None or abs(total - 1) > SUM_TOLERANCE:
            raise storm_error(exc, where, program, plain) from None


def expanded_within(tables: Tables, steps: int) -> bool:
    """Whether every state within ``steps`` moves of the initial state is expanded in
    ``tables`` (a build with a state limit; always true for a whole one): a task of that
    horizon then reads nothing of the world that Storm has not explored."""
    found = tables.unexplored
    if found is None:
        return True
    n = len(tables.states)
    per_choice = np.diff(tables.branches)
    owner = np.repeat(np.repeat(np.arange(n), np.diff(tables.choices)), per_choice)
    graph = sp.csr_matrix((np.ones(owner.size, dtype=np.int8), (owner, tables.targets)),
                          shape=(n, n))
    seen = np.zeros(n, dtype=bool)
    frontier = np.array([tables.initial])
    seen[frontier] = True
    for _ in range(steps + 1):
        if found[frontier].any():
            return False
        nxt = np.unique(graph[frontier].indices)
        frontier = nxt[~seen[nxt]]
        if frontier.size == 0:
            return True
        seen[frontier] = True
    return True
