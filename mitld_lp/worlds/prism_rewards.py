"""Expected-reward properties of a PRISM or JANI file, as Storm reads them: ``R{"name"}min=?
[F target]``, ``R{"name"}max=? [F target]``, the cumulative reward within ``k`` steps
``R{"name"}max=? [C<=k]`` (``C<k``: ``k-1`` steps), the state reward at step ``k``
``R{"name"}max=? [I=k]``, each with ``min`` too, and ``Rmin=?`` / ``Rmax=?`` with the
file's first reward structure (as PRISM takes it); the expected time ``Tmin=? [F target]``
(``Tmax``) as the expected reward of 1 in every state (each step), as Storm computes it
on an MDP or DTMC; and the bounds ``R{"name"}<=b [...]``, ``R>=b``, ``T~b`` (with
``min``/``max`` or without: for every scheduler, the greatest value deciding ``<=``,
``<``, the least ``>=``, ``>``, as Storm reads them), decided by the certified value
(:func:`mitld_lp.worlds.properties.verdict`).

:func:`pose_reward` reads Storm's parsed property into a :class:`RewardQuery` or refuses
it naming the form (:class:`mitld_lp.worlds.properties.PropertyError`): long-run
``LRA``, total ``C``, discounted rewards, a time-bounded ``F<=k``, ``R=?`` without
``min`` or ``max``, a step bound that is not a non-negative integer, a filter, a file
without that reward structure.  A JANI file's reward structures are its transient
variables that are not Boolean (Storm's reward models of a JANI model, ``R{"cost"}``
or a property's ``Emin`` over ``cost``).  :func:`reward_mdp` builds the program with
Storm in rational arithmetic (``build_model[stormpy.Rational]``: the probabilities and
rewards as the file writes them; its exploration checks on), within the world budgets
(``max_states``, ``max_memory``, as :func:`mitld_lp.worlds.prism.load_prism`, and
:data:`mitld_lp.defaults.EXACT_MAX_TRANSITIONS` before the rational work),
and gives the :class:`RewardMDP` (each choice's reward: its
state's state reward plus its action reward; the target: the state formula as Storm
evaluates it on the built model).  Transition rewards (``[a] g : r`` depending on the
successor) are Storm's ``transition_rewards``; PRISM files write action rewards, which
Storm gives as ``state_action_rewards``; a model with transition rewards is refused.
"""

from __future__ import annotations

import os
import re
from collections.abc import Mapping
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np

from mitld_lp import defaults
from mitld_lp.worlds import WorldError
from mitld_lp.worlds.properties import PropertyError

__all__ = ["RewardMDP", "RewardQuery", "is_reward", "pose_reward", "reward_mdp", "reward_names",
           "states_of"]


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
        state_rewards: per state, its state reward alone (for ``I=k``); empty when the
            structure has none.
        left: ``(n_states,)`` bool, where the left side of a reward-bounded until holds
            (None: everywhere).
    """

    groups: np.ndarray
    indptr: np.ndarray
    indices: np.ndarray
    probabilities: Any
    rewards: Any
    target: np.ndarray
    initial: int
    state_rewards: tuple[Any, ...] = ()
    left: np.ndarray | None = None

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
        target: Storm's state formula of ``F target`` (None for ``C<=k`` and ``I=k``).
        kind: ``"reach"`` (``F target``), ``"cumulative"`` (``C<=k``),
            ``"instantaneous"`` (``I=k``) or ``"bounded"`` (a reward-bounded until,
            :mod:`mitld_lp.worlds.reward_bounded`).
        steps: ``k`` of ``C<=k`` and ``I=k``.
        formula: Storm's formula (what Storm is asked to build the model for).
        left: the left state formula of a reward-bounded until (None: ``true``).
        per_step: Storm's expected time ``T``: a reward of 1 in every state (``reward``
            is ``""``; no structure of the file is read).
        comparison: ``">="``, ``">"``, ``"<="`` or ``"<"`` for ``R~b``, else None.
        threshold: ``b`` as a fraction, for ``R~b``.
    """

    name: str
    text: str
    reward: str
    objective: str
    target: Any
    kind: str = "reach"
    steps: int = 0
    formula: Any = None
    left: Any = None
    per_step: bool = False
    comparison: str | None = None
    threshold: Fraction | None = None

    @property
    def word(self) -> str:
        """``R{"cost"}min``, or ``Tmin`` for an expected time."""
        if self.per_step:
            return f"T{self.objective}"
        return (f"R{{\"{self.reward}\"}}" if self.reward else "R") + self.objective

    @property
    def structure(self) -> str | None:
        """The reward structure's name (None for an expected time, which reads none)."""
        return None if self.per_step else self.reward

    @property
    def said(self) -> str:
        """What is collected, for an answer's line."""
        return ("expected steps, a reward of 1 per step (Storm's T)" if self.per_step else
                f"reward \"{self.reward}\"")


