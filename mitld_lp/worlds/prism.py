"""A PRISM MDP as a :class:`mitld_lp.worlds.game.Game`, parsed by the own parser
(:mod:`mitld_lp.worlds.prism_own`, no stormpy) where it takes the file, else by Storm.

``load_prism("robot.prism", constants={"N": 4}, events=("opened",))`` parses the file,
gives its undefined constants their values, checks the program, builds the MDP's
reachable states with Storm (within ``max_states`` and ``max_memory``, stopped when the
exploration passes them; not past the states where the task is decided) and copies it
into numpy arrays without a loop over states
(:mod:`mitld_lp.worlds.prism_tables`; the game pickles and needs Storm no more):

* **states** are tuples of the PRISM variables' values, in the order
  :attr:`PrismGame.variables` lists them (``game.valuation(s)`` gives them by name);
  the initial state is the program's (exactly one is required).
* **propositions** are the program's ``label "name" = ...;`` definitions (and its Boolean
  ``formula``s, and the labels ``define=`` adds), all of them by default (Storm is always
  told to build every label: a label it was not asked to build would silently be false
  everywhere); ``labels=`` selects a subset, and naming a label the file does not define is
  an error.  Storm's own ``"init"`` and ``"deadlock"`` are not propositions.
* **robot actions** are the choices of each state, named by their PRISM action: ``[go]``
  gives ``"go"``.  A command without an action (``[] ...``) is named
  ``"<module>_cmd<k>"``, the ``k``-th command (from 1) of its module, and the self-loop
  Storm adds to a state where no command is enabled is ``"deadlock"``.  Two choices of
  one state with the same name (overlapping guards of one action) get the commands
  they come from appended, ``"go@robot_cmd1"``, so names are always distinct and the
  same on every run.

External events.  An event of the specification that the PRISM model does not mention
changes nothing in the world: it only appears in the step's label, as the bus arrivals
of the grid case study do.  An event that *does* change the world is written as a
PRISM action and listed in ``events``: its commands (in one module, or synchronised
across several, as PRISM composes them) are the event's **effect**, and they are never
offered to the robot.  In a step where the environment's events are ``E``::

    P(s' | s, a, E) = sum over t of P_a(t | s) * (effect of E)(s' | t)

the robot's action ``a`` moves the world first, then each event of ``E`` (in name order)
applies its command at the state reached; where the event's command is not enabled the
event leaves the state unchanged.  Why this order: the formula reads the step's events
together with the propositions of the state the step ends in, so the effect of an event
is computed from exactly the state the formula pairs it with (a bus that arrives while
the robot reaches the stop finds the robot there).  This keeps a single Storm build (the
event commands are ordinary nondeterministic choices to Storm, so every state that any
interleaving of moves and events reaches is built), and a PRISM user writes an event as
they would write any other action.  An event's command must be unique where enabled
(one choice per state): an event is the environment's, not a choice.

Checks.  Storm builds with its exploration checks on, so an update that leaves a
variable's range or probabilities that do not sum to 1 in some state stop the build
(without them Storm stores values modulo the range); before it builds, every variable
must have a non-empty range holding its initial value and every command with constant
probabilities must have them in [0, 1] summing to 1 (:mod:`mitld_lp.worlds.prism_program`).
Sums are compared as PRISM compares them, within
:data:`~mitld_lp.worlds.prism_program.SUM_TOLERANCE` (1e-5): Storm's own check is exact
in floating point, so where it alone fails, within the tolerance, the model is built
without Storm's checks and every sum and range is checked on the copy (Storm's exact
checks only word a refusal: :func:`~mitld_lp.worlds.prism_build.build_tables`), and a
choice that sums to 1 only within that tolerance is divided by its sum
(:attr:`PrismGame.normalised` counts them).  An expression deeper than
Storm's parser takes is refused before it reads the file
(:mod:`mitld_lp.worlds.prism_depth`).

Budgets and exploration.  The product of the variables' ranges is a note, not a
refusal: Storm explores the reachable part within ``max_states`` and ``max_memory``
(in a memory-capped child process when the ranges do not already fit:
:mod:`mitld_lp.worlds.prism_bounded`).  Given the task, states where it is decided
whatever happens next are not expanded (:mod:`mitld_lp.worlds.prism_terminal`): they
keep their labels and have one action, :data:`DECIDED_ACTION`, a self-loop.  Given a task
of bounded horizon, Storm explores only the states within that horizon, breadth first,
and more only if the product asks for them (:class:`LazyPrismGame`; Storm's build itself
is :mod:`mitld_lp.worlds.prism_build`).

Errors are :class:`mitld_lp.worlds.WorldError`, one line naming the file and what is
wrong: a missing file or one that is not UTF-8 (the first bad byte's line and column),
PRISM's parse message as ``FILE:LINE:COLUMN`` with a short excerpt, the module and
command of an update out of range or of probabilities that do not sum to 1, an undefined
constant, a label or event action the file does not define, a model that is not an
MDP, a state where only event commands are enabled.  Storm's own log never reaches
standard output.  Without stormpy the error says
``pip install -e '.[prism]'``.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Hashable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np

from mitld_lp import defaults
from mitld_lp.logic.fragment import horizon
from mitld_lp.logic.syntax import Formula
from mitld_lp.worlds import WorldError
from mitld_lp.worlds.game import GameError
from mitld_lp.worlds.prism_build import (
    BYTES_PER_STATE,
    CAP_BYTES_PER_STATE,
    UNEXPLORED,
    Grower,
    PrismTooLarge,
    build_tables,
    build_within,
    check_budgets,
    cold_note,
    own_build,
)
from mitld_lp.worlds.prism_depth import ExpressionDepth, check_text
from mitld_lp.worlds.prism_exact import PrismRecipe, exact_probabilities
from mitld_lp.worlds.prism_names import DeferredNames, command_names
from mitld_lp.worlds.prism_own import own_load
from mitld_lp.worlds.prism_program import (
    check_constants,
    check_program,
    labelled_program,
    storm_error,
    storm_quiet,
    with_constants,
)
from mitld_lp.worlds.prism_tables import DEADLOCK_ACTION, DECIDED_ACTION, Tables
from mitld_lp.worlds.prism_terminal import decided as decided_when
from mitld_lp.worlds.prism_terminal import render
from mitld_lp.worlds.successors import Normalisation
from mitld_lp.worlds.table import LATE, LateNames, WorldTable

__all__ = [
    "PrismGame", "LazyPrismGame", "PrismTooLarge", "load_prism", "DEADLOCK_ACTION",
    "DECIDED_ACTION", "BYTES_PER_STATE", "CAP_BYTES_PER_STATE", "build_within",
    "check_budgets", "LAZY_FIRST_STATES", "LAZY_GROWTH",
]

log = logging.getLogger(__name__)

State = tuple[Hashable, ...]
"""A PRISM state: the values of :attr:`PrismGame.variables`, in that order."""

_Distribution = tuple[tuple[State, float], ...]

_INSTALL = "pip install -e '.[prism]'"

@dataclass(frozen=True, eq=False)
class PrismGame:
    """A PRISM MDP as a game (see the module docstring for the mapping).

    Attributes:
        source: the PRISM file.
        variables: the PRISM variables, in the order of a state's values.
        states: every state Storm built, in Storm's order (each made a tuple when
            asked for: :class:`mitld_lp.worlds.prism_tables.Valuations`).
        initial: the initial state.
        proposition_names: the labels that are propositions.
        effects: ``event -> array over states``: where each event action's command is
            enabled, the index of its choice; -1 where it is not (the event leaves the
            state as it is).
        terminal: the PRISM expression of the states where the task is decided, which
            Storm did not expand ("" when there are none).
        decided: how many of :attr:`states` were not expanded (their one action is
            :data:`DECIDED_ACTION`, a self-loop).
        normalised: the choices whose probabilities summed to 1 only within PRISM's
            tolerance, each divided by its sum when the file was read (None: none
            were); an answer's checks say it (:func:`mitld_lp.synthesis.solve`).

    Transitions stay in Storm's sparse layout (:class:`mitld_lp.worlds.prism_tables.Tables`);
    a state's actions and a choice's distribution become tuples when first asked for
    (and the index of the states, a dictionary, when a state is first looked up).  The
    product reads the layout whole (:meth:`as_table`) when no event changes the world.
    """

    source: str
    variables: tuple[str, ...]
    states: Sequence[State]
    initial: State
    proposition_names: frozenset[str]
    effects: Mapping[str, np.ndarray]
    _tables: Tables = field(repr=False)
    terminal: str = ""
    decided: int = 0
    normalised: Normalisation | None = None
    _cache: dict[Any, Any] = field(default_factory=dict, repr=False, compare=False)
    recipe: Any = field(default=None, repr=False)  # to build it again: a PrismRecipe, a JaniRecipe

    @property
    def event_names(self) -> frozenset[str]:
        """The events the world reacts to: the event actions whose commands change it."""
        return frozenset(self.effects)

    @property
    def n_states(self) -> int | None:
        """How many states Storm built (bounds the product before it is built)."""
        return len(self.states)

    @property
    def explored(self) -> int:
        """How many states Storm expanded (all of :attr:`states` unless the world is
        explored as the task reaches it: :class:`LazyPrismGame`)."""
        return len(self.states)

    def valuation(self, state: State) -> dict[str, Hashable]:
        """The state's variables by name, e.g. ``{"x": 2, "open": False}``."""
        return dict(zip(self.variables, state, strict=True))

    def _at(self, state: State) -> int:
        index = self._cache.get("index")
        if index is None:  # built on first use: the product reads the table instead
            index = self._cache["index"] = dict(
                zip(self.states, range(len(self.states)), strict=True))
        try:
            return index[state]
        except (KeyError, TypeError):
            raise GameError(f"{state!r} is not a state of {self.source}") from None

    def _names(self, s: int) -> list[str | None]:
        """The names of state ``s``'s choices, None for an event's."""
        t = self._tables
        return [t.action_names[k] if k >= 0 else None
                for k in t.action_index[t.choices[s] : t.choices[s + 1]].tolist()]

    def actions(self, state: State) -> tuple[str, ...]:
        s = self._at(state)
        key = ("actions", s)
        found = self._cache.get(key)
        if found is None:
            found = self._cache[key] = tuple(a for a in self._names(s) if a is not None)
        return found

    def propositions(self, state: State) -> frozenset[str]:
        t = self._tables
        return t.label_sets[int(t.label_index[self._at(state)])]

    def robot_actions(self, exact: bool = False) -> frozenset[str]:
        """Every name of a robot action at some state (where the choices are not named
        yet, :mod:`mitld_lp.worlds.prism_names`: every name a command's choice may have,
        unless ``exact``, which names them)."""
        t = self._tables
        names, ids = t.action_names, t.action_index
        if isinstance(names, DeferredNames) and not exact and not names.resolved:
            used = np.flatnonzero(np.bincount(ids[ids < LATE], minlength=1))  # every name
            return frozenset(names[k] for k in used.tolist()) | names.commands  # of a command
        if isinstance(names, LateNames):  # all at once (Storm's second build, if deferred)
            codes, table = names.names_of(np.arange(ids.size))
            return frozenset(table[k] for k in np.flatnonzero(np.bincount(codes)).tolist())
        used = np.unique(ids)
        return frozenset(names[k] for k in used[used >= 0].tolist())

    def as_table(self) -> WorldTable | None:
        """The world as a :class:`~mitld_lp.worlds.table.WorldTable` for the product (no
        copy of the transitions when no choice is an event's); None when an event
        changes the world (its moves then depend on the step's events)."""
        if self.effects:
            return None
        t = self._tables
        return WorldTable(
            states=self.states, initial=t.initial, label_sets=t.label_sets,
            label_of=t.label_index, choices=t.choices, action_names=t.action_names,
            action_of=t.action_index, branches=t.branches, targets=t.targets,
            probabilities=t.probabilities, checked=t.checked,
        )

    def _distribution(self, choice: int, exact: bool = False) -> dict[int, Any]:
        t = self._tables
        lo, hi = t.branches[choice], t.branches[choice + 1]
        if exact:  # Storm's exact build, made when first asked (mitld_lp.worlds.prism_exact)
            probabilities = self._cache.get("exact")
            if probabilities is None:
                if self.recipe is None:
                    raise WorldError(f"{self.source}: this world was not built by "
                                     "load_prism: its exact probabilities are unknown")
                probabilities = self._cache["exact"] = exact_probabilities(self.recipe, t)
            return dict(zip(t.targets[lo:hi].tolist(), probabilities[lo:hi], strict=True))
        return dict(zip(t.targets[lo:hi].tolist(), t.probabilities[lo:hi].tolist(), strict=True))

    def successors(
        self, state: State, action: str, events: frozenset[str]
    ) -> tuple[tuple[State, float], ...]:
        """The robot's move, then each event's effect in name order (module docstring)."""
        return self._moves(state, action, events, exact=False)

    def exact_successors(
        self, state: State, action: str, events: frozenset[str]
    ) -> tuple[tuple[State, Fraction], ...]:
        """:meth:`successors` in rational arithmetic, the probabilities as the PRISM file
        writes them (Storm's exact build, :mod:`mitld_lp.worlds.prism_exact`)."""
        return self._moves(state, action, events, exact=True)

    def _moves(self, state: State, action: str, events: frozenset[str], exact: bool,
               ) -> tuple[tuple[State, Any], ...]:
        s = self._at(state)
        acting = frozenset(events & self.effects.keys())
        key = (s, action, acting, exact)
        found = self._cache.get(key)
        if found is not None:
            return found
        t = self._tables
        row = self._names(s)
        if action not in row:
            raise GameError(f"state {state!r}: {action!r} is not one of its actions {row!r}")
        dist = self._distribution(int(t.choices[s]) + row.index(action), exact)
        for event in sorted(acting):
            effect = self.effects[event]
            moved: dict[int, Any] = {}
            for u, p in dist.items():
                c = int(effect[u])
                for v, q in (self._distribution(c, exact) if c >= 0 else {u: 1}).items():
                    moved[v] = moved.get(v, 0) + p * q
            dist = moved
        if exact:  # every state asked for in turn: made tuples once, not one by one
            listed = self._cache.get("listed")
            if listed is None:
                listed = self._cache["listed"] = list(self.states)
            out = tuple((listed[u], p) for u, p in dist.items())
        else:
            out = tuple((self.states[u], p) for u, p in dist.items())
        self._cache[key] = out
        return out


