"""Model files: a task, a world and the events' distributions in one TOML file.

The schema (also in docs/model-files.md)::

    name = "bus_grid"                   # optional, non-empty; default the file's stem
    spec = "D[mu1] b1 & F(b1 & F[0,3] A)"   # required, an MITLD formula (co-safe)
    epsilon = 0.01                      # optional, in (0, 1), default 0.01

    [grid]                              # the game: exactly one game table
    size = [4, 4]                       # required, positive integers (width, height)
    start = [0, 0]                      # required, a free cell
    slip = 0.1                          # optional, in [0, 0.5], default 0
    obstacles = [[2, 2]]                # optional, cells, default none
    stay = false                        # optional: a "stay" action (no slip), default off

    [regions]                           # optional (grid only): name -> non-empty cells
    A = [[1, 2]]

    [distributions]                     # optional: name -> inline table (see
    mu1 = { geometric = 0.8 }           # mitld_lp.distributions.from_table)

    [constants]                         # optional: name -> value, written {name} in
    T = 3                               # the spec (mitld_lp.files.constants)

Every key is validated: unknown keys, wrong types (``true`` is not a number) and
out-of-range values are errors.  Each event of the spec gets exactly one distribution
(a name under ``[distributions]`` or an inline literal); every other proposition must be
a region, not an event; a distribution the spec does not use is an error (nothing is
silently ignored).  Regions the spec does not mention describe the world: allowed.

Every error is a :class:`ModelError` whose message starts with the source (the file
path) and names the key path and the offending value, e.g.
``models/x.toml: grid.slip: must be in [0, 0.5], got 0.7``.

Game kinds: the loader dispatches on which game table is present (``[grid]``,
``[prism]``, ``[gym]``, ``[python]``); a new kind is one entry in ``_GAME_KINDS`` with
the top-level tables it owns and a builder.
"""

from __future__ import annotations

import os
import re
import tomllib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

from mitld_lp import defaults
from mitld_lp.distributions import DistributionError, FirstOccurrence, from_table
from mitld_lp.files import rules as file_rules
from mitld_lp.files.constants import substitute
from mitld_lp.files.keys import (
    KeyContext,
    ModelError,
    budgets_table,
    key_path,
    toml_text,
    type_name,
)
from mitld_lp.logic.fragment import FragmentError, FragmentReport, check
from mitld_lp.logic.parser import ParseError, parse_source
from mitld_lp.logic.syntax import Formula, atoms
from mitld_lp.sensing.sensors import Sensor, read_sensors, sensors_from
from mitld_lp.util.decimals import Written
from mitld_lp.worlds.game import Game, GameError, world_members
from mitld_lp.worlds.grid import GridWorld
from mitld_lp.worlds.task import BindError, Task, bind, resolve_laws

__all__ = [
    "Model",
    "ModelError",
    "load_model",
    "loads_model",
    "model_budgets",
    "bind_distributions",
    "DEFAULT_EPSILON",
]

DEFAULT_EPSILON = defaults.EPSILON
"""The truncation budget used when a model gives no ``epsilon``."""



