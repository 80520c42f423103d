"""Expected-reward properties of a PRISM file, as Storm reads them: ``R{"name"}min=? [F
target]``, ``R{"name"}max=? [F target]``, and ``Rmin=?`` / ``Rmax=?`` with the file's
first reward structure (as PRISM takes it).

:func:`pose_reward` reads Storm's parsed property into a :class:`RewardQuery` or refuses
it naming the form (:class:`mitld_lp.worlds.properties.PropertyError`): cumulative
``C<=k``, instantaneous ``I=k``, long-run ``LRA``, total ``C``, reward bounds ``R~b``, a
filter, a file without that reward structure.  :func:`reward_mdp` builds the program
with Storm in rational arithmetic (``build_model[stormpy.Rational]``: the probabilities
and rewards as the file writes them; its exploration checks on), within the world
budgets (``max_states``, ``max_memory``, as :func:`mitld_lp.worlds.prism.load_prism`,
and :data:`mitld_lp.defaults.EXACT_MAX_TRANSITIONS` before the rational work),
and gives the :class:`RewardMDP` (each choice's reward: its
state's state reward plus its action reward; the target: the state formula as Storm
evaluates it on the built model).  Transition rewards (``[a] g : r`` depending on the
successor) are Storm's ``transition_rewards``; PRISM files write action rewards, which
Storm gives as ``state_action_rewards``; a model with transition rewards is refused.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np

from mitld_lp import defaults
from mitld_lp.worlds import WorldError
from mitld_lp.worlds.properties import PropertyError

__all__ = ["RewardMDP", "RewardQuery", "is_reward", "pose_reward", "reward_mdp"]


@dataclass(frozen=True, slots=True, eq=False)
class RewardMDP:
    """An MDP with rewards, exactly.

    Attributes:
        groups: ``(n_states + 1,)`` the choices of state ``s`` are
            ``groups[s]:groups[s+1]``.
        indptr, indices: the choices' successors (CSR layout over choices).
        probabilities: per entry, its probability (a rational: python-flint ``fmpq`` or
            :class:`fractions.Fraction`; a float64 array from a double build).
        rewards: per choice, the reward collected when it is taken (the state reward of
            its state plus the action reward), a non-negative rational (or a float64
            array).
        target: ``(n_states,)`` bool.
        initial: the initial state.
    """

    groups: np.ndarray
    indptr: np.ndarray
    indices: np.ndarray
    probabilities: Any
    rewards: Any
    target: np.ndarray
    initial: int

    @property
    def n_states(self) -> int:
        return int(self.groups.size - 1)

    @property
    def owner(self) -> np.ndarray:
        return np.repeat(np.arange(self.n_states), np.diff(self.groups))


@dataclass(frozen=True)
class RewardQuery:
    """One expected-reward property.

    Attributes:
        name: its name in its file, or its number there.
        text: the property as Storm prints it.
        reward: the reward structure's name (``""`` for an unnamed one).
        objective: ``"min"`` or ``"max"``.
        target: Storm's state formula of ``F target``.
    """

    name: str
    text: str
    reward: str
    objective: str
    target: Any

    @property
    def word(self) -> str:
        return f"R{{\"{self.reward}\"}}{self.objective}"


def is_reward(prop: Any) -> bool:
    """Whether Storm's property is an ``R`` operator."""
    import stormpy.logic as logic  # pyright: ignore[reportMissingImports]

    return isinstance(prop.get_raw_formula(), logic.RewardOperatorFormula)


def _refuse(name: str, text: str, form: str, why: str) -> PropertyError:
    return PropertyError(f"property {name} ({text}): {form} is refused: {why}")


