"""A PRISM MDP as a :class:`mitld_lp.game.Game`, built by Storm through stormpy.

``load_prism("robot.prism", constants={"N": 4}, events=("opened",))`` parses the file,
gives its undefined constants their values, builds the MDP's reachable states with
Storm and copies everything the product construction needs into plain Python tables
(so the game pickles and Storm is not needed afterwards):

* **states** are tuples of the PRISM variables' values, in the order
  :attr:`PrismGame.variables` lists them (``game.valuation(s)`` gives them by name);
  the initial state is the program's (exactly one is required).
* **propositions** are the program's ``label "name" = ...;`` definitions, all of them
  by default (Storm is always told to build every label: a label it was not asked to
  build would silently be false everywhere); ``labels=`` selects a subset, and naming a
  label the file does not define is an error.  Storm's own ``"init"`` and
  ``"deadlock"`` are not propositions.
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

import json
import logging
import os
from collections.abc import Hashable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mitld_lp.game import ExplicitGame
from mitld_lp.worlds import WorldError
from mitld_lp.worlds.prism_program import check_program, storm_error, storm_quiet

__all__ = ["PrismGame", "load_prism", "DEADLOCK_ACTION"]

log = logging.getLogger(__name__)

State = tuple[Hashable, ...]
"""A PRISM state: the values of :attr:`PrismGame.variables`, in that order."""

_Distribution = tuple[tuple[State, float], ...]

DEADLOCK_ACTION = "deadlock"
"""The name of the self-loop Storm adds where no PRISM command is enabled."""

_INSTALL = "pip install -e '.[prism]'"


@dataclass(frozen=True, eq=False)
class PrismGame:
    """A PRISM MDP as a game (see the module docstring for the mapping).

    Attributes:
        source: the PRISM file.
        variables: the PRISM variables, in the order of a state's values.
        robot: the robot's part: states, actions, labels and the moves without events.
        effects: ``event -> state -> distribution``: where each event action's command is
            enabled, the distribution it moves to; an event absent at a state leaves it.
    """

    source: str
    variables: tuple[str, ...]
    robot: ExplicitGame[State]
    effects: Mapping[str, Mapping[State, _Distribution]]
    _cache: dict[tuple[State, str, frozenset[str]], _Distribution] = field(
        default_factory=dict, repr=False, compare=False
    )

    @property
    def initial(self) -> State:
        return self.robot.initial

    @property
    def proposition_names(self) -> frozenset[str]:
        return self.robot.proposition_names

    @property
    def events(self) -> frozenset[str]:
        """The event actions whose commands change the world."""
        return frozenset(self.effects)

    @property
    def states(self) -> tuple[State, ...]:
        """Every state Storm built."""
        return self.robot.states

    def valuation(self, state: State) -> dict[str, Hashable]:
        """The state's variables by name, e.g. ``{"x": 2, "open": False}``."""
        return dict(zip(self.variables, state, strict=True))

    def actions(self, state: State) -> tuple[str, ...]:
        return self.robot.actions(state)

    def propositions(self, state: State) -> frozenset[str]:
        return self.robot.propositions(state)

    def successors(
        self, state: State, action: str, events: frozenset[str]
    ) -> tuple[tuple[State, float], ...]:
        """The robot's move, then each event's effect in name order (module docstring)."""
        acting = events & self.effects.keys()
        base = self.robot.successors(state, action, frozenset())
        if not acting:
            return base
        key = (state, action, frozenset(acting))
        cached = self._cache.get(key)
        if cached is not None:
            return cached
        dist: dict[State, float] = dict(base)
        for event in sorted(acting):
            effect = self.effects[event]
            moved: dict[State, float] = {}
            for t, p in dist.items():
                for u, q in effect.get(t, ((t, 1.0),)):
                    moved[u] = moved.get(u, 0.0) + p * q
            dist = moved
        out = tuple(dist.items())
        self._cache[key] = out
        return out


# --------------------------------------------------------------------------- loading


def _stormpy() -> Any:
    try:
        import stormpy  # pyright: ignore[reportMissingImports]
    except ImportError as exc:
        raise WorldError(
            f"reading a PRISM file needs stormpy, which is not installed: {_INSTALL}"
        ) from exc
    return stormpy


def _check_utf8(path: Path, where: str) -> None:
    """Refuse a file that is not UTF-8 text, naming the first bad byte's place."""
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise WorldError(f"{where}: cannot read: {exc.strerror or exc}") from None
    try:
        data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        column = exc.start - (data.rfind(b"\n", 0, exc.start) + 1) + 1
        raise WorldError(
            f"{where}:{line}:{column}: not UTF-8 text (byte 0x{data[exc.start]:02x}); "
            "a PRISM file is UTF-8"
        ) from None