@dataclass(frozen=True, slots=True)
class Model:
    """A loaded, validated model file.

    Attributes:
        name: the model's ``name``.
        spec: the parsed specification.
        spec_text: the specification as written in the file.
        epsilon: the truncation budget shared over the events.
        game: the world (today a :class:`mitld_lp.worlds.grid.GridWorld`).
        distributions: read-only mapping ``event -> FirstOccurrence`` with one entry per
            external event of the spec (the events are exactly its keys).
        source: the file the model was read from, or ``None`` for :func:`loads_model`.
        constraints: the file's ``constraints`` (texts, checked when loaded; see
            :mod:`mitld_lp.logic.constraints`).
        costs: the file's ``[costs]``: cost per action (1 for an action not named).
        objective: ``"max"`` (the default) or ``"min"``: the probability of the task is
            maximised or minimised (PRISM's ``Pmax`` / ``Pmin``).
        budgets: the file's ``[budgets]`` (``max_states``, ``max_automaton_states``,
            ``max_memory`` bytes, ``time_limit`` seconds), where the caller sets none.
        sensors: the file's ``[sensors]`` (:mod:`mitld_lp.sensing`); an event not
            named is seen the step it happens.
    """

    name: str
    spec: Formula
    spec_text: str
    epsilon: float
    game: Game[Any]
    distributions: Mapping[str, FirstOccurrence]
    source: Path | None = None
    constraints: tuple[str, ...] = ()
    costs: Mapping[str, float] = field(default_factory=lambda: MappingProxyType({}))
    objective: str = "max"
    budgets: Mapping[str, float] = field(default_factory=lambda: MappingProxyType({}))
    sensors: Mapping[str, Sensor] = field(default_factory=lambda: MappingProxyType({}))

    @property
    def events(self) -> frozenset[str]:
        """The external events of the spec."""
        return frozenset(self.distributions)

    def __reduce__(self) -> tuple[Any, ...]:
        # A read-only mapping view does not pickle: rebuild it from a plain dict.
        return (_unpickle_model, (self.name, self.spec, self.spec_text, self.epsilon,
                                  self.game, dict(self.distributions), self.source,
                                  self.constraints, dict(self.costs), self.objective,
                                  dict(self.budgets), dict(self.sensors)))

    @classmethod
    def from_game(
        cls,
        game: Game[Any],
        spec: Formula | str,
        *,
        distributions: Mapping[str, FirstOccurrence] | None = None,
        events: Mapping[str, FirstOccurrence] | None = None,
        epsilon: float = DEFAULT_EPSILON,
        name: str = "model",
        objective: str = "max",
        sensors: Mapping[str, Any] | None = None,
    ) -> Model:
        """A model from a game object and a specification, validated as a file would be.

        ``spec``: a formula or its text; ``distributions`` binds the names used in
        ``D[name]`` to laws (inline literals such as ``D[geometric(0.3)]`` need none).
        Raises :class:`ModelError` (source ``<spec>``) when the spec does not parse or is
        unsupported, the game's members are missing or wrong
        (:func:`mitld_lp.worlds.game.world_members`), or the task does not fit the game
        (:func:`mitld_lp.worlds.task.bind`: a name is unbound or bound but unused, a
        proposition of the spec is neither a proposition of the game nor an event, a
        proposition of the game has an event's name, or the game reacts to events
        (``event_names``) the spec gives no distribution).  ``events`` gives events of
        the world their laws without the spec asking that they happen (a model file's
        ``[events]``): the spec may use them as propositions, ``G (door -> F[0,3] stop)``.
        ``sensors``: per event a :class:`~mitld_lp.sensing.Sensor` or its table
        (``{"detect": 0.8}``), as a model file's ``[sensors]`` (:mod:`mitld_lp.sensing`)."""
        ctx = KeyContext("<spec>")
        try:
            world_members(game)
        except GameError as exc:
            raise ctx.error("game", str(exc)) from exc
        try:
            epsilon = defaults.check_epsilon(epsilon)
        except ValueError as err:
            raise ctx.error("epsilon", str(err)) from None
        if isinstance(spec, str):
            formula, report = _parse_spec(spec, ctx)
            text = spec
        elif isinstance(spec, Formula):
            formula, text = spec, str(spec)
            try:
                report = check(formula)
            except FragmentError as exc:
                raise ctx.error("spec", str(exc)) from exc
        else:
            raise ctx.error("spec", f"must be a formula or its text, got {type(spec).__name__}")
        task = _bind(game, report, distributions, "proposition", None, ctx, events)
        if objective not in OBJECTIVES:
            raise ctx.error("objective", f"must be 'max' or 'min', got {objective!r}")
        seen = sensors_from(sensors, task.laws, ctx)
        return cls(name=name, spec=formula, spec_text=text, epsilon=float(epsilon), game=game,
                   distributions=task.laws, source=None, objective=objective, sensors=seen)


