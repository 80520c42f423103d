"""A gymnasium toy-text transition table as a :class:`mitld_lp.worlds.game.Game`.

Toy-text environments (FrozenLake, CliffWalking, Taxi) publish their dynamics as
``env.unwrapped.P``: ``P[s][a]`` is a list of ``(probability, next_state, reward,
terminated)``.  :func:`from_transition_table` turns such a table into an
:class:`~mitld_lp.worlds.game.ExplicitGame`; :func:`from_env` reads it from an environment.
gymnasium itself is never imported: any object with a ``P`` table works.

* **states** are the table's keys; **actions** are the keys of ``P[s]``, named by
  ``action_names`` (a sequence indexed by the action, or a mapping) or by ``str(a)``.
* **propositions** come from the user: a mapping ``state -> names`` or a function
  ``state -> names`` (:func:`map_labels` reads them off a toy-text map such as
  FrozenLake's ``desc``: goal and hole cells).
* **rewards and termination as propositions**: ``reward_labels={"cliff": -100}`` makes
  ``cliff`` true in the state a transition with reward -100 enters (a value, or a closed
  interval ``(lo, hi)``); ``done_label="done"`` makes ``done`` true in the state a
  ``terminated`` transition enters.  A proposition of a transition holds at the step the
  transition leads to (the formula reads the letter of the state a step ends in), so a
  state is then ``(s, t, entered, ended)``: the table's state, the step count (0 without
  a time limit), the propositions of the transition that entered it, and whether it
  ended the episode.  Without them rewards play no part: the task is the formula.
* **termination**: gymnasium ends an episode on a transition flagged ``terminated``.
  With ``terminal="absorb"`` (the default) a state entered by such a transition becomes
  absorbing, every action staying there, so the run keeps its last label as the episode
  would; on the plain table such a state must not also be entered by an unflagged
  transition (it would then be both an end and a step, and an error says so; with
  ``(s, t, entered, ended)`` states the two are told apart).  ``terminal="keep"`` uses
  the table as it is.
* **time limit**: an environment made by ``gymnasium.make`` is wrapped in a
  ``TimeLimit`` (FrozenLake 4x4: 100 steps) that truncates the episode.  ``from_env``
  honours it by default (``time_limit="honour"``: the state carries the step count
  ``t``, and at ``t = max_episode_steps`` it is absorbing, as the episode is over), so the
  promised value is the real environment's; ``time_limit="ignore"`` reads the table
  without it (the answer is then about episodes without a limit, and the name says so).
* **actions**: the controller answers the game's action names; :class:`GymAgent` turns
  its answers into the environment's integer actions and the environment's observations
  into the game's states, for ``env.step``.
* **budgets**: the game's states (``len(P)``, times ``max_episode_steps + 1`` with a time
  limit) and memory are estimated before the game is built and checked against
  ``max_states`` and ``max_memory`` (:class:`GymTooLarge`, a budget stop); while the
  ``(s, t, entered, ended)`` states are explored, their count is checked as it grows.
* **events**: a toy-text table has none (the game's ``event_names`` is empty), so the
  dynamics ignore the specification's external events (they only label the steps).

Errors are :class:`mitld_lp.worlds.WorldError` naming the state and action at fault.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Hashable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

from mitld_lp import defaults
from mitld_lp.util.memory import ProductTooLarge, byte_text, default_max_memory
from mitld_lp.worlds import WorldError
from mitld_lp.worlds.game import ExplicitGame, GameError

__all__ = [
    "from_transition_table", "from_env", "map_labels", "FROZEN_LAKE_ACTIONS", "GymGame",
    "GymTooLarge", "time_limit_of", "BYTES_PER_STATE", "BYTES_PER_BRANCH",
]

BYTES_PER_STATE = 600
"""Memory of a game state (its row of actions, its index entries, its labels), rounded up."""

BYTES_PER_BRANCH = 160
"""Memory of one ``(next state, probability)`` branch of the game's table, rounded up."""


class GymTooLarge(WorldError, ProductTooLarge):
    """The environment's table would exceed ``max_states`` or ``max_memory``, judged
    before the game is built: a budget stop (exit 3 on the command line)."""


