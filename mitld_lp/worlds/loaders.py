"""Worlds a model file names by code: ``[gym]`` (a gymnasium toy-text environment) and
``[python]`` (a factory function of any Python module).

``[gym]``::

    env = "FrozenLake-v1"                  # required: the id gymnasium.make takes
    kwargs = { map_name = "4x4", is_slippery = true }   # optional: gymnasium.make's keywords
    labels = { G = "goal", H = "hole" }    # optional: map letter -> proposition (this default)
    propositions = { goal = [15] }         # optional, instead of labels: name -> states
    actions = ["LEFT", "DOWN", "RIGHT", "UP"]   # optional: names of actions 0, 1, ...
    initial = 0                            # optional: the start state
    terminal = "absorb"                    # optional: "absorb" or "keep"

The game is the environment's transition table (:func:`mitld_lp.worlds.gym.from_env`).
Propositions are read off the environment's map (``desc``, one state per cell, as
:func:`mitld_lp.worlds.gym.map_labels` does: ``goal`` and ``hole`` on FrozenLake) unless
``propositions`` lists the states of each name.  FrozenLake's actions are named
``LEFT, DOWN, RIGHT, UP``; other environments' are ``0, 1, ...`` unless ``actions``
names them.

``[python]``::

    world = "package.module:factory"       # required: a callable returning a game
    kwargs = { size = 4 }                  # optional: its keyword arguments

The module is imported (the model file's folder is searched first, as Python searches a
script's folder) and ``factory(**kwargs)`` is called: **loading such a model file runs
that code**, so a model file from someone else deserves the care a script from them
does.  The result must implement the :class:`mitld_lp.game.Game` protocol.

Errors are :class:`mitld_lp.model.ModelError` naming the key path (``gym.env``,
``python.world``, ...).
"""

from __future__ import annotations

import contextlib
import importlib
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

from mitld_lp.game import Game
from mitld_lp.logic.syntax import is_proposition_name
from mitld_lp.worlds import WorldError

if TYPE_CHECKING:
    from mitld_lp.model import _Context

__all__ = ["gym_world", "python_world"]

_TERMINAL = ("absorb", "keep")


def _names(ctx: _Context, value: Any, path: str) -> list[str]:
    return [ctx.string(v, f"{path}[{i}]") for i, v in enumerate(ctx.array(value, path))]


def _proposition(ctx: _Context, name: str, path: str) -> str:
    if not is_proposition_name(name):
        raise ctx.error(path, f"{name!r} is not a name a formula can write (letters, digits "
                        "and _, not a reserved word such as F)")
    return name


def _labels(ctx: _Context, table: dict[str, Any], env: Any, n_states: int, env_id: str,
            ) -> tuple[dict[Any, frozenset[str]], frozenset[str]]:
    """``(state -> propositions, every proposition name)`` of a ``[gym]`` table."""
    from mitld_lp.worlds.gym import map_labels

    if "propositions" in table:
        if "labels" in table:
            raise ctx.error("gym.labels", "give either labels (read off the map) or "
                            "propositions (states per name), not both")
        out: dict[Any, set[str]] = {}
        given = ctx.table(table["propositions"], "gym.propositions")
        for name, states in given.items():
            path = f"gym.propositions.{name}"
            _proposition(ctx, name, path)
            for i, s in enumerate(ctx.array(states, path)):
                out.setdefault(ctx.integer(s, f"{path}[{i}]"), set()).add(name)
        return {s: frozenset(v) for s, v in out.items()}, frozenset(given)
    letters = ctx.table(table.get("labels", {"G": "goal", "H": "hole"}), "gym.labels")
    for letter, name in letters.items():
        _proposition(ctx, ctx.string(name, f"gym.labels.{letter}"), f"gym.labels.{letter}")
    desc = getattr(env.unwrapped, "desc", None)  # an environment, not a world
    if desc is None or len(desc) * len(desc[0]) != n_states:
        raise ctx.error("gym.labels", f"{env_id} has no map with one cell per state to read "
                        f"propositions off ({n_states} states); give gym.propositions = "
                        "{ name = [states] }")
    return map_labels(desc, letters), frozenset(letters.values())