def _unpickle_model(
    name: str, spec: Formula, spec_text: str, epsilon: float, game: Game[Any],
    distributions: dict[str, FirstOccurrence], source: Path | None,
    constraints: tuple[str, ...] = (), costs: dict[str, float] | None = None,
    objective: str = "max", budgets: dict[str, float] | None = None,
    sensors: dict[str, Sensor] | None = None,
) -> Model:
    return Model(name, spec, spec_text, epsilon, game, MappingProxyType(distributions), source,
                 constraints, MappingProxyType(costs or {}), objective,
                 MappingProxyType(budgets or {}), MappingProxyType(sensors or {}))



# --------------------------------------------------------------------------- game kinds


def _no_check(game: Game[Any], task: Task, ctx: KeyContext) -> None:
    """A kind with nothing to check beyond :func:`mitld_lp.worlds.task.bind`."""


@dataclass(frozen=True, slots=True)
class _GameKind:
    """A kind of world a model file may describe.

    Attributes:
        table: the top-level table that selects this kind (``grid``).
        extra_tables: other top-level tables this kind owns (``regions``).
        proposition_noun: what the kind calls a robot proposition, for messages.
        build: ``(document, context) -> game``; validates its own tables.
        check_task: ``(game, task, context)``: what this kind refuses of a task bound to
            its game beyond :func:`mitld_lp.worlds.task.bind` (the spec is read once, after the
            game is built).
    """

    table: str
    extra_tables: tuple[str, ...]
    proposition_noun: str
    build: Callable[[dict[str, Any], KeyContext], Game[Any]]
    check_task: Callable[[Game[Any], Task, KeyContext], None] = _no_check


def _build_grid(doc: dict[str, Any], ctx: KeyContext) -> GridWorld:
    """The ``[grid]`` and ``[regions]`` tables: their TOML types are checked here, their
    values by :class:`GridWorld`, whose :class:`GridError` paths map to key paths."""
    from mitld_lp.worlds.grid import GridError

    grid = ctx.table(doc["grid"], "grid")
    ctx.keys(grid, "grid", {"size", "start"}, {"slip", "obstacles", "stay"})
    size = grid["size"]
    if not isinstance(size, list) or len(size) != 2:
        raise ctx.error("grid.size", f"must be [width, height], got {toml_text(size)}")
    width = ctx.integer(size[0], "grid.size[0]")
    height = ctx.integer(size[1], "grid.size[1]")

    def cells(value: Any, path: str) -> Any:
        for i, v in enumerate(ctx.array(value, path)):
            ctx.pair(v, f"{path}[{i}]")
        return value

    if "slip" in grid:
        ctx.number(grid["slip"], "grid.slip")
    stay = grid.get("stay", False)
    if not isinstance(stay, bool):
        raise ctx.error("grid.stay", f"must be a boolean, got {type_name(stay)} {toml_text(stay)}")
    obstacles = cells(grid.get("obstacles", []), "grid.obstacles")
    ctx.pair(grid["start"], "grid.start")
    table = ctx.table(doc.get("regions", {}), "regions")
    regions: Any = {name: cells(value, key_path("regions", name)) for name, value in table.items()}
    try:
        return GridWorld(
            width=width,
            height=height,
            # the values as written (lists), so that messages show them as written;
            # GridWorld validates and normalises them
            start=grid["start"],
            slip=grid.get("slip", 0.0),
            obstacles=obstacles,
            regions=regions,
            stay=stay,
        )
    except GridError as exc:
        head, *rest = exc.parts
        if head in ("width", "height"):
            path = f"grid.size[{0 if head == 'width' else 1}]"
        else:
            path = "regions" if head == "regions" else f"grid.{head}"
        for part in rest:
            path = f"{path}[{part}]" if isinstance(part, int) else key_path(path, part)
        raise ctx.error(path, exc.message) from None