LAZY_FIRST_STATES = 4096
"""The states Storm first explores of a world explored as the task reaches it."""

LAZY_GROWTH = 8
"""How much more a lazily explored world's next exploration finds than its last."""


@dataclass(frozen=True, eq=False)
class LazyPrismGame(PrismGame):
    """A PRISM MDP explored as the product reaches it (``load_prism(explore=...)``).

    Storm explores breadth first and stops expanding once it has found :attr:`limit`
    states (:func:`~mitld_lp.worlds.prism_build.build_tables`): a state's index, actions
    and moves are the whole build's, as Storm numbers states in the order it finds them.
    A state found but not expanded, when the product asks for it, makes Storm explore
    again with :data:`LAZY_GROWTH` times the limit (never past ``max_states``: beyond,
    :class:`PrismTooLarge` before Storm explores further).

    Differences from :class:`PrismGame`, each by name: :attr:`states` are the states
    found so far, :attr:`n_states` is None until Storm has expanded every state (the
    product then counts its states as it builds), :meth:`robot_actions` names the
    program's actions, :meth:`as_table` is None (the product asks state by state), and
    the exact successors (``--exact``) are refused: they need the whole world."""

    exact_successors = None  # Storm's exact build is of the whole world (prism_exact)
    inexact_reason = ("a PRISM world explored as the task reaches it: its exact "
                      "probabilities come from Storm's exact build of the whole world; "
                      "explore it whole ([prism] explore = \"full\" in a model file, "
                      "load_prism(explore=\"full\"))")

    grow: Any = field(default=None, repr=False)  # limit -> Tables (a prism_build.Grower)
    limit: int = 0
    max_states: int = defaults.MAX_STATES
    program_actions: frozenset[str] = frozenset()

    @property
    def ignores_events(self) -> bool:
        return True  # no event changes a lazily explored world (load_prism)

    @property
    def n_states(self) -> int | None:
        return None if self._open() is not None else len(self.states)

    @property
    def explored(self) -> int:
        found = self._open()
        return len(self.states) - (0 if found is None else int(np.count_nonzero(found)))

    def _open(self) -> np.ndarray | None:
        return self._tables.unexplored

    def _at(self, state: State, expanded: bool = True) -> int:
        """The index of ``state``, exploring further until it is found (and, when
        ``expanded``, expanded)."""
        while True:
            try:
                s = super()._at(state)
            except GameError:
                if self._open() is None:
                    raise
            else:
                found = self._open()
                if not expanded or found is None or not found[s]:
                    return s
            self._explore_further()

    def _explore_further(self) -> None:
        if self.limit >= self.max_states:
            raise PrismTooLarge(
                f"{self.source}: the task reaches more than max_states = {self.max_states:,} "
                "world states (explored breadth first from the initial state): raise "
                "max_states (--max-world-states)")
        limit = min(self.limit * LAZY_GROWTH, self.max_states)
        tables: Tables = self.grow(limit)
        log.info("%s: explored further, %d states found (limit %d)", self.source,
                 len(tables.states), limit)
        for name, value in (("_tables", tables), ("states", tables.states),
                            ("limit", limit), ("decided", tables.decided)):
            object.__setattr__(self, name, value)  # the same states, more of them
        self._cache.pop("index", None)  # the other entries are by index: still true

    def propositions(self, state: State) -> frozenset[str]:
        t = self._tables  # a state found is labelled, expanded or not
        return t.label_sets[int(t.label_index[self._at(state, expanded=False)])]

    def robot_actions(self, exact: bool = False) -> frozenset[str]:
        return self.program_actions  # the states found so far: not all of the world's

    def as_table(self) -> WorldTable | None:
        return None

    def _moves(self, state: State, action: str, events: frozenset[str], exact: bool,
               ) -> tuple[tuple[State, Any], ...]:
        if exact:
            raise WorldError(f"{self.source}: no exact successors on {self.inexact_reason}")
        s = self._at(state)
        key = (s, action)  # no event changes this world: the row is the action's alone
        found = self._cache.get(key)
        if found is None:
            t = self._tables
            row = self._names(s)
            if action not in row:
                raise GameError(f"state {state!r}: {action!r} is not one of its actions {row!r}")
            c = int(t.choices[s]) + row.index(action)
            lo, hi = int(t.branches[c]), int(t.branches[c + 1])
            found = self._cache[key] = tuple(zip(
                t.states.rows(t.targets[lo:hi]), t.probabilities[lo:hi].tolist(), strict=True))
        return found