def is_reward(prop: Any) -> bool:
    """Whether Storm's property is an ``R`` or a ``T`` operator (:func:`pose_reward`)."""
    import stormpy.logic as logic  # pyright: ignore[reportMissingImports]

    return isinstance(prop.get_raw_formula(), (logic.RewardOperatorFormula,
                                               logic.TimeOperatorFormula))


def reward_names(program: Any) -> list[str]:
    """The reward structures of Storm's PRISM program in the file's order, or of a JANI
    model: its transient variables that are not Boolean (its order)."""
    if hasattr(program, "reward_models"):
        return [r.name for r in program.reward_models]
    return [v.name for v in program.global_variables
            if v.is_transient and not v.expression_variable.has_boolean_type()]


def _refuse(name: str, text: str, form: str, why: str) -> PropertyError:
    return PropertyError(f"property {name} ({text}): {form} is refused: {why}")


def pose_reward(name: str, prop: Any, reward_names: list[str], *,
                first: bool = True, chain: bool = False) -> RewardQuery:
    """The :class:`RewardQuery` of Storm's ``R`` or ``T`` property ``prop`` over a file
    whose reward structures are ``reward_names`` (in the file's order), or a
    :class:`PropertyError` naming the form refused.  ``R`` without a name is the first
    structure (PRISM's rule) when ``first``, else only the one structure of the file
    (Storm's rule for a JANI file); ``T`` reads no structure (1 per step).  ``chain``:
    the file is a DTMC (``R=?`` needs no ``min`` or ``max``)."""
    import stormpy.logic as logic  # pyright: ignore[reportMissingImports]

    from mitld_lp.worlds.properties import INIT_FILTER, probability_objective

    formula = prop.get_raw_formula()
    text = str(formula)
    if not INIT_FILTER.search(str(prop)):
        raise _refuse(name, text, "a filter", "only the value at the initial state is "
                      "answered")
    per_step = isinstance(formula, logic.TimeOperatorFormula)
    letter, what = ("T", "the expected time") if per_step else ("R", "the expected reward")
    objective, comparison, threshold = probability_objective(name, formula, letter, what,
                                                             chain=chain)
    sub = formula.subformula
    kind, steps, target = "reach", 0, None
    if isinstance(sub, (logic.CumulativeRewardFormula, logic.InstantaneousRewardFormula)):
        kind = "cumulative" if isinstance(sub, logic.CumulativeRewardFormula) else \
            "instantaneous"
        steps = _steps(name, text, str(sub))
    elif not isinstance(sub, logic.EventuallyFormula) or not isinstance(
            sub.subformula, logic.StateFormula) or "rew" in str(sub) or "<" in \
            str(sub).split(" ")[0]:
        forms = (("LongRunAverageRewardFormula", "a long-run average reward LRA"),
                 ("DiscountedCumulativeRewardFormula", "a discounted cumulative reward"),
                 ("DiscountedTotalRewardFormula", "a discounted total reward"),
                 ("TotalRewardFormula", "a total reward C"),
                 ("BoundedUntilFormula", "a reward-bounded or time-bounded F"),
                 ("EventuallyFormula", "a reward-bounded or time-bounded F"))
        form = next((f for cls, f in forms
                     if isinstance(sub, getattr(logic, cls, ()))),
                    "a total reward C" if str(sub).strip() == "C" else
                    f"the reward formula {str(sub)!r}")
        raise _refuse(name, text, form, "answered are the expected reward until a "
                      "target (F target), the cumulative reward within k steps (C<=k) and "
                      "the state reward at step k (I=k), each with min or max")
    else:
        target = sub.subformula
    if per_step:
        return RewardQuery(name=name, text=text, reward="", objective=objective,
                           target=target, formula=formula, per_step=True,
                           comparison=comparison, threshold=threshold)
    if formula.has_reward_model_name():
        reward = formula.reward_name
        if reward not in reward_names:
            known = ", ".join(f'"{r}"' for r in reward_names) or "none"
            raise PropertyError(f"property {name} ({text}): the file has no reward "
                                f"structure \"{reward}\" (reward structures: {known})")
    elif len(reward_names) > 1 and not first:
        known = ", ".join(f'"{r}"' for r in reward_names)
        raise PropertyError(f"property {name} ({text}): which reward structure is meant? "
                            f"the file has several ({known}): name one, R{{\"name\"}} (as "
                            "Storm asks for a JANI file)")
    elif reward_names:
        reward = reward_names[0]  # PRISM's default: the first structure
    else:
        raise PropertyError(f"property {name} ({text}): the file has no reward structure")
    return RewardQuery(name=name, text=text, reward=reward, objective=objective,
                       target=target, kind=kind, steps=steps, formula=formula,
                       comparison=comparison, threshold=threshold)