def _check_constants(program: Any, constants: Mapping[str, Any], where: str) -> None:
    declared = {c.name: c for c in program.constants}
    for name, value in constants.items():
        if name not in declared:
            known = ", ".join(sorted(declared)) or "none"
            raise WorldError(f"{where}: constant {name!r} is not declared (constants: {known})")
        c = declared[name]
        if c.defined:
            raise WorldError(
                f"{where}: constant {name!r} already has a value in the file "
                f"({c.definition}); only undefined constants can be given"
            )
        kind = c.type
        if kind.is_boolean:
            ok, want = isinstance(value, bool), "a boolean"
        elif kind.is_integer:
            ok, want = isinstance(value, int) and not isinstance(value, bool), "an integer"
        else:
            ok = isinstance(value, int | float) and not isinstance(value, bool)
            want = "a number"
        if not ok:
            raise WorldError(f"{where}: constant {name!r} must be {want}, got {value!r}")
    missing = sorted(c.name for c in program.constants if not c.defined and c.name not in constants)
    if missing:
        raise WorldError(
            f"{where}: constants {', '.join(missing)} have no value in the file; "
            "give them with constants={...}"
        )


def _command_names(program: Any) -> dict[int, str]:
    """Global command index -> ``<module>_cmd<k>`` (k from 1 within the module)."""
    return {
        cmd.global_index: f"{module.name}_cmd{k}"
        for module in program.modules
        for k, cmd in enumerate(module.commands, start=1)
    }


def load_prism(
    path: str | os.PathLike[str],
    *,
    constants: Mapping[str, bool | int | float] | None = None,
    labels: Iterable[str] | None = None,
    events: Iterable[str] = (),
) -> PrismGame:
    """Build the PRISM MDP at ``path`` with Storm and return it as a game.

    ``constants``: values of the file's undefined constants (every undefined constant
    needs one).  ``labels``: the labels that become propositions (default: every label
    of the file).  ``events``: PRISM actions that are external events' effects (module
    docstring); their names must match the events of the specification.

    Raises :class:`mitld_lp.worlds.WorldError`.
    """
    where = os.fspath(path)
    p = Path(path)
    if not p.is_file():
        raise WorldError(f"{where}: no such PRISM file")
    if p.suffix.lower() == ".jani":
        raise WorldError(f"{where}: JANI files are not supported; give the PRISM source")
    _check_utf8(p, where)
    stormpy = _stormpy()
    try:
        with storm_quiet():
            program = stormpy.parse_prism_program(where)
    except (RuntimeError, stormpy.exceptions.StormError) as exc:
        raise storm_error(exc, where) from None
    kind = str(program.model_type).rsplit(".", 1)[-1]
    if kind != "MDP":
        hint = " (a dtmc is an mdp with one command per state: write mdp)" if kind == "DTMC" else ""
        raise WorldError(f"{where}: the model is a {kind}, a game needs an mdp{hint}")

    given = dict(constants or {})
    _check_constants(program, given, where)
    defined = [lab.name for lab in program.labels]
    if labels is None:
        chosen = frozenset(defined)
    else:
        chosen = frozenset([labels] if isinstance(labels, str) else labels)
        for name in sorted(chosen - set(defined)):
            raise WorldError(
                f"{where}: label {name!r} is not defined (labels: {', '.join(defined) or 'none'})"
            )
    actions = {
        cmd.action_name for module in program.modules for cmd in module.commands if cmd.is_labeled
    }
    event_set = frozenset([events] if isinstance(events, str) else events)
    for name in sorted(event_set - actions):
        raise WorldError(
            f"{where}: event {name!r} is not an action of the file "
            f"(actions: {', '.join(sorted(actions)) or 'none'})"
        )

    if given:
        try:
            with storm_quiet():
                program, _ = stormpy.instantiate_constants(program, given)
        except (RuntimeError, stormpy.exceptions.StormError) as exc:
            raise storm_error(exc, where) from None
    try:
        with storm_quiet():
            plain = program.substitute_constants()
    except (RuntimeError, stormpy.exceptions.StormError) as exc:
        raise storm_error(exc, where) from None
    check_program(plain, where)
    options = stormpy.BuilderOptions()
    # Refuse updates out of a variable's range and probabilities that do not sum to 1
    # where they depend on the state (without the checks Storm wraps values around).
    options.set_exploration_checks(True)
    # Every label, always: a label left out of the build would be false in every state.
    options.set_build_all_labels()
    options.set_build_choice_labels()
    options.set_build_choice_origins()
    options.set_build_state_valuations()
    try:
        with storm_quiet():
            model = stormpy.build_model(program, options=options)
    except (RuntimeError, stormpy.exceptions.StormError) as exc:
        raise storm_error(exc, where, program) from None
    built = set(model.labeling.get_labels())
    if not chosen <= built:  # cannot happen with build_all_labels; never trust it silently
        raise WorldError(f"{where}: Storm did not build labels {sorted(chosen - built)}")
    return _tables(model, where, chosen, event_set, _command_names(program))