def gym_world(doc: dict[str, Any], ctx: _Context) -> Game[Any]:
    """The game of a ``[gym]`` table (module docstring)."""
    table = ctx.table(doc["gym"], "gym")
    ctx.keys(table, "gym", {"env"},
             {"kwargs", "labels", "propositions", "actions", "initial", "terminal"})
    env_id = ctx.string(table["env"], "gym.env")
    kwargs = ctx.table(table.get("kwargs", {}), "gym.kwargs")
    actions = _names(ctx, table["actions"], "gym.actions") if "actions" in table else None
    initial = ctx.integer(table["initial"], "gym.initial") if "initial" in table else None
    terminal = table.get("terminal", "absorb")
    if terminal not in _TERMINAL:
        raise ctx.error("gym.terminal", f'must be "absorb" or "keep", got {terminal!r}')
    try:
        import gymnasium
    except ImportError:
        raise ctx.error("gym", "needs gymnasium (pip install 'mitld_lp[gym]')") from None
    from mitld_lp.worlds.gym import FROZEN_LAKE_ACTIONS, from_env

    try:
        env = gymnasium.make(env_id, **kwargs)
    except gymnasium.error.Error as exc:
        raise ctx.error("gym.env", f"gymnasium cannot make {env_id!r}: {exc}") from None
    except Exception as exc:  # noqa: BLE001 - the environment's own check of its kwargs
        raise ctx.error("gym.kwargs", f"gymnasium.make({env_id!r}, ...) failed: "
                        f"{type(exc).__name__}: {exc}") from None
    try:
        table_p = getattr(env.unwrapped, "P", None)
        if table_p is None:
            raise ctx.error("gym.env", f"{env_id} has no transition table P (only toy-text "
                            "environments such as FrozenLake, CliffWalking, Taxi have one)")
        labels, names = _labels(ctx, table, env, len(table_p), env_id)
        if actions is None and env_id.startswith("FrozenLake"):
            actions = list(FROZEN_LAKE_ACTIONS)
        return from_env(env, propositions=labels, proposition_names=names,
                        action_names=actions, initial=initial, terminal=terminal)
    except WorldError as exc:
        raise ctx.error("gym", str(exc)) from None
    finally:
        env.close()


@contextlib.contextmanager
def _searched_first(folder: Path) -> Iterator[None]:
    sys.path.insert(0, str(folder))
    try:
        yield
    finally:
        with contextlib.suppress(ValueError):
            sys.path.remove(str(folder))


def python_world(doc: dict[str, Any], ctx: _Context) -> Game[Any]:
    """The game a ``[python]`` table's factory returns (module docstring)."""
    table = ctx.table(doc["python"], "python")
    ctx.keys(table, "python", {"world"}, {"kwargs"})
    target = ctx.string(table["world"], "python.world")
    kwargs = ctx.table(table.get("kwargs", {}), "python.kwargs")
    module_name, _, attribute = (part.strip() for part in target.partition(":"))
    if not module_name or not attribute:
        raise ctx.error("python.world", f'must be "package.module:factory", got {target!r}')
    source = Path(ctx.source)
    folder = source.parent if source.is_file() else Path.cwd()
    with _searched_first(folder.resolve()):
        try:
            module = importlib.import_module(module_name)
        except ImportError as exc:
            raise ctx.error("python.world", f"cannot import {module_name}: {exc}") from None
        except Exception as exc:  # noqa: BLE001 - the module's own code failed
            raise ctx.error("python.world", f"importing {module_name} raised "
                            f"{type(exc).__name__}: {exc}") from None
    factory: Any = module
    for part in attribute.split("."):
        if not hasattr(factory, part):
            raise ctx.error("python.world", f"{module_name} has no attribute {attribute}")
        factory = getattr(factory, part)
    if not callable(factory):
        raise ctx.error("python.world", f"{target} is not callable")
    try:
        game = factory(**kwargs)
    except Exception as exc:  # noqa: BLE001 - the factory's own code failed
        raise ctx.error("python.kwargs" if isinstance(exc, TypeError) else "python.world",
                        f"{target}(**kwargs) raised {type(exc).__name__}: {exc}") from None
    if not isinstance(game, Game):
        raise ctx.error("python.world", f"{target} returned {type(game).__name__}, not a game "
                        "(the Game protocol: initial, proposition_names, actions, successors,"
                        " propositions)")
    return game
