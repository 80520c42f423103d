"""``solve MODEL --objective min-steps`` (or ``min-cost``): the least expected steps
(cost) of satisfying the task, :mod:`mitld_lp.routes.steps`, one line (one JSON
object)."""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path
from typing import Any

from mitld_lp.cli.kernel import (
    EXIT_OK,
    EXIT_UNCERTIFIED,
    UsageError,
    json_text,
    read_model,
    say_answer,
    solve_settings,
    time_left,
)
from mitld_lp.report import bracket_text

__all__ = ["solve_steps"]


def solve_steps(args: argparse.Namespace, world: bool, policy_file: Path | None) -> int:
    """The task posed for its maximum probability, its product built, the expected steps
    (cost) bracketed and said; the exit code (3 when not certified)."""
    from mitld_lp.cli import door
    from mitld_lp.problem import ProblemError
    from mitld_lp.routes.stages import build_posed
    from mitld_lp.routes.steps import expected_steps, steps_refusal
    from mitld_lp.synthesis import pose

    objective = args.objective
    if policy_file is not None:
        raise UsageError(f"--policy: objective {objective} writes no policy file")
    started = time.perf_counter()
    args.objective = None  # the task's probability is posed as a maximum
    model = door.world_model(args) if world else read_model(args)
    if model.objective != "max":
        raise ProblemError(f"objective {objective}: the model file asks objective "
                           f"{model.objective!r} for the probability; the expected steps "
                           "are asked alone")
    posed = pose(model, args.constraint, then=args.then, settings=solve_settings(args),
                 objective="max")
    reasons = steps_refusal(posed, objective)
    if reasons:
        raise ProblemError(*reasons)
    built = build_posed(posed)
    answer = expected_steps(posed, built, objective, time_limit=time_left(args))
    seconds = time.perf_counter() - started
    code = EXIT_OK if answer.certified else EXIT_UNCERTIFIED
    why = ("no policy satisfies the task with probability 1: Storm's infinity, decided "
           "by the product's graph")
    if args.json:
        record: dict[str, Any] = {
            "model": model.name, "spec": str(model.spec), "objective": objective,
            "status": "optimal" if answer.certified else "not_certified",
            "certified": answer.certified, "infinite": answer.infinite,
            "value": "inf" if answer.infinite else (answer.lower + answer.upper) / 2,
            "lower": None if answer.infinite else answer.lower,
            "upper": None if math.isinf(answer.upper) else answer.upper,
            "states": answer.states, "choices": answer.choices,
            "lp_value": answer.lp_value, "seconds": seconds}
        if answer.infinite:
            record["why"] = why
        say_answer(json_text(record))
        return code
    what = "steps" if objective == "min-steps" else "cost"
    head = "= inf" if answer.infinite else f"in {bracket_text(answer.lower, answer.upper)}"
    tail = [why] if answer.infinite else []
    tail += ["certified" if answer.certified else "NOT certified",
             f"{answer.states} product states, {answer.choices} choices", f"{seconds:.2f} s"]
    say_answer(f"{model.name}: least expected {what} to satisfy {model.spec}  {head}  "
               f"({'; '.join(tail)})")
    return code