def _steps(name: str, text: str, shown: str) -> int:
    """``k`` of Storm's printing ``C<=k``, ``C<k`` (``k-1``) or ``I=k``: a non-negative
    integer, else the property is refused."""
    m = re.fullmatch(r"\s*[CI]\s*(<=|<|=)\s*(.+?)\s*", shown)
    form = f"the step bound of {shown.strip()!r}"
    if m is None:
        raise _refuse(name, text, form, "expected C<=k, C<k or I=k")
    try:
        value = Fraction(re.sub(r"[()\s]", "", m[2]))  # Storm prints 5/2 as (5 / 2)
    except ValueError:
        raise _refuse(name, text, form, f"{m[2]!r} is not a number (a constant without "
                      "a value? give it with --const)") from None
    if value.denominator != 1 or value < 0:
        raise _refuse(name, text, form, "the steps must be a non-negative integer "
                      "(discrete time counts steps)")
    k = int(value) - (m[1] == "<")
    if k < 0:
        raise _refuse(name, text, form, "no step is below 0")
    return k


def _fraction(x: Any) -> Fraction:
    return Fraction(str(x))


def _structure(model: Any, query: RewardQuery, where: str) -> Any:
    """Storm's reward model of ``query`` on the built ``model`` (None for an expected
    time, 1 per step); rewards on transitions are refused."""
    if query.per_step:
        return None
    rm = model.reward_models[query.reward]
    if rm.has_transition_rewards:
        raise WorldError(f"{where}: reward structure \"{query.reward}\": rewards on "
                         "transitions (depending on the successor) are refused; state and "
                         "action rewards are read")
    return rm