# --------------------------------------------------------------------------- loading


def stormpy_module() -> Any:
    """stormpy, or a :class:`WorldError` saying how to install it."""
    try:
        import stormpy  # pyright: ignore[reportMissingImports]
    except ImportError as exc:
        raise WorldError(
            f"reading a PRISM file needs stormpy, which is not installed: {_INSTALL}"
        ) from exc
    return stormpy


def load_prism(
    path: str | os.PathLike[str],
    *,
    constants: Mapping[str, bool | int | float] | None = None,
    labels: Iterable[str] | None = None,
    events: Iterable[str] = (),
    max_states: int = defaults.MAX_STATES,
    max_memory: int | None = None,
    define: Mapping[str, str] | None = None,
    task: Formula | None = None,
    explore: str = "auto",
    first_states: int = LAZY_FIRST_STATES,
) -> PrismGame:
    """Build the PRISM MDP at ``path`` with Storm and return it as a game.

    ``constants``: values of the file's undefined constants (every undefined constant
    needs one).  ``labels``: the propositions (default: every label of the file, every
    Boolean ``formula`` that no label shadows, and every name of ``define``).
    ``define``: more labels, ``name -> PRISM expression`` over the file's variables,
    constants and formulas (``{"done": "l=9"}``), evaluated by Storm as if the file ended
    with ``label "done" = l=9;`` (the file itself is not changed).  ``events``: PRISM
    actions that are external events' effects (module docstring); their names must match
    the events of the specification.  ``task``: the formula the world is for; states
    where it is decided whatever happens next are not expanded
    (:mod:`mitld_lp.worlds.prism_terminal`).

    Budgets: Storm explores at most ``max_states`` states within ``max_memory`` bytes
    (default :func:`mitld_lp.product.default_max_memory`), at :data:`BYTES_PER_STATE`
    bytes a state.  When the product of the variables' ranges does not already fit, the
    exploration runs in a child process capped at that memory
    (:mod:`mitld_lp.worlds.prism_bounded`), so that a program larger than the budget
    stops when the budget is spent; the range product is only reported.

    ``explore``: ``"full"`` builds every reachable state before the product is built;
    ``"lazy"`` explores the states breadth first as the product reaches them, starting
    with ``first_states`` (:class:`LazyPrismGame`; refused with event effects); ``"auto"``
    (default) is ``"lazy"`` for a task of bounded horizon ``H`` (``F[0,10] goal``, not
    ``F goal`` or ``D[mu] a``) without event effects, else ``"full"``, and explores at
    once (:data:`LAZY_GROWTH` times more each time) until every state within ``H`` moves
    is expanded.  Either way a world Storm explores whole within the states it was
    allowed is the plain :class:`PrismGame`, which the product reads whole.

    Raises :class:`mitld_lp.worlds.WorldError` (:class:`PrismTooLarge` for a budget).
    """
    if explore not in ("auto", "full", "lazy"):
        raise ValueError(f"explore must be 'auto', 'full' or 'lazy', got {explore!r}")
    if isinstance(first_states, bool) or not isinstance(first_states, int) or first_states < 1:
        raise ValueError(f"first_states must be a positive integer, got {first_states!r}")
    memory = check_budgets(max_states, max_memory)
    where = os.fspath(path)
    p = Path(path)
    if p.suffix.lower() == ".jani":
        raise WorldError(f"{where}: JANI files are not supported here: load_jani reads them")
    depth = ExpressionDepth()
    check_text(p, where, depth)  # before Storm's parser, which can crash on it
    owned = own_load(p.read_text(encoding="utf-8"), where, depth, constants=dict(
        constants or {}), labels=labels, events=frozenset([events] if isinstance(
            events, str) else events), max_states=max_states, memory=memory,
        define=dict(define or {}), task=task, explore=explore, first=first_states)
    if owned is not None:  # no stormpy: the own parser and explorer (prism_own)
        return _game(where, owned.tables, owned.chosen, owned.terminal, PrismRecipe(
            str(p.resolve()), where, dict(constants or {}), dict(define or {}),
            owned.terminal), f"{owned.bound}, parsed without Storm", frozenset())
    stormpy = stormpy_module()
    program = labelled_program(stormpy, p, where, dict(define or {}), where, depth,
                               lambda program: _an_mdp(program, where))
    given = dict(constants or {})
    check_constants(program, given, where)
    defined = [lab.name for lab in program.labels]
    if labels is None:
        chosen = frozenset(defined)
    else:
        chosen = frozenset([labels] if isinstance(labels, str) else labels)
        for name in sorted(chosen - set(defined)):
            raise WorldError(
                f"{where}: label {name!r} is not defined (labels: {', '.join(defined) or 'none'})"
            )
    actions = _labelled(program)
    event_set = frozenset([events] if isinstance(events, str) else events)
    for name in sorted(event_set - actions):
        raise WorldError(
            f"{where}: event {name!r} is not an action of the file "
            f"(actions: {', '.join(sorted(actions)) or 'none'})"
        )

    program = with_constants(stormpy, program, given, where)
    try:
        with storm_quiet():
            plain = program.substitute_constants()
    except (RuntimeError, stormpy.exceptions.StormError) as exc:
        raise storm_error(exc, where) from None
    bound = check_program(plain, where)
    condition = decided_when(task, frozenset(defined)) if task is not None else False
    terminal = "" if condition is False else render(
        condition, {lab.name: str(lab.expression) for lab in plain.labels})
    if terminal and depth.deepest(terminal) is not None:  # every state expanded instead
        log.info("%s: the states where the task is decided are too deep an expression for "
                 "Storm; all states are expanded", where)
        terminal = ""
    recipe = PrismRecipe(str(p.resolve()), where, dict(given), dict(define or {}), terminal)

    def work(limit: int | None = None, own: bool = True) -> Tables:
        return build_tables(stormpy, program, plain, where, chosen, event_set, terminal,
                            max_states, limit, recipe, own=own)

    lazy = explore == "lazy" or (explore == "auto" and task is not None
                                 and horizon(task) is not None and not event_set
                                 and UNEXPLORED not in defined)
    if lazy and (event_set or UNEXPLORED in defined):
        raise WorldError(f"{where}: explore='lazy' takes no event effects and no label "
                         f"named {UNEXPLORED!r}: use explore='full'")
    first = min(first_states, max_states)
    if lazy:  # the first states Storm finds; all of them when the world is that small
        grower = Grower(work, where, memory, str(bound), max_states)
        steps = horizon(task) if task is not None and explore == "auto" else None
        tables, first = grower.within(first, steps, LAZY_GROWTH)
    else:
        fits = bound.states <= max_states and bound.states * BYTES_PER_STATE <= memory
        tables = (None if fits or event_set else own_build(  # the own explorer, else Storm
            stormpy, plain, where, chosen, terminal, max_states, memory)) or build_within(
            lambda: work(None, own=fits), where, fits, str(bound), max_states, memory)
    if tables.unexplored is None:
        return _game(where, tables, chosen, terminal, recipe, str(bound), event_set)
    common = _common(where, tables, chosen, terminal, recipe, str(bound), event_set)
    return LazyPrismGame(**common, grow=grower, limit=first,  # type: ignore[arg-type]
                         max_states=max_states,
                         program_actions=command_names(program) - event_set)