def _build_prism(doc: dict[str, Any], ctx: KeyContext) -> Game[Any]:
    """``[prism]``: ``file`` (relative to the model file; to the working directory for
    :func:`loads_model`), optional ``constants`` (name -> boolean or number), ``labels``
    (the labels that become propositions, default all) and ``events`` (PRISM actions
    that are the effects of the spec's events); see :mod:`mitld_lp.worlds.prism`.  The
    top-level ``[labels]`` table defines more labels, ``done = "l=9"``, evaluated by
    Storm on the world's variables; the spec is given to the loader so that states
    where the task is decided are not expanded."""
    from mitld_lp.worlds import WorldError
    from mitld_lp.worlds.prism import PrismTooLarge, load_prism

    table = ctx.table(doc["prism"], "prism")
    ctx.keys(table, "prism", {"file"}, {"constants", "labels", "events", "explore"})
    source = Path(ctx.source)
    base = source.parent if source.is_file() else Path.cwd()
    path = base / ctx.string(table["file"], "prism.file")
    constants = ctx.table(table.get("constants", {}), "prism.constants")
    for cname, value in constants.items():
        if not isinstance(value, bool | int | float):
            raise ctx.error(
                key_path("prism.constants", cname),
                f"must be a boolean or a number, got {type_name(value)} {toml_text(value)}",
            )

    def names(key: str) -> list[str] | None:
        if key not in table:
            return None
        items = ctx.array(table[key], f"prism.{key}")
        return [ctx.string(v, f"prism.{key}[{i}]") for i, v in enumerate(items)]

    labels, events = names("labels"), names("events")
    explore = ctx.string(table.get("explore", "auto"), "prism.explore")
    if explore not in ("auto", "full", "lazy"):
        raise ctx.error("prism.explore", f'must be "auto", "full" or "lazy", got {explore!r}')
    # [labels]: name -> a PRISM expression, a label Storm evaluates on the world's states
    define = {name: ctx.string(text, key_path("labels", name))
              for name, text in ctx.table(doc.get("labels", {}), "labels").items()}
    # the task, so that Storm does not expand states where it is decided
    task, _ = _parse_spec(doc["spec"], ctx)
    try:
        return load_prism(path, constants=constants, labels=labels, events=events or (),
                          max_states=ctx.max_states, max_memory=ctx.max_memory,
                          define=define, task=task, explore=explore)
    except PrismTooLarge as exc:  # a budget stop, not a mistake in the file
        raise PrismTooLarge(f"{ctx.source}: prism: {exc}") from exc
    except WorldError as exc:
        message = str(exc)
        m = re.match(r"label '(\w+)'(?: = '[^']*')?: (.*)$", message)
        if m and m[1] in define:
            raise ctx.error(key_path("labels", m[1]), m[2]) from exc
        raise ctx.error("prism", message) from exc


def _check_prism_task(game: Game[Any], task: Task, ctx: KeyContext) -> None:
    """A PRISM action named like a proposition of the spec but not listed under
    ``prism.events`` would be offered to the robot as a move of its own: refuse it
    rather than let the robot cause the event."""
    from mitld_lp.worlds.prism import PrismGame

    assert isinstance(game, PrismGame)
    robot_actions = game.robot_actions()  # from the tables, not state by state
    # a label of the world named like an action is the label (the spec reads labels)
    for action in sorted((atoms(task.formula) - set(game.proposition_names))
                         & robot_actions):
        raise ctx.error(
            "prism.events",
            f"PRISM action {action!r} has the name of a proposition of spec; list it in "
            "prism.events if it is the effect of that event",
        )


_GAME_KINDS: tuple[_GameKind, ...] = (
    _GameKind(
        table="grid", extra_tables=("regions",), proposition_noun="region", build=_build_grid,
    ),
    _GameKind(
        table="prism", extra_tables=("labels",), proposition_noun="label", build=_build_prism,
        check_task=_check_prism_task,
    ),
    # worlds named by code (mitld_lp.worlds.loaders): a gymnasium environment, a factory
    _GameKind(table="gym", extra_tables=(), proposition_noun="label",
              build=lambda doc, ctx: _loaders().gym_world(doc, ctx)),
    _GameKind(table="python", extra_tables=(), proposition_noun="proposition",
              build=lambda doc, ctx: _loaders().python_world(doc, ctx)),
)


