"""``solve FILE.prism --prop 'R{"r"}min=? [F "goal"]'``: an expected reward until a
target, answered by :mod:`mitld_lp.exact.reward` on Storm's exact build of the file
(:mod:`mitld_lp.worlds.prism_rewards`), one line (one JSON object) per property.

The answer is the optimum in rationals, the bracket that value rounded outward (both
ends certified: the optimum is a policy's exact value and an exact sub- or pre-fixed
point of the Bellman operator, see :mod:`mitld_lp.exact.reward`), or ``inf`` where the
graph decides that the target is not reached with probability 1 (for ``Rmin`` by any
scheduler, for ``Rmax`` by some scheduler), as Storm answers it.
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path
from typing import Any

from mitld_lp.cli.kernel import EXIT_OK, json_text, say_answer
from mitld_lp.report import bracket_text

__all__ = ["answer_reward"]


def answer_reward(args: argparse.Namespace, name: str, prop: Any, program: Any,
                  constants: dict[str, Any]) -> int:
    """One ``R`` property posed, built, solved and said; its exit code.  Raises
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
                        first=Path(args.model).suffix.lower() != ".jani")
    kwargs: dict[str, Any] = {}
    if args.max_world_states is not None:
        kwargs["max_states"] = args.max_world_states
    try:
        model = reward_mdp(args.model, program.program, query, constants=constants,
                           max_memory=args.max_memory, **kwargs)
    except (PrismTooLarge, PropertyError):
        raise  # a budget stop stays one; a refusal is the door's
    except WorldError as exc:
        raise ModelError(str(exc)) from exc
    if query.kind != "reach":  # C<=k, I=k: backward induction
        from mitld_lp.cli.bounded import answer_horizon

        return answer_horizon(args, query, model, started)
    answer = solve_reward(model, query.objective)
    seconds = time.perf_counter() - started
    value = answer.value
    lower = math.inf if value is None else float_down(value)
    upper = math.inf if value is None else float_up(value)
    scheduler = "every" if query.objective == "min" else "some"
    why = (f"the target is not reached with probability 1 under {scheduler} scheduler: "
           "Storm's infinity, decided by the graph")
    if args.json:
        record = {"property": query.name, "formula": query.text, "reward": query.reward,
                  "objective": query.objective, "target": str(query.target),
                  "status": "optimal", "certified": True,
                  "value": "inf" if value is None else str(value),
                  "lower": lower, "upper": upper, "infinite": value is None,
                  "states": model.n_states, "choices": int(model.groups[-1]),
                  "infinite_states": int(answer.infinite.sum()),
                  "policy_evaluations": answer.rounds, "seconds": seconds,
                  "model": Path(args.model).stem}
        if value is None:
            record["why"] = why
        say_answer(json_text(record))
        return EXIT_OK
    head = "= inf" if value is None else f"in {bracket_text(lower, upper)}"
    tail = [f"reward \"{query.reward}\", target {query.target}",
            why if value is None else f"exact {value}",
            "certified",
            f"{model.n_states} states, {int(model.groups[-1])} choices, "
            f"{answer.rounds} exact policy evaluations", f"{seconds:.2f} s"]
    say_answer(f"{query.name}: {query.text}  {head}  ({'; '.join(tail)})")
    return EXIT_OK