def _common(where: str, tables: Tables, chosen: frozenset[str], terminal: str,
            recipe: PrismRecipe, bound: str, events: frozenset[str]) -> dict[str, Any]:
    """The fields of a loaded game (its load logged)."""
    log.info("%s: %d states explored (%s), %d not expanded (task decided: %s), labels %s, "
             "events %s%s", where, len(tables.states), bound, tables.decided,
             terminal or "never", sorted(chosen), sorted(events), cold_note())
    return dict(source=where, variables=tables.variables, states=tables.states,
                initial=tables.states[tables.initial], proposition_names=chosen,
                effects=tables.effects, terminal=terminal, decided=tables.decided,
                normalised=tables.normalised, _tables=tables, recipe=recipe)


def _game(*args: Any) -> PrismGame:
    return PrismGame(**_common(*args))


def _an_mdp(program: Any, where: str) -> None:
    """A :class:`WorldError` unless ``program`` is an MDP."""
    kind = str(program.model_type).rsplit(".", 1)[-1]
    if kind != "MDP":
        hint = " (a dtmc is an mdp with one command per state: write mdp)" if kind == "DTMC" else ""
        raise WorldError(f"{where}: the model is a {kind}, a game needs an mdp{hint}")


def _labelled(program: Any) -> set[str]:
    """The actions of the program's commands."""
    return {cmd.action_name for module in program.modules for cmd in module.commands
            if cmd.is_labeled}