def _loaders() -> Any:
    from mitld_lp.worlds import loaders

    return loaders

_COMMON_REQUIRED = {"spec"}
_COMMON_OPTIONAL = {"name", "epsilon", "distributions", "events", "constants", "constraints",
                    "costs", "objective", "budgets", "sensors"}
OBJECTIVES = defaults.OBJECTIVES


# --------------------------------------------------------------------------- the spec


def _parse_spec(text: str, ctx: KeyContext) -> tuple[Formula, FragmentReport]:
    """Parse the spec (errors carry ``line:column`` within the spec string) and check it
    is in the supported co-safe fragment."""
    try:
        source = parse_source(text)
    except ParseError as exc:
        raise ctx.error("spec", f"{exc.line}:{exc.column}: {exc.reason}") from exc
    try:
        report = check(source)  # the events of every D[mu] a written, also folded ones
    except FragmentError as exc:
        raise ctx.error("spec", str(exc)) from exc
    return report.formula, report


def bind_distributions(
    spec: Formula, named: Mapping[str, FirstOccurrence] | None = None, source: str = "<spec>"
) -> dict[str, FirstOccurrence]:
    """The distribution of each external event of ``spec``: ``D[name]`` looked up in
    ``named``, an inline literal built (:func:`mitld_lp.worlds.task.resolve_laws`).  Raises
    :class:`ModelError` naming the problem (an unsupported formula, an unknown name, a
    bad literal, a name bound but not used)."""
    ctx = KeyContext(source)
    try:
        report = check(spec)
    except FragmentError as exc:
        raise ctx.error("spec", str(exc)) from exc
    try:
        return resolve_laws(report, named)
    except BindError as exc:
        raise ctx.error(_bind_path(exc, None), exc.reason) from exc


# --------------------------------------------------------------------------- loading


def _toml_error(exc: tomllib.TOMLDecodeError, text: str, ctx: KeyContext) -> ModelError:
    """``SOURCE:LINE:COLUMN: TOML syntax error at line L, column C: what``."""
    message = str(exc)
    m = re.search(r"\s*\(at line (\d+), column (\d+)\)", message)
    if m:
        line, column = int(m.group(1)), int(m.group(2))
        message = message[: m.start()] + message[m.end() :]
    elif "(at end of document)" in message:
        lines = text.split("\n")
        line, column = len(lines), len(lines[-1]) + 1
        message = message.replace("(at end of document)", "at the end of the file").strip()
    else:
        return ModelError(f"{ctx.source}: TOML syntax error: {message}")
    return ModelError(
        f"{ctx.source}:{line}:{column}: TOML syntax error at line {line}, column {column}: "
        f"{message.strip()}"
    )


def _bind_path(exc: BindError, table: str | None) -> str:
    """The key path of a binding fault: a proposition of the world is named under
    ``table`` (where the world's propositions are declared) when there is one."""
    match exc.key:
        case ("distributions" | "events" as key, name):
            return key_path(key, name)
        case ("proposition", name) if table:
            return key_path(table, name)
    return "spec"


def _bind(
    game: Game[Any],
    report: FragmentReport,
    named: Mapping[str, FirstOccurrence] | None,
    noun: str,
    table: str | None,
    ctx: KeyContext,
    declared: Mapping[str, FirstOccurrence] | None = None,
) -> Task:
    """:func:`mitld_lp.worlds.task.bind`, its faults as :class:`ModelError` with key paths."""
    try:
        return bind(game, report, named, noun=noun, declared=declared)
    except BindError as exc:
        raise ctx.error(_bind_path(exc, table), exc.reason) from exc