def _float_tables(model: Any, query: RewardQuery, where: str) -> RewardMDP:
    """The built (double) model's :class:`RewardMDP` with float arrays: the transitions
    from Storm's binary export (no loop over states), the rewards per choice."""
    from mitld_lp.worlds.prism import stormpy_module
    from mitld_lp.worlds.prism_program import storm_quiet
    from mitld_lp.worlds.prism_tables import transition_arrays

    stormpy = stormpy_module()
    groups, indptr, indices, probabilities = transition_arrays(model, where)
    n, m = model.nr_states, int(groups[-1])
    rm = _structure(model, query, where)
    rewards = np.ones(m) if rm is None else np.zeros(m)  # T: 1 per step
    if rm is not None and rm.has_state_action_rewards:
        rewards += np.asarray(list(rm.state_action_rewards), dtype=np.float64)
    if rm is not None and rm.has_state_rewards:
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
    rm = _structure(model, query, where)
    rewards = [Fraction(0)] * matrix.nr_rows
    if rm is not None and rm.has_state_action_rewards:
        rewards = [_fraction(x) for x in rm.state_action_rewards]
    state: list[Fraction] = []
    if rm is None:  # T: a state reward of 1 in every state
        state = [Fraction(1)] * n
    elif rm.has_state_rewards:
        state = [_fraction(x) for x in rm.state_rewards]
    for s, r in enumerate(state):
        for c in range(int(groups[s]), int(groups[s + 1])):
            rewards[c] += r
    negative = [r for r in rewards + state if r < 0]
    if negative:
        raise WorldError(f"{where}: reward structure \"{query.reward}\": a negative reward "
                         f"({negative[0]}); expected rewards need rewards >= 0")
    return RewardMDP(groups=groups, indptr=np.asarray(indptr, dtype=np.int64),
                     indices=np.asarray(indices, dtype=np.int64),
                     probabilities=tuple(probabilities), rewards=tuple(rewards),
                     target=states_of(model, query.target),
                     initial=int(model.initial_states[0]), state_rewards=tuple(state),
                     left=None if query.left is None else states_of(model, query.left))


def states_of(model: Any, formula: Any) -> np.ndarray:
    """``(n_states,)`` bool: where Storm's state ``formula`` holds on the built ``model``
    (nowhere for None)."""
    from mitld_lp.worlds.prism import stormpy_module
    from mitld_lp.worlds.prism_program import storm_quiet

    where = np.zeros(model.nr_states, dtype=bool)
    if formula is None:
        return where
    with storm_quiet():
        truth = stormpy_module().model_checking(model, formula)
    where[np.asarray(list(truth.get_truth_values_vector()), dtype=np.int64)] = True
    return where


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
    """The :class:`RewardMDP` of ``query`` on the PRISM ``program`` or JANI model
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
    stormpy = stormpy_module()
    kind = str(program.model_type).rsplit(".", 1)[-1]
    if kind not in ("MDP", "DTMC"):
        raise WorldError(f"{where}: the model is a {kind}; expected rewards are answered "
                         "on an mdp (or a dtmc)")
    given = exact_constants(stormpy, dict(constants or {}))
    errors = (RuntimeError, stormpy.exceptions.StormError)
    if Path(where).suffix.lower() == ".jani":
        from mitld_lp.worlds.jani import state_bound

        try:
            with storm_quiet():
                plain = stormpy.instantiate_constants(program, given)[0] if given else \
                    program
        except errors as exc:
            raise storm_error(exc, where) from None
        states = state_bound(plain)
        fits = states is not None and states <= max_states and \
            states * BYTES_PER_STATE <= memory
        note = ("the variables' ranges unbounded" if states is None else
                f"{states:,} valuations of the variables' ranges and the locations")
    else:
        program = with_constants(stormpy, program, given, where)
        try:
            with storm_quiet():
                plain = program.substitute_constants()
        except errors as exc:
            raise storm_error(exc, where) from None
        bound = check_program(plain, where)
        fits = bound.states <= max_states and bound.states * BYTES_PER_STATE <= memory
        note = str(bound)
    formulas = [query.target] if query.kind == "reach" else [query.formula]
    options = stormpy.BuilderOptions(formulas)
    if not query.per_step:  # T reads no structure of the file
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

    return build_within(work, where, fits, note, max_states, memory)