RewardLabels = Mapping[str, float | tuple[float, float]]


@dataclass(frozen=True, eq=False)
class GymGame(ExplicitGame[Any]):
    """The game of a toy-text table, with what is needed to run its controller in the
    environment (:class:`GymAgent`).

    Attributes (beyond :class:`~mitld_lp.worlds.game.ExplicitGame`'s):
        env_actions: action name -> the environment's action (an integer for
            toy-text environments).
        horizon: the time limit honoured (``None``: none).
        reward_labels, done_label: the propositions of transitions (module docstring).
        extended: whether states are ``(s, t, entered, ended)`` rather than ``s``.
        ends: with ``terminal="absorb"``, whether a terminated transition ends the run.
    """

    env_actions: Mapping[str, Any] = field(default_factory=dict)
    horizon: int | None = None
    reward_labels: RewardLabels = field(default_factory=dict)
    done_label: str | None = None
    extended: bool = False
    ends: bool = True

    def entered(self, reward: float, terminated: bool) -> tuple[str, ...]:
        """The propositions of a transition with ``reward`` and ``terminated``."""
        return _entered(self.reward_labels, self.done_label, reward, terminated)

    def state_of(self, observation: Any, t: int = 0, entered: tuple[str, ...] = (),
                 ended: bool = False) -> Any:
        """The game state of the environment's ``observation`` at step ``t``."""
        if not self.extended:
            return observation
        return (observation, t if self.horizon is not None else 0, entered,
                ended and self.ends)

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
    reward_labels: RewardLabels | None = None,
    done_label: str | None = None,
    horizon: int | None = None,
    max_states: int = defaults.MAX_STATES,
    max_memory: int | None = None,
) -> GymGame:
    """The game of a toy-text table ``P[s][a] = [(prob, next, reward, terminated), ...]``.

    ``initial``: the start state.  ``propositions``: ``state -> names`` as a mapping
    (states not listed have none) or a function.  ``proposition_names``: every name
    any state may carry (default: those used, and those of ``reward_labels`` and
    ``done_label``).  ``horizon``: a time limit of that many steps.  See the module
    docstring for ``action_names``, ``terminal``, ``reward_labels``, ``done_label`` and
    the budgets.  Raises :class:`mitld_lp.worlds.WorldError` (:class:`GymTooLarge`).
    """
    if terminal not in ("absorb", "keep"):
        raise WorldError(f"terminal: must be 'absorb' or 'keep', got {terminal!r}")
    rewards = _check_reward_labels(reward_labels)
    if done_label is not None and (not isinstance(done_label, str) or not done_label):
        raise WorldError(f"done_label: must be a non-empty string, got {done_label!r}")
    if horizon is not None and (isinstance(horizon, bool) or not isinstance(horizon, int)
                                or horizon < 1):
        raise WorldError(f"horizon: must be a positive integer, got {horizon!r}")
    extended = bool(rewards) or done_label is not None or horizon is not None
    _check_budget(table, extended, horizon, max_states,
                  default_max_memory() if max_memory is None else max_memory)
    rows: dict[Any, dict[str, list[tuple[Any, float]]]] = {}
    outcomes: dict[Any, dict[str, list[tuple[Any, float, tuple[str, ...], bool]]]] = {}
    env_actions: dict[str, Any] = {}
    # states entered by a terminated transition, and by an ordinary one: (from, action)
    ended: dict[Any, tuple[Any, str]] = {}
    stepped: dict[Any, tuple[Any, str]] = {}
    for state, acts in _rows(table, "table"):
        row: dict[str, list[tuple[Any, float]]] = {}
        for action, results in _rows(acts, f"table[{state!r}]"):
            name = _action_name(action, action_names, state)
            if name in row:
                raise WorldError(f"state {state!r}: two actions are named {name!r}")
            if env_actions.setdefault(name, action) != action:
                raise WorldError(f"action_names: {name!r} names actions "
                                 f"{env_actions[name]!r} and {action!r}")
            dist: list[tuple[Any, float]] = []
            detail: list[tuple[Any, float, tuple[str, ...], bool]] = []
            for item in results:
                try:
                    prob, nxt, reward, done = item
                except (TypeError, ValueError):
                    raise WorldError(
                        f"state {state!r}, action {action!r}: expected (probability, "
                        f"next_state, reward, terminated), got {item!r}"
                    ) from None
                dist.append((nxt, prob))
                if extended:
                    detail.append((nxt, prob, _entered(rewards, done_label, reward, done),
                                   bool(done)))
                if float(prob) > 0.0 and done:
                    ended.setdefault(nxt, (state, name))
                elif float(prob) > 0.0 and nxt != state:  # staying put enters nothing
                    stepped.setdefault(nxt, (state, name))
            row[name] = dist
            if extended:
                outcomes.setdefault(state, {})[name] = detail
        if not row:
            raise WorldError(f"state {state!r}: has no actions")
        rows[state] = row
    if initial not in rows:
        raise WorldError(f"initial state {initial!r} is not a state of the table")

    base = _base_labels(rows, propositions)
    names = None if proposition_names is None else frozenset(proposition_names)
    settings = {"env_actions": env_actions, "horizon": horizon, "reward_labels": rewards,
                "done_label": done_label, "extended": extended, "ends": terminal == "absorb"}
    if extended:
        every = set(names) if names is not None else {n for v in base.values() for n in v}
        every |= set(rewards) | ({done_label} if done_label else set())
        return _explore(outcomes, initial, base, frozenset(every), settings, max_states)

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

    try:
        return GymGame(
            initial=initial,
            transitions=rows,
            labels=base,
            proposition_names=names,  # type: ignore[arg-type]  # None: the labels used
            **settings,
        )
    except GameError as exc:
        raise WorldError(str(exc)) from exc