def _law_tables(doc: Mapping[str, Any], key: str, ctx: KeyContext) -> dict[str, FirstOccurrence]:
    """The laws of a model file's ``[distributions]`` or ``[events]`` table: each entry
    an inline table such as ``{ geometric = 0.5 }`` (errors at ``key.name``)."""
    laws: dict[str, FirstOccurrence] = {}
    source = Path(ctx.source)  # a fit's data file is read beside the model file
    base = source.parent if source.is_file() else None
    for name, value in ctx.table(doc.get(key, {}), key).items():
        path = key_path(key, name)
        if not isinstance(value, dict):
            raise ctx.error(
                path,
                f"must be an inline table such as {{ geometric = 0.5 }}, got "
                f"{type_name(value)} {toml_text(value)}",
            )
        try:
            laws[name] = from_table(value, path, base)
        except DistributionError as exc:
            message = str(exc)
            raise ModelError(
                f"{ctx.source}: {message}" if path in message
                else f"{ctx.source}: {path}: {message}"
            ) from exc
    return laws


def _load(
    text: str, source: str, path: Path | None, max_states: int | None,
    max_memory: int | None
) -> Model:
    ctx = KeyContext(source)
    try:
        # every decimal keeps its text: an exact answer is about the model as written
        doc = tomllib.loads(text, parse_float=Written)
    except tomllib.TOMLDecodeError as exc:
        raise _toml_error(exc, text, ctx) from None
    except RecursionError:  # tomllib parses nested arrays and tables recursively
        raise ctx.error("", "TOML nested too deeply to read") from None
    budgets = budgets_table(doc, ctx)
    # the caller's budgets first, then the file's, then the defaults (a world built while
    # loading, a [prism] program, is bounded by them)
    ctx.max_states = int(max_states if max_states is not None else
                         budgets.get("max_world_states", defaults.MAX_STATES))
    mem = max_memory if max_memory is not None else budgets.get("max_memory")
    ctx.max_memory = None if mem is None else int(mem)

    present = [k for k in _GAME_KINDS if k.table in doc]
    if len(present) > 1:
        raise ctx.error(
            "",
            f"exactly one game table is allowed, got {', '.join(f'[{k.table}]' for k in present)}",
        )
    if not present:
        every = {k.table for k in _GAME_KINDS} | {t for k in _GAME_KINDS for t in k.extra_tables}
        ctx.keys(doc, "", set(), _COMMON_REQUIRED | _COMMON_OPTIONAL | every)
        allowed = ", ".join(f"[{k.table}]" for k in _GAME_KINDS)
        raise ctx.error("", f"no game table: add one of {allowed}")
    kind = present[0]
    ctx.keys(doc, "", _COMMON_REQUIRED | {kind.table}, _COMMON_OPTIONAL | set(kind.extra_tables))

    name = ctx.string(doc["name"], "name") if "name" in doc else _default_name(source, path)
    spec_text = ctx.string(doc["spec"], "spec")
    epsilon = DEFAULT_EPSILON
    if "epsilon" in doc:
        ctx.number(doc["epsilon"], "epsilon")
        try:
            epsilon = defaults.check_epsilon(doc["epsilon"])
        except ValueError as err:
            raise ctx.error("epsilon", str(err)) from None

    # {name} in the spec stands for a value under [constants] (mitld_lp.files.constants)
    spec_text = substitute(spec_text, ctx.table(doc.get("constants", {}), "constants"),
                           ctx.error)
    doc = {**doc, "spec": spec_text}

    game = kind.build(doc, ctx)

    named = _law_tables(doc, "distributions", ctx)
    declared = _law_tables(doc, "events", ctx)

    spec, report = _parse_spec(spec_text, ctx)
    where = kind.extra_tables[0] if kind.extra_tables else kind.table
    task = _bind(game, report, named, kind.proposition_noun, where, ctx, declared)
    kind.check_task(game, task, ctx)

    constraints, costs = constraints_and_costs(doc, ctx)
    sensors = read_sensors(doc.get("sensors", {}), task.laws, ctx)
    objective = doc.get("objective", "max")
    if objective not in OBJECTIVES:
        raise ctx.error("objective", f"must be \"max\" or \"min\", got {toml_text(objective)}")
    return Model(
        name=name,
        spec=spec,
        spec_text=spec_text,
        epsilon=epsilon,
        game=game,
        distributions=task.laws,
        source=path,
        constraints=constraints,
        costs=MappingProxyType(costs),
        objective=objective,
        budgets=MappingProxyType(budgets),
        sensors=sensors,
    )