def pose_reward(name: str, prop: Any, reward_names: list[str]) -> RewardQuery:
    """The :class:`RewardQuery` of Storm's ``R`` property ``prop`` over a file whose
    reward structures are ``reward_names`` (in the file's order), or a
    :class:`PropertyError` naming the form refused."""
    import stormpy.logic as logic  # pyright: ignore[reportMissingImports]

    from mitld_lp.worlds.properties import INIT_FILTER

    formula = prop.get_raw_formula()
    text = str(formula)
    if not INIT_FILTER.search(str(prop)):
        raise _refuse(name, text, "a filter", "only the value at the initial state is "
                      "answered")
    if formula.has_bound:
        raise _refuse(name, text, "a reward bound R~b", "ask R{...}min=? or R{...}max=? "
                      "and compare the certified value")
    if not formula.has_optimality_type:
        raise _refuse(name, text, "R=? without min or max",
                      "on an MDP the expected reward depends on the scheduler: write Rmax=? "
                      "or Rmin=?")
    objective = "min" if "MIN" in str(formula.optimality_type).upper() else "max"
    sub = formula.subformula
    if not isinstance(sub, logic.EventuallyFormula) or not isinstance(
            sub.subformula, logic.StateFormula) or "rew" in str(sub) or "<" in \
            str(sub).split(" ")[0]:
        forms = (("CumulativeRewardFormula", "a cumulative reward C<=k"),
                 ("InstantaneousRewardFormula", "an instantaneous reward I=k"),
                 ("LongRunAverageRewardFormula", "a long-run average reward LRA"),
                 ("TotalRewardFormula", "a total reward C"),
                 ("EventuallyFormula", "a reward-bounded or time-bounded F"))
        form = next((f for kind, f in forms
                     if isinstance(sub, getattr(logic, kind, ()))),
                    f"the reward formula {str(sub)!r}")
        raise _refuse(name, text, form, "only the expected reward until a target, "
                      "R{...}min=? [F target] and R{...}max=? [F target], is answered")
    if formula.has_reward_model_name():
        reward = formula.reward_name
        if reward not in reward_names:
            known = ", ".join(f'"{r}"' for r in reward_names) or "none"
            raise PropertyError(f"property {name} ({text}): the file has no reward "
                                f"structure \"{reward}\" (reward structures: {known})")
    elif reward_names:
        reward = reward_names[0]  # PRISM's default: the first structure
    else:
        raise PropertyError(f"property {name} ({text}): the file has no reward structure")
    return RewardQuery(name=name, text=text, reward=reward, objective=objective,
                       target=sub.subformula)


def _fraction(x: Any) -> Fraction:
    return Fraction(str(x))


def _float_tables(model: Any, query: RewardQuery, where: str) -> RewardMDP:
    """The built (double) model's :class:`RewardMDP` with float arrays: the transitions
    from Storm's binary export (no loop over states), the rewards per choice."""
    from mitld_lp.worlds.prism import stormpy_module
    from mitld_lp.worlds.prism_program import storm_quiet
    from mitld_lp.worlds.prism_tables import transition_arrays

    stormpy = stormpy_module()
    groups, indptr, indices, probabilities = transition_arrays(model, where)
    n, m = model.nr_states, int(groups[-1])
    rm = model.reward_models[query.reward]
    if rm.has_transition_rewards:
        raise WorldError(f"{where}: reward structure \"{query.reward}\": rewards on "
                         "transitions (depending on the successor) are refused; state and "
                         "action rewards are read")
    rewards = np.zeros(m)
    if rm.has_state_action_rewards:
        rewards += np.asarray(list(rm.state_action_rewards), dtype=np.float64)
    if rm.has_state_rewards:
        rewards += np.repeat(np.asarray(list(rm.state_rewards), dtype=np.float64),
                             np.diff(groups))
    bad = ~(rewards >= 0) | ~np.isfinite(rewards)
    if bad.any():
        raise WorldError(f"{where}: reward structure \"{query.reward}\": a negative reward "
                         f"({rewards[bad][0]}); expected rewards until a target need "
                         "rewards >= 0")
    with storm_quiet():
        truth = stormpy.model_checking(model, query.target)
    target = np.zeros(n, dtype=bool)
    target[np.asarray(list(truth.get_truth_values_vector()), dtype=np.int64)] = True
    return RewardMDP(groups=groups, indptr=indptr, indices=indices,
                     probabilities=probabilities, rewards=rewards, target=target,
                     initial=int(model.initial_states[0]))


def _tables(model: Any, query: RewardQuery, where: str) -> Any:
    """The built model's :class:`RewardMDP` (picklable: it may come from a capped child)."""
    from mitld_lp.worlds.prism import stormpy_module
    from mitld_lp.worlds.prism_program import storm_quiet

    stormpy = stormpy_module()
    matrix = model.transition_matrix
    n = model.nr_states
    if matrix.has_trivial_row_grouping:
        groups = np.arange(n + 1, dtype=np.int64)
    else:
        groups = np.asarray([matrix.get_row_group_start(s) for s in range(n)]
                            + [matrix.nr_rows], dtype=np.int64)
    indptr, indices, probabilities = [0], [], []
    for row in range(matrix.nr_rows):
        for entry in matrix.get_row(row):
            indices.append(entry.column)
            probabilities.append(_fraction(entry.value))
        indptr.append(len(indices))
    rm = model.reward_models[query.reward]
    if rm.has_transition_rewards:
        raise WorldError(f"{where}: reward structure \"{query.reward}\": rewards on "
                         "transitions (depending on the successor) are refused; state and "
                         "action rewards are read")
    rewards = [Fraction(0)] * matrix.nr_rows
    if rm.has_state_action_rewards:
        rewards = [_fraction(x) for x in rm.state_action_rewards]
    if rm.has_state_rewards:
        state = [_fraction(x) for x in rm.state_rewards]
        for s in range(n):
            for c in range(int(groups[s]), int(groups[s + 1])):
                rewards[c] += state[s]
    negative = [r for r in rewards if r < 0]
    if negative:
        raise WorldError(f"{where}: reward structure \"{query.reward}\": a negative reward "
                         f"({negative[0]}); expected rewards until a target need rewards >= 0")
    with storm_quiet():
        truth = stormpy.model_checking(model, query.target)
    target = np.zeros(n, dtype=bool)
    target[np.asarray(list(truth.get_truth_values_vector()), dtype=np.int64)] = True
    return RewardMDP(groups=groups, indptr=np.asarray(indptr, dtype=np.int64),
                     indices=np.asarray(indices, dtype=np.int64),
                     probabilities=tuple(probabilities), rewards=tuple(rewards),
                     target=target, initial=int(model.initial_states[0]))


