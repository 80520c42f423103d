"""``solve FILE.prism --prop 'R{"r"}min=? [F "goal"]'``: an expected reward until a
target (``Tmin=? [F "goal"]``: the expected steps, 1 per step), one line (one JSON
object) per property; ``R{"r"}<=b [...]`` (``T~b``) true or false by the certified
bracket, undecided (exit 3) when it straddles ``b``.

By default the model is built in doubles and answered by
:mod:`mitld_lp.solvers.reward`: a certified bracket (a checked sub- and super-solution)
and the occupancy LP's objective as a cross-check.  Under ``--exact`` it is answered by
:mod:`mitld_lp.exact.reward` on Storm's exact build of the file
(:mod:`mitld_lp.worlds.prism_rewards`): the optimum in rationals, the bracket that
value rounded outward (both ends certified: the optimum is a policy's exact value and
an exact sub- or pre-fixed point of the Bellman operator, see
:mod:`mitld_lp.exact.reward`).  Either way the answer is ``inf`` where the graph
decides that the target is not reached with probability 1 (for ``Rmin`` by any
scheduler, for ``Rmax`` by some scheduler), as Storm answers it.
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path
from typing import Any

from mitld_lp.cli.kernel import EXIT_OK, EXIT_UNCERTIFIED, json_text, say_answer, time_left
from mitld_lp.report import bracket_text

__all__ = ["answer_reward"]


def answer_reward(args: argparse.Namespace, name: str, prop: Any, program: Any,
                  constants: dict[str, Any]) -> int:
    """One ``R`` (or ``T``) property posed, built, solved and said; its exit code.  Raises
    :class:`mitld_lp.worlds.properties.PropertyError` for a form refused,
    :class:`mitld_lp.model.ModelError` for a file Storm refuses."""
    from mitld_lp.exact.reward import solve_reward
    from mitld_lp.model import ModelError
    from mitld_lp.solvers.rounding import float_down, float_up
    from mitld_lp.worlds import WorldError
    from mitld_lp.worlds.prism import PrismTooLarge
    from mitld_lp.worlds.prism_rewards import pose_reward, reward_mdp, reward_names
    from mitld_lp.worlds.properties import PropertyError

    started = time.perf_counter()
    query = pose_reward(name, prop, reward_names(program.program),
                        first=Path(args.model).suffix.lower() != ".jani",
                        chain=program.chain)
    kwargs: dict[str, Any] = {}
    if args.max_world_states is not None:
        kwargs["max_states"] = args.max_world_states
    # C<=k and I=k: backward induction on the exact build (floats past its budget)
    exact = bool(getattr(args, "exact", False)) or query.kind != "reach"
    try:
        model = reward_mdp(args.model, program.program, query, constants=constants,
                           max_memory=args.max_memory, exact=exact, **kwargs)
    except (PrismTooLarge, PropertyError):
        raise  # a budget stop stays one; a refusal is the door's
    except WorldError as exc:
        raise ModelError(str(exc)) from exc
    if query.kind != "reach":  # C<=k, I=k: backward induction
        from mitld_lp.cli.bounded import answer_horizon

        return answer_horizon(args, query, model, started)
    if not exact:
        return _say_float(args, query, model, started)
    from mitld_lp.cli.bounded import decide, reward_head

    answer = solve_reward(model, query.objective)
    seconds = time.perf_counter() - started
    value = answer.value
    lower = math.inf if value is None else float_down(value)
    upper = math.inf if value is None else float_up(value)
    why = _why(query.objective)
    bound, decided, code = decide(query, (math.inf, math.inf) if value is None else
                                  (value, value), EXIT_OK)
    if args.json:
        record = {"property": query.name, "formula": query.text, "reward": query.structure,
                  "objective": query.objective, "target": str(query.target),
                  "status": "optimal", "certified": True,
                  "value": "inf" if value is None else str(value),
                  "lower": lower, "upper": upper, "infinite": value is None,
                  "states": model.n_states, "choices": int(model.groups[-1]),
                  "infinite_states": int(answer.infinite.sum()),
                  "policy_evaluations": answer.rounds, "seconds": seconds,
                  "model": Path(args.model).stem, **bound}
        if value is None:
            record["why"] = why
        say_answer(json_text(record))
        return code
    head = reward_head(query, bracket_text(lower, upper), value is None, decided)
    tail = [f"{query.said}, target {query.target}",
            why if value is None else f"exact {value}",
            "certified",
            f"{model.n_states} states, {int(model.groups[-1])} choices, "
            f"{answer.rounds} exact policy evaluations", f"{seconds:.2f} s"]
    say_answer(f"{query.name}: {query.text}  {head}  ({'; '.join(tail)})")
    return code


def _why(objective: str) -> str:
    scheduler = "every" if objective == "min" else "some"
    return (f"the target is not reached with probability 1 under {scheduler} scheduler: "
            "Storm's infinity, decided by the graph")


def _say_float(args: argparse.Namespace, query: Any, model: Any, started: float) -> int:
    """The float route's answer said (module docs); its exit code (3 when the upper
    bound's check failed: not certified, or ``R~b`` undecided)."""
    from mitld_lp.cli.bounded import decide, reward_head
    from mitld_lp.solvers.reward import solve_reward_float

    answer = solve_reward_float(model, query.objective, time_limit=time_left(args))
    seconds = time.perf_counter() - started
    bound, decided, code = decide(query, (answer.lower, answer.upper),
                                  EXIT_OK if answer.certified else EXIT_UNCERTIFIED)
    choices = int(model.groups[-1])
    if args.json:
        record = {"property": query.name, "formula": query.text, "reward": query.structure,
                  "objective": query.objective, "target": str(query.target),
                  "status": "optimal" if answer.certified else "not_certified",
                  "certified": answer.certified,
                  "value": "inf" if answer.infinite else answer.value,
                  "lower": answer.lower, "upper": answer.upper,
                  "infinite": answer.infinite, "states": model.n_states,
                  "choices": choices, "policy_iterations": answer.rounds,
                  "lp_value": answer.lp_value, "lp_status": answer.lp_status,
                  "seconds": seconds, "model": Path(args.model).stem, **bound}
        if answer.infinite:
            record["why"] = _why(query.objective)
        say_answer(json_text(record))
        return code
    head = reward_head(query, bracket_text(answer.lower, answer.upper), answer.infinite,
                       decided)
    tail = [f"{query.said}, target {query.target}"]
    if answer.infinite:
        tail.append(_why(query.objective))
    tail.append("certified" if answer.certified else
                "NOT certified (the upper bound's check failed)")
    if answer.lp_value is not None:
        tail.append(f"occupancy LP {answer.lp_value:.10g}")
    tail += [f"{model.n_states} states, {choices} choices, {answer.rounds} policy "
             "evaluations", f"{seconds:.2f} s"]
    say_answer(f"{query.name}: {query.text}  {head}  ({'; '.join(tail)})")
    return code