def _valuations(model: Any) -> tuple[tuple[str, ...], list[State]]:
    """The variables (in Storm's order) and each state's values, read per variable."""
    valuations = model.state_valuations
    if model.nr_states == 0:
        return (), []
    order = tuple(json.loads(str(valuations.to_json(0))) or ())  # null: no variables
    by_name = {v.name: v for v in valuations.get_all_variables()}
    columns = []
    for name in order:
        var = by_name[name]
        if var.has_boolean_type():  # a bit vector: the states where it is true
            true = set(valuations.get_boolean_values(var))
            columns.append([s in true for s in range(model.nr_states)])
        elif var.has_integer_type():
            columns.append(valuations.get_int64_values(var))
        else:  # pragma: no cover - PRISM state variables are booleans and integers
            columns.append([valuations.get_value(s, var) for s in range(model.nr_states)])
    if not columns:  # no variables: every state is the empty valuation (one state)
        return order, [()] * model.nr_states
    return order, [tuple(row) for row in zip(*columns, strict=True)]


def _tables(
    model: Any,
    where: str,
    chosen: frozenset[str],
    events: frozenset[str],
    command_names: Mapping[int, str],
) -> PrismGame:
    """Copy Storm's sparse MDP into the game's tables (labels and choice labels are read
    per label, valuations per variable: the bindings are slow per call)."""
    variables, states = _valuations(model)

    def show(s: int) -> str:
        return "[" + " & ".join(f"{k}={v}" for k, v in zip(variables, states[s], strict=True)) + "]"

    def origin(choice: int) -> str:
        """The commands a choice comes from, ``robot_cmd2`` (``deadlock``: none)."""
        cmds = sorted(model.choice_origins.get_command_set(choice))
        return "+".join(command_names[c] for c in cmds) if cmds else DEADLOCK_ACTION

    state_labels: list[set[str]] = [set() for _ in states]
    for label in chosen:
        for s in model.labeling.get_states(label):
            state_labels[s].add(label)
    choice_label: dict[int, str] = {}
    for label in model.choice_labeling.get_labels():
        for c in model.choice_labeling.get_choices(label):
            choice_label[c] = label

    matrix = model.transition_matrix
    transitions: dict[State, dict[str, tuple[tuple[State, float], ...]]] = {}
    effects: dict[str, dict[State, _Distribution]] = {e: {} for e in events}
    labelling: dict[State, frozenset[str]] = {}
    for s in range(model.nr_states):
        state = states[s]
        labelling[state] = frozenset(state_labels[s])
        named: list[tuple[str, int, _Distribution]] = []  # (name, choice, distribution)
        for choice in range(matrix.get_row_group_start(s), matrix.get_row_group_end(s)):
            dist = tuple((states[e.column], float(e.value)) for e in matrix.get_row(choice))
            act = choice_label.get(choice)
            if act in events:
                if state in effects[act]:
                    raise WorldError(
                        f"{where}: event {act!r} has two enabled commands at state "
                        f"{show(s)}; an event's effect must be one command per state"
                    )
                effects[act][state] = dist
                continue
            named.append((act if act is not None else origin(choice), choice, dist))
        if not named:
            raise WorldError(
                f"{where}: at state {show(s)} only event commands are enabled; the robot "
                "needs an action there (e.g. [wait] true -> true;)"
            )
        counts: dict[str, int] = {}
        for name, _, _ in named:
            counts[name] = counts.get(name, 0) + 1
        row: dict[str, tuple[tuple[State, float], ...]] = {}
        for name, choice, dist in named:
            if counts[name] > 1:
                name = f"{name}@{origin(choice)}"
            if name in row:
                raise WorldError(f"{where}: two choices named {name!r} at state {show(s)}")
            row[name] = dist
        transitions[state] = row

    initial = list(model.initial_states)
    if len(initial) != 1:
        raise WorldError(
            f"{where}: the model has {len(initial)} initial states; a game needs exactly one"
        )
    robot = ExplicitGame(
        initial=states[initial[0]],
        transitions=transitions,
        labels=labelling,
        proposition_names=chosen,
    )
    log.info(
        "%s: %d states, %d choices, labels %s, events %s",
        where, model.nr_states, model.nr_choices, sorted(chosen), sorted(events),
    )
    return PrismGame(source=where, variables=variables, robot=robot, effects=effects)
