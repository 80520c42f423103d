"""The door's bounded questions on a PRISM or JANI file: the step-bounded expected rewards
``R{"r"}max=? [C<=k]`` and ``R{"r"}min=? [I=k]`` (:mod:`mitld_lp.exact.horizon`), and
the reward-bounded probabilities ``Pmax=? [F{"r"}<=b "goal"]``
(:mod:`mitld_lp.worlds.reward_bounded`, :mod:`mitld_lp.exact.reward_bounded`), each
exact, one line (one JSON object) per property.  The bracket is the exact value rounded
outward (certified: the value is the optimum itself, see those modules).  A bound
``R{"r"}<=b`` (``P>=p``) is true or false by that value (:func:`decide`).
"""

from __future__ import annotations

import argparse
import time
from fractions import Fraction
from pathlib import Path
from typing import Any

from mitld_lp.cli.kernel import EXIT_OK, EXIT_UNCERTIFIED, json_text, say_answer
from mitld_lp.report import bracket_text

__all__ = ["answer_horizon", "answer_reward_bounded", "decide", "reward_head"]


def _bracket(value: Fraction) -> tuple[float, float]:
    from mitld_lp.solvers.rounding import float_down, float_up

    return float_down(value), float_up(value)


def decide(query: Any, bracket: tuple[Any, Any], code: int
           ) -> tuple[dict[str, Any], bool | None, int]:
    """An ``R~b`` (``T~b``) ``query`` decided by the optimum's ``bracket`` (exact values,
    or ``math.inf`` both): the JSON fields it adds, the verdict (None: undecided) and the
    exit code (3 when undecided, else ``code``); nothing for ``R=?``."""
    from mitld_lp.worlds.properties import verdict

    if query.comparison is None:
        return {}, None, code
    decided = verdict(query, *bracket)
    fields = {"comparison": query.comparison, "threshold": str(query.threshold),
              "verdict": decided}
    return fields, decided, EXIT_UNCERTIFIED if decided is None else code


def reward_head(query: Any, bracket: str, infinite: bool, decided: bool | None) -> str:
    """An ``R`` property's answer, ``in [l, u]`` or ``= inf``, or for ``R~b`` its verdict
    with the optimum that decides it."""
    shown = "= inf" if infinite else f"in {bracket}"
    if query.comparison is None:
        return shown
    said = {True: "true", False: "false", None: "undecided"}[decided]
    return f"{said}: {query.word} {shown}, threshold {query.comparison} {query.threshold}"


def answer_horizon(args: argparse.Namespace, query: Any, model: Any, started: float) -> int:
    """``C<=k`` or ``I=k`` of ``query`` (a :class:`~mitld_lp.worlds.prism_rewards.
    RewardQuery`) on its built ``model``, said; its exit code."""
    from mitld_lp.exact import horizon
    from mitld_lp.exact.errors import ExactTooLarge

    try:
        horizon.check_horizon(model, query.steps)
    except ExactTooLarge:  # past the exact budget: the floating-point bracket
        from mitld_lp.solvers.step_bounded import horizon_bracket

        value = None
        lower, upper = horizon_bracket(model, query.kind, query.steps, query.objective)
    else:
        value = horizon.solve_horizon(model, query.kind, query.steps, query.objective).value
        lower, upper = _bracket(value)
    seconds = time.perf_counter() - started
    form = (f"cumulative reward within {query.steps} steps" if query.kind == "cumulative"
            else f"state reward at step {query.steps}")
    no_state = query.kind == "instantaneous" and not model.state_rewards
    bound, decided, code = decide(query, (lower, upper) if value is None else
                                  (value, value), EXIT_OK)
    if args.json:
        record = {"property": query.name, "formula": query.text, "reward": query.reward,
                  "objective": query.objective, "kind": query.kind, "steps": query.steps,
                  "status": "optimal", "certified": True,
                  "value": None if value is None else str(value),
                  "lower": lower, "upper": upper, "states": model.n_states,
                  "choices": int(model.groups[-1]), "seconds": seconds,
                  "model": Path(args.model).stem, **bound}
        if no_state:
            record["why"] = "the reward structure has no state rewards"
        say_answer(json_text(record))
        return code
    how = (f"exact {value}" if value is not None else
           f"floating-point bracket: {query.steps:,} steps x {int(model.indices.size):,} "
           "transitions past the exact budget")
    tail = [f"reward \"{query.reward}\", {form}", how, "certified",
            f"{model.n_states} states, {int(model.groups[-1])} choices"
            + (", a policy per step" if value is not None else ""),
            f"{seconds:.2f} s"]
    if no_state:
        tail.insert(1, "the structure has no state rewards")
    head = reward_head(query, bracket_text(lower, upper), False, decided)
    say_answer(f"{query.name}: {query.text}  {head}  ({'; '.join(tail)})")
    return code


def answer_reward_bounded(args: argparse.Namespace, name: str, prop: Any, program: Any,
                          constants: dict[str, Any]) -> int:
    """One reward-bounded ``P`` property posed, unfolded, solved and said; its exit
    code (3 when ``P~p`` is undecided).  Raises
    :class:`mitld_lp.worlds.properties.PropertyError` for a form refused."""
    from mitld_lp.cli.kernel import probability_head
    from mitld_lp.exact.reward_bounded import solve_reward_bounded
    from mitld_lp.model import ModelError
    from mitld_lp.worlds import WorldError
    from mitld_lp.worlds.prism import PrismTooLarge
    from mitld_lp.worlds.prism_rewards import reward_mdp, reward_names
    from mitld_lp.worlds.properties import PropertyError, verdict
    from mitld_lp.worlds.reward_bounded import pose_reward_bounded

    started = time.perf_counter()
    posed = pose_reward_bounded(name, prop, reward_names(program.program),
                                chain=program.chain)
    kwargs: dict[str, Any] = {}
    if args.max_world_states is not None:
        kwargs["max_states"] = args.max_world_states
    try:
        model = reward_mdp(args.model, program.program, posed.reward_query,
                           constants=constants, max_memory=args.max_memory, **kwargs)
    except (PrismTooLarge, PropertyError):
        raise
    except WorldError as exc:
        raise ModelError(str(exc)) from exc
    answer = solve_reward_bounded(model, posed, **kwargs)
    seconds = time.perf_counter() - started
    value = answer.value
    lower, upper = _bracket(value)
    query = posed.query
    decided = None if query.comparison is None else verdict(query, value, value)
    code = EXIT_OK if query.comparison is None or decided is not None else EXIT_UNCERTIFIED
    if args.json:
        record = {"property": name, "formula": query.text, "reward": posed.reward,
                  "objective": query.objective, "bound": posed.bound,
                  "status": "optimal", "certified": True,
                  "value": None if value is None else str(value),
                  "lower": lower, "upper": upper, "states": model.n_states,
                  "unfolded_states": answer.states, "seconds": seconds,
                  "model": Path(args.model).stem}
        if query.comparison is not None:
            record.update(comparison=query.comparison, threshold=str(query.threshold),
                          verdict=decided)
        say_answer(json_text(record))
        return code
    head = probability_head(query, bracket_text(lower, upper), decided)
    tail = [f"reward \"{posed.reward}\" accumulated <= {posed.bound}", f"exact {value}",
            "certified", f"{model.n_states} states unfolded to {answer.states}",
            f"{seconds:.2f} s"]
    say_answer(f"{name}: {query.text}  {head}  ({'; '.join(tail)})")
    return code