def _float_build(stormpy: Any, plain: Any, options: Any) -> Any:
    """Storm's double build with its exploration checks; where only a sum fails there
    (compared exactly in doubles: ``2/3 + 1/6 + 1/6``), the checks are run in rational
    arithmetic (every update in range, every sum exactly 1, or Storm's error) and the
    double model is built without them."""
    from mitld_lp.worlds.prism_program import storm_sum

    try:
        return stormpy.build_model(plain, options=options)
    except (RuntimeError, stormpy.exceptions.StormError) as exc:
        if storm_sum(str(exc)) is None:
            raise
    stormpy.build_model[stormpy.Rational](plain, options=options)
    options.set_exploration_checks(False)
    return stormpy.build_model(plain, options=options)


def reward_mdp(path: str | os.PathLike[str], program: Any, query: RewardQuery, *,
               constants: Mapping[str, Any] | None = None,
               max_states: int = defaults.MAX_STATES,
               max_memory: int | None = None, exact: bool = True) -> Any:
    """The :class:`RewardMDP` of ``query`` on the PRISM ``program``
    (Storm's parse of ``path``), its open ``constants`` given, built by Storm in rational
    arithmetic (``exact``; else in doubles, with float arrays) within the budgets
    (:class:`mitld_lp.worlds.prism.PrismTooLarge` past them); :class:`WorldError` for a
    model Storm refuses or that is not an MDP or DTMC."""
    from mitld_lp.worlds.prism import (
        BYTES_PER_STATE,
        PrismTooLarge,
        build_within,
        check_budgets,
        stormpy_module,
    )
    from mitld_lp.worlds.prism_exact import exact_constants
    from mitld_lp.worlds.prism_program import (
        check_program,
        storm_error,
        storm_quiet,
        with_constants,
    )

    memory = check_budgets(max_states, max_memory)
    where = os.fspath(path)
    if Path(where).suffix.lower() == ".jani":
        raise WorldError(f"{where}: expected rewards are read from PRISM files; a JANI "
                         "file's are refused")
    stormpy = stormpy_module()
    kind = str(program.model_type).rsplit(".", 1)[-1]
    if kind not in ("MDP", "DTMC"):
        raise WorldError(f"{where}: the model is a {kind}; expected rewards are answered "
                         "on an mdp (or a dtmc)")
    program = with_constants(stormpy, program, exact_constants(stormpy, dict(constants or {})),
                             where)
    errors = (RuntimeError, stormpy.exceptions.StormError)
    try:
        with storm_quiet():
            plain = program.substitute_constants()
    except errors as exc:
        raise storm_error(exc, where) from None
    bound = check_program(plain, where)
    options = stormpy.BuilderOptions([query.target])
    options.set_build_all_reward_models()
    options.set_exploration_checks(True)

    def work() -> Any:
        try:
            with storm_quiet():
                model = (stormpy.build_model[stormpy.Rational](plain, options=options)
                         if exact else _float_build(stormpy, plain, options))
        except errors as exc:
            raise storm_error(exc, where) from None
        if model.nr_states > max_states:
            raise PrismTooLarge(f"{where}: Storm built {model.nr_states:,} states, more than "
                                f"max_states = {max_states:,} (--max-world-states)")
        if not exact:
            return _float_tables(model, query, where)
        if model.nr_transitions > defaults.EXACT_MAX_TRANSITIONS:
            raise PrismTooLarge(
                f"{where}: {model.nr_transitions:,} transitions, more than the "
                f"{defaults.EXACT_MAX_TRANSITIONS:,} an expected reward is solved with in "
                "rational arithmetic (mitld_lp.defaults.EXACT_MAX_TRANSITIONS)")
        return _tables(model, query, where)

    fits = bound.states <= max_states and bound.states * BYTES_PER_STATE <= memory
    return build_within(work, where, fits, str(bound), max_states, memory)