def _base_labels(rows: Mapping[Any, Any], propositions: Propositions | None
                 ) -> dict[Any, frozenset[str]]:
    labels: dict[Any, frozenset[str]] = {}
    if callable(propositions):
        for state in rows:
            labels[state] = frozenset(_names(propositions(state), state))
    elif propositions is not None:
        for state, names in propositions.items():
            if state not in rows:
                raise WorldError(f"propositions: state {state!r} is not a state of the table")
            labels[state] = frozenset(_names(names, state))
    return labels


def _check_reward_labels(given: RewardLabels | None) -> dict[str, tuple[float, float]]:
    """``name -> (lo, hi)``: a reward value ``v`` is the interval ``(v, v)``."""
    out: dict[str, tuple[float, float]] = {}
    for name, value in (given or {}).items():
        if not isinstance(name, str) or not name:
            raise WorldError(f"reward_labels: {name!r} is not a proposition name")
        if isinstance(value, tuple | list) and len(value) == 2:
            lo, hi = value
        else:
            lo = hi = value
        if any(isinstance(x, bool) or not isinstance(x, int | float) for x in (lo, hi)) or lo > hi:
            raise WorldError(f"reward_labels.{name}: must be a reward or an interval "
                             f"(lo, hi) with lo <= hi, got {value!r}")
        out[name] = (float(lo), float(hi))
    return out


def _entered(rewards: Mapping[str, tuple[float, float]], done_label: str | None,
             reward: float, terminated: bool) -> tuple[str, ...]:
    names = [n for n, (lo, hi) in rewards.items() if lo <= float(reward) <= hi]
    if terminated and done_label is not None:
        names.append(done_label)
    return tuple(sorted(set(names)))


def _check_budget(table: Any, extended: bool, horizon: int | None, max_states: int,
                  max_memory: int) -> None:
    """Refuse, before anything is built, a table whose game would pass a budget: at
    least ``len(table)`` states (times ``horizon + 1`` with a time limit), each with the
    first state's actions and outcomes."""
    try:
        n = len(table)
        first = next(iter(table.values() if isinstance(table, Mapping) else table))
        actions = len(first)
        row = first.values() if isinstance(first, Mapping) else first
        branches = max((len(o) for o in row), default=1)
    except (TypeError, StopIteration, AttributeError):
        return  # not a table: the reading below says what is wrong
    states = n * ((horizon + 1) if horizon is not None else 1)
    kind = "with its time limit of " + f"{horizon:,} steps, " if horizon else ""
    if states > max_states:
        raise GymTooLarge(
            f"the environment's table has {n:,} states, {kind}at least {states:,} game "
            f"states, more than max_states = {max_states:,}; nothing was built: raise "
            "max_states (--max-world-states)"
        )
    need = states * (BYTES_PER_STATE + actions * branches * BYTES_PER_BRANCH)
    if need > max_memory:
        raise GymTooLarge(
            f"the environment's table ({n:,} states, {actions} actions, up to {branches} "
            f"outcomes) would need about {byte_text(need)} as a game, more than max_memory = "
            f"{byte_text(max_memory)}; nothing was built: raise max_memory (--max-memory)"
        )


