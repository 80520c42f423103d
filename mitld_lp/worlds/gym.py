"""A gymnasium toy-text transition table as a :class:`mitld_lp.game.Game`.

Toy-text environments (FrozenLake, CliffWalking, Taxi) publish their dynamics as
``env.unwrapped.P``: ``P[s][a]`` is a list of ``(probability, next_state, reward,
terminated)``.  :func:`from_transition_table` turns such a table into an
:class:`~mitld_lp.game.ExplicitGame`; :func:`from_env` reads it from an environment.
gymnasium itself is never imported: any object with a ``P`` table works.

* **states** are the table's keys; **actions** are the keys of ``P[s]``, named by
  ``action_names`` (a sequence indexed by the action, or a mapping) or by ``str(a)``.
* **propositions** come from the user: a mapping ``state -> names`` or a function
  ``state -> names`` (:func:`map_labels` reads them off a toy-text map such as
  FrozenLake's ``desc``: goal and hole cells).
* **rewards** are dropped: the task is the formula.
* **termination**: gymnasium ends an episode on a transition flagged ``terminated``.
  With ``terminal="absorb"`` (the default) a state entered by such a transition becomes
  absorbing, every action staying there, so the run keeps its last label as the episode
  would; such a state must not also be entered by an unflagged transition (it would then
  be both an end and a step, and an error says so).  ``terminal="keep"`` uses the table
  as it is.
* **events**: a toy-text table has none (the game's ``event_names`` is empty), so the
  dynamics ignore the specification's external events (they only label the steps).

Errors are :class:`mitld_lp.worlds.WorldError` naming the state and action at fault.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable, Iterable, Mapping, Sequence
from typing import Any, Literal

from mitld_lp.game import ExplicitGame, GameError
from mitld_lp.worlds import WorldError

__all__ = ["from_transition_table", "from_env", "map_labels", "FROZEN_LAKE_ACTIONS"]

FROZEN_LAKE_ACTIONS: tuple[str, ...] = ("LEFT", "DOWN", "RIGHT", "UP")
"""FrozenLake's actions 0..3, for ``action_names``."""

Propositions = Mapping[Any, Iterable[str]] | Callable[[Any], Iterable[str]]


def _rows(table: Any, what: str) -> list[tuple[Any, Any]]:
    if isinstance(table, Mapping):
        return list(table.items())
    if isinstance(table, Sequence) and not isinstance(table, str):
        return list(enumerate(table))
    raise WorldError(f"{what}: must be a mapping or a list, got {type(table).__name__}")


def _action_name(action: Any, names: Sequence[str] | Mapping[Any, str] | None, state: Any) -> str:
    if names is None:
        return str(action)
    try:
        name = names[action]
    except (KeyError, IndexError, TypeError):
        raise WorldError(
            f"action_names: no name for action {action!r} (of state {state!r})"
        ) from None
    if not isinstance(name, str) or not name:
        raise WorldError(f"action_names: the name of action {action!r} must be a non-empty string")
    return name


