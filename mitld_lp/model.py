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
``[prism]``, ``[gym]``, ``[python]``); a new kind is one entry in
:data:`mitld_lp.game_tables.GAME_KINDS` with the top-level tables it owns and a builder.
"""

from __future__ import annotations

import os
import re
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

from mitld_lp import defaults
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
from mitld_lp.game_tables import GAME_KINDS, parse_spec
from mitld_lp.logic.fragment import FragmentError, FragmentReport, check
from mitld_lp.logic.syntax import Formula
from mitld_lp.sensing.sensors import Sensor, read_sensors, sensors_from
from mitld_lp.util.decimals import Written
from mitld_lp.worlds.game import Game, GameError, world_members
from mitld_lp.worlds.task import BindError, Task, bind, resolve_laws

if TYPE_CHECKING:  # the laws' package is read only where a file names a law
    from mitld_lp.distributions import FirstOccurrence

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
            formula, report = parse_spec(spec, ctx)
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



_COMMON_REQUIRED = {"spec"}
_COMMON_OPTIONAL = {"name", "epsilon", "distributions", "events", "constants", "constraints",
                    "costs", "objective", "budgets", "sensors"}
OBJECTIVES = defaults.OBJECTIVES


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
    tables = ctx.table(doc.get(key, {}), key)
    if not tables:  # a PRISM file's world with no law: the families are not imported
        return laws
    from mitld_lp.distributions import DistributionError, from_table

    source = Path(ctx.source)  # a fit's data file is read beside the model file
    base = source.parent if source.is_file() else None
    for name, value in tables.items():
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

    present = [k for k in GAME_KINDS if k.table in doc]
    if len(present) > 1:
        raise ctx.error(
            "",
            f"exactly one game table is allowed, got {', '.join(f'[{k.table}]' for k in present)}",
        )
    if not present:
        every = {k.table for k in GAME_KINDS} | {t for k in GAME_KINDS for t in k.extra_tables}
        ctx.keys(doc, "", set(), _COMMON_REQUIRED | _COMMON_OPTIONAL | every)
        allowed = ", ".join(f"[{k.table}]" for k in GAME_KINDS)
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

    spec, report = parse_spec(spec_text, ctx)
    where = kind.extra_tables[0] if kind.extra_tables else kind.table
    task = _bind(game, report, named, kind.proposition_noun, where, ctx, declared)
    kind.check_task(game, task, ctx)

    constraints, costs = constraints_and_costs(doc, ctx)
    sensors = read_sensors(doc.get("sensors", {}), task.laws, ctx)
    objective = doc.get("objective", "max")
    if objective not in OBJECTIVES:
        asked = (f" (ask for the task's expected {objective[4:]} on the command line: "
                 f"--objective {objective}; a model file's objective is the "
                 "probability's)" if objective in ("min-steps", "min-cost") else "")
        raise ctx.error("objective", f"must be \"max\" or \"min\", got "
                        f"{toml_text(objective)}{asked}")
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