def _explore(outcomes: Mapping[Any, Mapping[str, list[tuple[Any, float, tuple[str, ...], bool]]]],
             initial: Any, base: Mapping[Any, frozenset[str]], names: frozenset[str],
             settings: dict[str, Any], max_states: int) -> GymGame:
    """The ``(s, t, entered, ended)`` states reachable from ``(initial, 0, (), False)``."""
    horizon, ends = settings["horizon"], settings["ends"]
    start = (initial, 0, (), False)
    rows: dict[Any, dict[str, dict[Any, float]]] = {}
    labels: dict[Any, frozenset[str]] = {}
    queue = deque([start])
    seen = {start}
    while queue:
        state = queue.popleft()
        s, t, entered, ended = state
        labels[state] = base.get(s, frozenset()) | frozenset(entered)
        acts = outcomes[s]
        if ended or (horizon is not None and t >= horizon):  # the episode is over
            rows[state] = {a: {state: 1.0} for a in acts}
            continue
        row: dict[str, dict[Any, float]] = {}
        for action, branches in acts.items():
            dist: dict[Any, float] = {}
            for nxt, prob, marks, done in branches:
                target = (nxt, t + 1 if horizon is not None else 0, marks, done and ends)
                dist[target] = dist.get(target, 0.0) + float(prob)
                if target not in seen:
                    if nxt not in outcomes:
                        raise WorldError(f"state {s!r}, action {action!r}: successor {nxt!r} "
                                         "has no transitions")
                    seen.add(target)
                    if len(seen) > max_states:
                        raise GymTooLarge(
                            f"the episodes' states (state, step, reward labels) pass "
                            f"max_states = {max_states:,} while explored; raise max_states "
                            "(--max-world-states)"
                        )
                    queue.append(target)
            row[action] = dist
        rows[state] = row
    try:
        return GymGame(initial=start, transitions=rows, labels=labels,
                       proposition_names=names, **settings)
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


def time_limit_of(env: Any) -> int | None:
    """The ``max_episode_steps`` of the ``TimeLimit`` wrapping ``env`` (None: none)."""
    layer = env
    for _ in range(64):  # a wrapper chain, outermost first
        if type(layer).__name__ == "TimeLimit":
            steps = getattr(layer, "_max_episode_steps", None)
            return int(steps) if steps is not None else None
        inner = getattr(layer, "env", None)
        if inner is None or inner is layer:
            break
        layer = inner
    return None


def from_env(
    env: Any,
    *,
    propositions: Propositions | None = None,
    proposition_names: Iterable[str] | None = None,
    action_names: Sequence[str] | Mapping[Any, str] | None = None,
    initial: Hashable | None = None,
    terminal: Literal["absorb", "keep"] = "absorb",
    time_limit: Literal["honour", "ignore"] = "honour",
    reward_labels: RewardLabels | None = None,
    done_label: str | None = None,
    max_states: int = defaults.MAX_STATES,
    max_memory: int | None = None,
) -> GymGame:
    """The game of a toy-text environment: its ``unwrapped.P`` table, started in
    ``initial`` or, by default, in the one state of ``initial_state_distrib`` (an error
    when the environment starts in several).  ``time_limit``: the environment's
    ``TimeLimit`` honoured (the default) or ignored (module docstring)."""
    if time_limit not in ("honour", "ignore"):
        raise WorldError(f"time_limit: must be 'honour' or 'ignore', got {time_limit!r}")
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
        reward_labels=reward_labels,
        done_label=done_label,
        horizon=time_limit_of(env) if time_limit == "honour" else None,
        max_states=max_states,
        max_memory=max_memory,
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