def _default_name(source: str, path: Path | None) -> str:
    """A model's name when its file gives none: the file's stem (its source's for text
    whose source names a file), else ``"model"``."""
    stem = (path or Path(source)).stem if path is not None or not source.startswith("<") else ""
    return stem or "model"


def loads_model(
    text: str,
    source: str = "<string>",
    *,
    max_states: int | None = None,
    max_memory: int | None = None,
) -> Model:
    """Load a model from TOML ``text``; ``source`` prefixes every error message.
    ``max_states`` and ``max_memory`` bound a world built while loading (a ``[prism]``
    program, checked before Storm runs), as they bound the product later.

    Raises :class:`ModelError`.  The returned model's ``source`` is ``None``."""
    return _load(text, source, None, max_states, max_memory)


def load_model(
    path: str | os.PathLike[str],
    *,
    max_states: int | None = None,
    max_memory: int | None = None,
) -> Model:
    """Load and validate the model file at ``path`` (budgets as for :func:`loads_model`).

    Raises :class:`ModelError` (message ``PATH: KEY.PATH: problem``), also when the
    file cannot be read or is not UTF-8."""
    return _load(_read(path, max_memory), os.fspath(path), Path(path), max_states, max_memory)


def _read(path: str | os.PathLike[str], max_memory: int | None) -> str:
    source = os.fspath(path)
    try:  # a regular file, no larger than the memory budget allows (file_rules)
        return file_rules.read_bytes(path, file_rules.read_limit(max_memory)).decode("utf-8")
    except file_rules.InputFileError as exc:
        raise ModelError(str(exc)) from exc
    except OSError as exc:
        raise ModelError(f"{source}: cannot read: {exc.strerror or exc}") from exc
    except UnicodeDecodeError as exc:
        raise ModelError(f"{source}: not UTF-8 text: {exc}") from exc


def model_budgets(path: str | os.PathLike[str], *,
                  max_memory: int | None = None) -> dict[str, float]:
    """The ``[budgets]`` of the model file at ``path`` alone, read before the model is so
    that a command holds every stage to them, the world's loading included (the command
    line's time limit); ``{}`` when they cannot be read: :func:`load_model` says why."""
    try:
        return budgets_table(tomllib.loads(_read(path, max_memory)), KeyContext(os.fspath(path)))
    except (ModelError, tomllib.TOMLDecodeError, RecursionError):
        return {}


def constraints_and_costs(doc: Mapping[str, Any], ctx: KeyContext) -> tuple[tuple[str, ...],
                                                                          dict[str, float]]:
    """The ``constraints`` list (each read by :func:`mitld_lp.logic.constraints.parse_constraint`)
    and the ``[costs]`` table (numbers > 0 per action)."""
    from mitld_lp.logic.constraints import ConstraintError, check_costs, parse_constraint

    texts = doc.get("constraints", [])
    if not isinstance(texts, list):
        raise ctx.error("constraints", f"must be a list of strings, got {type_name(texts)}")
    for i, text in enumerate(texts):
        try:
            parse_constraint(text, f"constraints[{i}]")
        except ConstraintError as exc:
            raise ModelError(f"{ctx.source}: {exc}") from None
    try:
        costs = check_costs(ctx.table(doc.get("costs", {}), "costs"))
    except ConstraintError as exc:
        raise ModelError(f"{ctx.source}: {exc}") from None
    return tuple(texts), costs
