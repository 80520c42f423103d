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
does.  The result must implement the :class:`mitld_lp.worlds.game.Game` protocol.

The game is then held to the :class:`~mitld_lp.worlds.game.Game` contract on every call
(:class:`GuardedWorld`): a method that raises, answers ``None``, an empty or repeated
action list, propositions that are not a set of its ``proposition_names``, or successor
probabilities that are not a distribution (negative, NaN, summing to 0.99) is a
:class:`WorldContractError` (a :class:`~mitld_lp.model.ModelError`: exit 2 on the
command line, ``model_error`` in a sweep) naming the model file, the world, the method
and the state, ``m.toml: python.world: bw:make: W.successors(state 0, action 'a'):
probabilities sum to 0.99, not 1``.  ``SystemExit`` raised by the world is such an
error too; ``KeyboardInterrupt`` raised by it is an interrupt: in the main thread it
propagates, and under the command line (whose command runs in a worker thread) it
interrupts the command as Ctrl-C does (``interrupted``, exit 130); in any other thread
(a Dask worker's) it is an error of the world.  A factory that returns one of this
package's own worlds (a ``GridWorld``) is not wrapped.

Errors are :class:`mitld_lp.model.ModelError` naming the key path (``gym.env``,
``python.world``, ...).
"""

from __future__ import annotations

import _thread
import contextlib
import importlib
import inspect
import sys
import threading
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn

from mitld_lp.files import write as files
from mitld_lp.files.keys import ModelError
from mitld_lp.logic.syntax import is_proposition_name
from mitld_lp.worlds import WorldError
from mitld_lp.worlds.game import Game, GameError, world_members
from mitld_lp.worlds.successors import actions_fault, distribution_fault, place, propositions_fault

if TYPE_CHECKING:
    from mitld_lp.files.keys import KeyContext

__all__ = ["gym_world", "python_world", "GuardedWorld", "WorldContractError"]

_TERMINAL = ("absorb", "keep")


#: Bytes gymnasium's own table takes per (state, action, outcome) entry (a list of
#: tuples in a dict of dicts: measured about 200 on FrozenLake).
_GYM_BYTES_PER_ENTRY = 200


def _before_make(env_id: str, kwargs: dict[str, Any], ctx: KeyContext) -> None:
    """Refuse, before ``gymnasium.make`` builds its own table, a toy-text map whose size
    the keywords already tell (FrozenLake's ``desc`` or ``map_name``) when its states
    pass the world budget or its table the memory budget; any other environment is
    checked by :func:`mitld_lp.worlds.gym.from_env` once made."""
    from mitld_lp.worlds.gym import GymTooLarge

    if not env_id.startswith("FrozenLake"):
        return
    desc = kwargs.get("desc")
    if isinstance(desc, list) and desc and all(isinstance(r, str) for r in desc):
        states = len(desc) * max(len(r) for r in desc)
    elif kwargs.get("map_name", "4x4") in ("4x4", "8x8"):
        states = 16 if kwargs.get("map_name", "4x4") == "4x4" else 64
    else:
        return
    outcomes = 3 if kwargs.get("is_slippery", True) else 1
    need = states * 4 * outcomes * _GYM_BYTES_PER_ENTRY
    if states > ctx.max_states:
        raise GymTooLarge(f"{ctx.source}: gym: {env_id} with this map has {states:,} states, "
                          f"more than max_states = {ctx.max_states:,} (checked before "
                          "gymnasium builds its table)")
    if ctx.max_memory is not None and need > ctx.max_memory:
        raise GymTooLarge(f"{ctx.source}: gym: {env_id} with this map has {states:,} states; "
                          f"gymnasium's own table alone needs about {need / 2**20:.0f} MB, "
                          f"more than max_memory = {ctx.max_memory / 2**20:.1f} MB (checked "
                          "before it is built)")


def _reward_labels(ctx: KeyContext, table: dict[str, Any]) -> dict[str, float]:
    """``reward_labels``: proposition -> the reward whose transitions enter it."""
    out: dict[str, float] = {}
    for name, value in ctx.table(table.get("reward_labels", {}), "gym.reward_labels").items():
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ctx.error(f"gym.reward_labels.{name}", f"must be a number, got {value!r}")
        out[name] = float(value)
    return out


def _names(ctx: KeyContext, value: Any, path: str) -> list[str]:
    return [ctx.string(v, f"{path}[{i}]") for i, v in enumerate(ctx.array(value, path))]


def _proposition(ctx: KeyContext, name: str, path: str) -> str:
    if not is_proposition_name(name):
        raise ctx.error(path, f"{name!r} is not a name a formula can write (letters, digits "
                        "and _, not a reserved word such as F)")
    return name


def _labels(ctx: KeyContext, table: dict[str, Any], env: Any, n_states: int, env_id: str,
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


def gym_world(doc: dict[str, Any], ctx: KeyContext) -> Game[Any]:
    """The game of a ``[gym]`` table (module docstring)."""
    table = ctx.table(doc["gym"], "gym")
    ctx.keys(table, "gym", {"env"},
             {"kwargs", "labels", "propositions", "actions", "initial", "terminal",
              "reward_labels", "done_label", "time_limit"})
    env_id = ctx.string(table["env"], "gym.env")
    kwargs = ctx.table(table.get("kwargs", {}), "gym.kwargs")
    actions = _names(ctx, table["actions"], "gym.actions") if "actions" in table else None
    initial = ctx.integer(table["initial"], "gym.initial") if "initial" in table else None
    terminal = table.get("terminal", "absorb")
    if terminal not in _TERMINAL:
        raise ctx.error("gym.terminal", f'must be "absorb" or "keep", got {terminal!r}')
    rewards = _reward_labels(ctx, table)
    done = ctx.string(table["done_label"], "gym.done_label") if "done_label" in table else None
    time_limit = table.get("time_limit", "honour")
    if time_limit not in ("honour", "ignore"):
        raise ctx.error("gym.time_limit", f'must be "honour" or "ignore", got {time_limit!r}')
    try:
        import gymnasium
    except ImportError:
        raise ctx.error("gym", "needs gymnasium (pip install 'mitld_lp[gym]')") from None
    from mitld_lp.worlds.gym import FROZEN_LAKE_ACTIONS, GymTooLarge, from_env

    _before_make(env_id, kwargs, ctx)
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
                        action_names=actions, initial=initial, terminal=terminal,
                        reward_labels=rewards, done_label=done, time_limit=time_limit,
                        max_states=ctx.max_states, max_memory=ctx.max_memory)
    except GymTooLarge as exc:  # a budget stop (exit 3), not a mistake in the file
        raise GymTooLarge(f"{ctx.source}: gym: {exc}") from None
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


def python_world(doc: dict[str, Any], ctx: KeyContext) -> Game[Any]:
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
            raise ctx.error("python.world", f"cannot import {module_name}: {exc}"
                            f"{_unreadable_module(exc, folder)}") from None
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
    except KeyboardInterrupt:
        _interrupt(lambda: ctx.error("python.world", f"{target}(**kwargs) raised "
                                     "KeyboardInterrupt"))
    except (Exception, SystemExit) as exc:  # noqa: BLE001 - the factory's own code failed
        raise ctx.error("python.kwargs" if isinstance(exc, TypeError) else "python.world",
                        f"{target}(**kwargs) raised {_raised(exc)}") from None
    if not _is_game(game):
        raise ctx.error("python.world", f"{target} returned {type(game).__name__}, not a game "
                        "(the Game protocol: initial, proposition_names, actions, successors,"
                        " propositions)")
    if type(game).__module__.startswith("mitld_lp."):  # our own world: trusted
        return game
    guarded = GuardedWorld(game, f"{ctx.source}: python.world: {target}")
    try:
        world_members(guarded)
    except GameError as exc:
        raise ctx.error("python.world", f"{target}: {exc}") from None
    return guarded


def _unreadable_module(exc: ImportError, folder: Path) -> str:
    """Why Python found no module ``exc.name`` in the model file's folder when a file of
    its name is there but is no regular file (a FIFO, a folder named ``m.py``), which
    Python passes over in silence; else nothing."""
    if not isinstance(exc, ModuleNotFoundError) or not exc.name:
        return ""
    parts = exc.name.split(".")
    candidate = folder.joinpath(*parts[:-1], f"{parts[-1]}.py")
    kind = files.irregular_kind(candidate)
    return "" if kind is None else f" ({candidate} is {kind}, not a regular file)"


# --------------------------------------------------------------------------- the guard

_GAME_MEMBERS = ("initial", "proposition_names", "actions", "successors", "propositions")


def _is_game(world: object) -> bool:
    """``isinstance(world, Game)`` without running the world's code (a property)."""
    absent = object()
    return all(inspect.getattr_static(world, m, absent) is not absent for m in _GAME_MEMBERS)



class WorldContractError(ModelError):
    """A ``[python]`` world broke the :class:`~mitld_lp.worlds.game.Game` contract: the message
    names the model file, the world, the method and the state."""


def _raised(exc: BaseException) -> str:
    text = str(exc).splitlines()[0] if str(exc) else ""
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__ + (
        f"({exc.code!r})" if isinstance(exc, SystemExit) else "")


_COMMAND_THREAD = "mitld-lp"
"""The name of the thread the command line runs its command in (``mitld_lp.cli``)."""


def _interrupt(error: Callable[[], BaseException]) -> NoReturn:
    """A ``KeyboardInterrupt`` raised by the user's code, handled as Ctrl-C would be: in
    the main thread it propagates; in the command line's worker thread the main thread
    is interrupted, which stops the command and abandons this thread.  In any other
    thread (a Dask worker's, an application's) nobody pressed Ctrl-C, and interrupting
    that process's main thread would stop more than this task: there it is ``error()``,
    an error of the world."""
    me = threading.current_thread()
    if me is threading.main_thread():
        raise KeyboardInterrupt
    if me.name != _COMMAND_THREAD:
        raise error()
    _thread.interrupt_main()
    if files.abandoned(timeout=5.0):
        raise files.WriteAbandoned("interrupted (the world raised KeyboardInterrupt)")
    raise error()


class GuardedWorld:
    """A user's world held to the :class:`~mitld_lp.worlds.game.Game` contract on every call
    (module docstring); every other attribute is the world's own."""

    __slots__ = ("_world", "_label", "_names")

    def __init__(self, world: Any, label: str) -> None:
        self._world = world
        self._label = label
        self._names: frozenset[str] | None = None

    def __repr__(self) -> str:
        return f"GuardedWorld({self._world!r})"

    def __dir__(self) -> list[str]:
        return dir(self._world)

    def __getattr__(self, name: str) -> Any:
        if name.startswith("__"):
            raise AttributeError(name)
        return self._call(name, None, lambda: getattr(self._world, name), attribute=True)

    @property
    def world(self) -> Any:
        """The user's world itself."""
        return self._world

    def _error(self, method: str, where: str | None, why: str) -> WorldContractError:
        kind = type(self._world).__name__
        at = f"({where})" if where is not None else ""
        return WorldContractError(f"{self._label}: {kind}.{method}{at}: {why}")

    def _fail(self, method: str, where: str | None, why: str) -> NoReturn:
        raise self._error(method, where, why)

    def _call(self, method: str, where: Callable[[], str] | None, call: Callable[[], Any],
              attribute: bool = False) -> Any:
        try:
            return call()
        except KeyboardInterrupt:
            _interrupt(lambda: self._error(method, None if where is None else where(),
                                           "raised KeyboardInterrupt"))
        except AttributeError:
            if attribute:
                raise
            self._fail(method, None if where is None else where(), "raised AttributeError")
        except (Exception, SystemExit) as exc:  # noqa: BLE001 - the user's code failed
            self._fail(method, None if where is None else where(), f"raised {_raised(exc)}")

    @property
    def initial(self) -> Any:
        s = self._call("initial", None, lambda: self._world.initial)
        try:
            hash(s)
        except TypeError:
            self._fail("initial", None, f"the initial state {s!r} is not hashable")
        return s

    @property
    def proposition_names(self) -> frozenset[str]:
        if self._names is None:
            names = self._call("proposition_names", None,
                               lambda: self._world.proposition_names)
            if not isinstance(names, frozenset | set) or not all(
                    isinstance(n, str) for n in names):
                self._fail("proposition_names", None,
                           f"must be a frozenset of names, got {names!r}")
            self._names = frozenset(names)
        return self._names

    def actions(self, state: Any) -> tuple[str, ...]:
        acts = self._call("actions", lambda: f"state {state!r}",
                          lambda: self._world.actions(state))
        why = actions_fault(acts)
        if why:
            self._fail("actions", f"state {state!r}", why)
        return tuple(acts)

    def successors(self, state: Any, action: str, events: frozenset[str]) -> Any:
        where = lambda: place(state, action, events)  # noqa: E731
        succ = self._call("successors", where,
                          lambda: self._world.successors(state, action, events))
        if not isinstance(succ, tuple | list):
            succ = self._call("successors", where, lambda: tuple(succ)) if (
                succ is not None and not isinstance(succ, str | bytes | dict)) else succ
        why = distribution_fault(succ)
        if why:
            self._fail("successors", where(), why)
        return succ

    def propositions(self, state: Any) -> frozenset[str]:
        props = self._call("propositions", lambda: f"state {state!r}",
                           lambda: self._world.propositions(state))
        why = propositions_fault(props, self.proposition_names)
        if why:
            self._fail("propositions", f"state {state!r}", why)
        return props if isinstance(props, frozenset) else frozenset(props)
