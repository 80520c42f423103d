"""The game tables of a model file: which top-level table selects which kind of world
(``[grid]``, ``[prism]``, ``[gym]``, ``[python]``), the builder that checks each table's
keys and builds its game, and what each kind refuses of a task (a new kind is one entry
in :data:`GAME_KINDS`); and the model file's spec read once (:func:`parse_spec`).  Used
by :mod:`mitld_lp.model`, which reads the rest of the file."""

from __future__ import annotations

import functools
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from mitld_lp.files.keys import KeyContext, key_path, toml_text, type_name
from mitld_lp.logic.fragment import FragmentError, FragmentReport, check
from mitld_lp.logic.parser import ParseError, parse_source
from mitld_lp.logic.syntax import Formula, atoms
from mitld_lp.worlds.game import Game
from mitld_lp.worlds.task import Task

if TYPE_CHECKING:  # a grid's module is read only where a file describes a grid
    from mitld_lp.worlds.grid import GridWorld

__all__ = ["GAME_KINDS", "GameKind", "parse_spec"]


def parse_spec(text: str, ctx: KeyContext) -> tuple[Formula, FragmentReport]:
    """Parse the spec (errors carry ``line:column`` within the spec string) and check it
    is in the supported co-safe fragment.  A text read before is not parsed again (a
    PRISM model file reads its spec for the loader's decided states, then for its task):
    the report and its formula are frozen, so the same objects serve both."""
    try:
        report = _checked(text)
    except ParseError as exc:
        raise ctx.error("spec", f"{exc.line}:{exc.column}: {exc.reason}") from exc
    except FragmentError as exc:
        raise ctx.error("spec", str(exc)) from exc
    return report.formula, report


@functools.lru_cache(maxsize=32)
def _checked(text: str) -> FragmentReport:
    """The spec's report, by its text (a failure is not kept: it raises again)."""
    return check(parse_source(text))  # the events of every D[mu] a written, also folded ones


def _no_check(game: Game[Any], task: Task, ctx: KeyContext) -> None:
    """A kind with nothing to check beyond :func:`mitld_lp.worlds.task.bind`."""


@dataclass(frozen=True, slots=True)
class GameKind:
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
    from mitld_lp.worlds.grid import GridError, GridWorld

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
    task, _ = parse_spec(doc["spec"], ctx)
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
    # from the tables, not state by state; where the choices are named when first read,
    # every name a command may give first, and Storm's names only if one is an atom
    # (a label of the world named like an action is the label: the spec reads labels)
    named = (atoms(task.formula) - set(game.proposition_names)) & game.robot_actions()
    if named:
        named &= game.robot_actions(exact=True)
    for action in sorted(named):
        raise ctx.error(
            "prism.events",
            f"PRISM action {action!r} has the name of a proposition of spec; list it in "
            "prism.events if it is the effect of that event",
        )


GAME_KINDS: tuple[GameKind, ...] = (
    GameKind(
        table="grid", extra_tables=("regions",), proposition_noun="region", build=_build_grid,
    ),
    GameKind(
        table="prism", extra_tables=("labels",), proposition_noun="label", build=_build_prism,
        check_task=_check_prism_task,
    ),
    # worlds named by code (mitld_lp.worlds.loaders): a gymnasium environment, a factory
    GameKind(table="gym", extra_tables=(), proposition_noun="label",
              build=lambda doc, ctx: _loaders().gym_world(doc, ctx)),
    GameKind(table="python", extra_tables=(), proposition_noun="proposition",
              build=lambda doc, ctx: _loaders().python_world(doc, ctx)),
)


def _loaders() -> Any:
    from mitld_lp.worlds import loaders

    return loaders