def from_transition_table(
    table: Any,
    initial: Hashable,
    *,
    propositions: Propositions | None = None,
    proposition_names: Iterable[str] | None = None,
    action_names: Sequence[str] | Mapping[Any, str] | None = None,
    terminal: Literal["absorb", "keep"] = "absorb",
) -> ExplicitGame[Any]:
    """The game of a toy-text table ``P[s][a] = [(prob, next, reward, terminated), ...]``.

    ``initial``: the start state.  ``propositions``: ``state -> names`` as a mapping
    (states not listed have none) or a function.  ``proposition_names``: every name
    any state may carry (default: those used).  See the module docstring for
    ``action_names`` and ``terminal``.  Raises :class:`mitld_lp.worlds.WorldError`.
    """
    if terminal not in ("absorb", "keep"):
        raise WorldError(f"terminal: must be 'absorb' or 'keep', got {terminal!r}")
    rows: dict[Any, dict[str, list[tuple[Any, float]]]] = {}
    # states entered by a terminated transition, and by an ordinary one: (from, action)
    ended: dict[Any, tuple[Any, str]] = {}
    stepped: dict[Any, tuple[Any, str]] = {}
    for state, acts in _rows(table, "table"):
        row: dict[str, list[tuple[Any, float]]] = {}
        for action, outcomes in _rows(acts, f"table[{state!r}]"):
            name = _action_name(action, action_names, state)
            if name in row:
                raise WorldError(f"state {state!r}: two actions are named {name!r}")
            dist: list[tuple[Any, float]] = []
            for item in outcomes:
                try:
                    prob, nxt, _reward, done = item
                except (TypeError, ValueError):
                    raise WorldError(
                        f"state {state!r}, action {action!r}: expected (probability, "
                        f"next_state, reward, terminated), got {item!r}"
                    ) from None
                dist.append((nxt, prob))
                if float(prob) > 0.0 and done:
                    ended.setdefault(nxt, (state, name))
                elif float(prob) > 0.0 and nxt != state:  # staying put enters nothing
                    stepped.setdefault(nxt, (state, name))
            row[name] = dist
        if not row:
            raise WorldError(f"state {state!r}: has no actions")
        rows[state] = row
    if initial not in rows:
        raise WorldError(f"initial state {initial!r} is not a state of the table")

    if terminal == "absorb":
        for state in ended:
            if state in stepped:
                src, act = stepped[state]
                raise WorldError(
                    f"state {state!r} ends an episode (a terminated transition enters it) "
                    f"but state {src!r}, action {act!r} also steps into it without ending; "
                    "use terminal='keep' to take the table as it is"
                )
            if state in rows:
                rows[state] = {a: [(state, 1.0)] for a in rows[state]}

    labels: dict[Any, Iterable[str]] = {}
    if callable(propositions):
        for state in rows:
            labels[state] = frozenset(_names(propositions(state), state))
    elif propositions is not None:
        for state, names in propositions.items():
            if state not in rows:
                raise WorldError(f"propositions: state {state!r} is not a state of the table")
            labels[state] = frozenset(_names(names, state))
    names = None if proposition_names is None else frozenset(proposition_names)
    try:
        return ExplicitGame(
            initial=initial,
            transitions=rows,
            labels=labels,
            proposition_names=names,  # type: ignore[arg-type]  # None: the labels used
        )
    except GameError as exc:
        raise WorldError(str(exc)) from exc


def _names(names: Iterable[str], state: Any) -> list[str]:
    if isinstance(names, str):
        raise WorldError(
            f"propositions: state {state!r} needs a set of names, got the string {names!r}"
        )
    out = list(names)
    for n in out:
        if not isinstance(n, str):
            raise WorldError(f"propositions: state {state!r}: {n!r} is not a name")
    return out


def from_env(
    env: Any,
    *,
    propositions: Propositions | None = None,
    proposition_names: Iterable[str] | None = None,
    action_names: Sequence[str] | Mapping[Any, str] | None = None,
    initial: Hashable | None = None,
    terminal: Literal["absorb", "keep"] = "absorb",
) -> ExplicitGame[Any]:
    """The game of a toy-text environment: its ``unwrapped.P`` table, started in
    ``initial`` or, by default, in the one state of ``initial_state_distrib`` (an error
    when the environment starts in several)."""
    inner = getattr(env, "unwrapped", env)
    table = getattr(inner, "P", None)
    if table is None:
        raise WorldError(
            f"{type(inner).__name__} has no transition table P (toy-text environments have one)"
        )
    if initial is None:
        start = getattr(inner, "initial_state_distrib", None)
        if start is None:
            raise WorldError(f"{type(inner).__name__}: give initial= (no initial_state_distrib)")
        support = [s for s, p in enumerate(start) if p > 0]
        if len(support) != 1:
            raise WorldError(
                f"{type(inner).__name__} starts in {len(support)} states {support[:5]}; "
                "a game has one initial state: give initial="
            )
        initial = support[0]
    return from_transition_table(
        table,
        initial,
        propositions=propositions,
        proposition_names=proposition_names,
        action_names=action_names,
        terminal=terminal,
    )


def map_labels(
    desc: Iterable[Any], names: Mapping[str, str] | None = None
) -> dict[int, frozenset[str]]:
    """Propositions from a toy-text map (rows of letters, e.g. FrozenLake's ``desc``):
    the cell in row ``r``, column ``c`` is state ``r * ncol + c``, and it carries
    ``names[letter]`` (default ``{"G": "goal", "H": "hole"}``)."""
    table = {"G": "goal", "H": "hole"} if names is None else dict(names)
    out: dict[int, frozenset[str]] = {}
    grid = [[_letter(c) for c in row] for row in desc]
    ncol = len(grid[0]) if grid else 0
    for r, row in enumerate(grid):
        if len(row) != ncol:
            raise WorldError(f"map row {r} has {len(row)} cells, row 0 has {ncol}")
        for c, letter in enumerate(row):
            if letter in table:
                out[r * ncol + c] = frozenset({table[letter]})
    return out


def _letter(cell: Any) -> str:
    if isinstance(cell, bytes):
        return cell.decode()
    if hasattr(cell, "tobytes"):  # a numpy bytes scalar
        return bytes(cell).decode()
    return str(cell)
